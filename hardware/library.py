"""Run a controller on the robot or an emulated one from Python: one request in, the episodes back in memory.

``pectoral-deploy`` (:mod:`pectoral_gym.hardware.deploy`) is this function's command line, and the deployment
study (:mod:`pectoral_gym.hardware.studies.deployment`) calls it too::

    from pectoral_gym.hardware.library import DeployRequest, run_deployment

    run = run_deployment(DeployRequest(controller="hand", rig="lockstep", episodes=3, seed=7))
    print([e["success"] for e in run.episodes], run.link["sent"], run.wall_time)
    run = run_deployment(DeployRequest(controller=my_controller, rig="lockstep", task="goal", out="runs/d"))

A request's settings are checked before anything moves (``ValueError``, one line naming the setting); a device
that does not answer or an episode that cannot go on raises :class:`DeployError`. Files (``steps.jsonl``,
``run.jsonl``, ``summary.json``, ``trajectory.png``) are written only with an ``out`` folder; a run that fails
before its first step leaves none behind (nor the folders made for them). Every resource (emulated robot, radio
link, camera, env) is released on every path out, Ctrl-C included (``KeyboardInterrupt``, after the fins were
stopped).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pectoral_gym.hardware import deploy_runs
from pectoral_gym.hardware.deploy_checks import (
    CONTROL_PERIOD_RANGE,
    MIN_TRACKING_WALL,
    NICE_RANGE,
    SPEED_RANGE,
    check_scaling,
    env_settings,
    policy_preflight,
    raise_priority,
    shipped_k_problem,
)
from pectoral_gym.hardware.deploy_episodes import plot_trajectories
from pectoral_gym.hardware.deploy_runs import DeployError
from pectoral_gym.hardware.emulated_firmware import FIRMWARES
from pectoral_gym.hardware.emurig import RigConditions
from pectoral_gym.hardware.safety.rules import SafetyConfig

__all__ = ["CONTROLLERS", "RIGS", "DeployError", "DeployRequest", "Deployment", "run_deployment", "summary_report"]

#: The rigs: the emulated robot and the whole PC stack in simulated time, the emulated robot in real time, a robot.
RIGS = ("lockstep", "emulated", "robot")
#: The controllers a request names (else it passes an object with ``reset(seed)`` and ``act(obs)``).
CONTROLLERS = ("policy", "nmpc", "hand", "excite")


@dataclass(frozen=True)
class DeployRequest:
    """A deployment: what drives the fish, on which rig, for how many episodes (units: seconds, metres).

    Attributes:
        controller: ``"policy"`` (loads ``policy``), ``"nmpc"``, ``"hand"``, ``"excite"`` (an identification run),
            or a controller object (``reset(seed)``, ``act(obs)``; a loaded policy carries its ``trained``
            settings, which are checked as for ``"policy"``); an object runs with ``jobs=1`` only.
        policy: Run folder or ``.zip`` of a trained policy (``controller="policy"`` only). Its pickles run when
            loaded: only folders you made or trust.
        episodes: Episodes, >= 1; episode ``k`` is seeded with ``seed + k``.
        seed: Seed of the targets, starts and every emulated condition, >= 0.
        task: ``"goal"`` or ``"track"`` (``None``: the policy's own, else ``goal``).
        control_period: Seconds between actions (``None``: the policy's own, else 0.5).
        rig: One of :data:`RIGS`.
        port, camera, robot_address, prompt: The robot's radio (serial URL), camera (index, URL, file), its XBee's
            64-bit address (``None``: broadcast) and whether to ask before each episode that the fish be placed
            (``rig="robot"`` only).
        speed: The emulated clock's speed-up (``rig="emulated"``).
        conditions: The emulated radio's and camera's conditions (emulated rigs only).
        emulate_params: The emulated fish's :class:`~pectoral_gym.model.params.FishParams` (``None``: Table 1's).
        firmware: The emulated robot's rules (:data:`pectoral_gym.hardware.emulated_firmware.FIRMWARES`).
        take_over: Take control of a robot that another live session drives.
        safety: The safety supervisor's settings.
        params: The robot's own model for the PC side (geofence, fin replay), checked by a probe first.
        scaling: The K file the hand law and the NMPC plan with (``None``: the shipped K).
        calibration: Camera calibration file (``None``: the emulator's camera model).
        solve_fraction: NMPC: the share of the control period a step's solves may take, in (0, 1].
        jobs: Worker processes for the lockstep episodes, >= 1 (the same results for any number).
        max_episode_steps: Steps per episode, >= 1.
        nice: Nice value to run at in real time, in [-20, 0] (0: leave the process as it is).
        out: Output folder (``None``: no files; the results are in memory either way).
        progress: Show a progress bar over the episodes.
    """

    controller: Any = "hand"
    policy: str | Path | None = None
    episodes: int = 1
    seed: int = 0
    task: str | None = None
    control_period: float | None = None
    rig: str = "lockstep"
    port: str | None = None
    camera: str | None = None
    robot_address: int | None = None
    prompt: bool = True
    speed: float = 1.0
    conditions: RigConditions = RigConditions()
    emulate_params: Any = None
    firmware: str = "python"
    take_over: bool = False
    safety: SafetyConfig = SafetyConfig()
    params: Any = None
    scaling: str | None = None
    calibration: str | None = None
    solve_fraction: float = 0.5
    jobs: int = 1
    max_episode_steps: int = 240
    nice: int = 0
    out: str | Path | None = None
    progress: bool = False

    def __post_init__(self) -> None:
        if self.policy is not None:
            object.__setattr__(self, "policy", str(self.policy))
        problem = _request_problem(self)
        if problem is not None:
            raise ValueError(problem)

    @property
    def controller_name(self) -> str:
        """The controller's name: one of :data:`CONTROLLERS`, or ``"object"`` for a controller object."""
        return self.controller if isinstance(self.controller, str) else "object"


def _request_problem(r: DeployRequest) -> str | None:
    """What is wrong with a request's settings taken alone (``None``: nothing)."""
    from pectoral_gym.agents.baselines import scaling_flag_problem

    emulated = r.rig != "robot"
    if r.rig not in RIGS:
        return f"rig must be one of {RIGS}, got {r.rig!r}"
    if isinstance(r.controller, str) and r.controller not in CONTROLLERS:
        return f"controller must be one of {CONTROLLERS} or a controller object, got {r.controller!r}"
    if not isinstance(r.controller, str) and not (hasattr(r.controller, "act") and hasattr(r.controller, "reset")):
        return f"a controller object needs reset(seed) and act(obs), got {type(r.controller).__name__}"
    if (r.controller_name == "policy") != (r.policy is not None):
        return "policy is needed with controller 'policy', and only then"
    if not isinstance(r.controller, str) and r.jobs != 1:
        return "a controller object runs in this process: jobs must be 1 (or name the policy's folder)"
    if emulated and (r.port, r.camera, r.robot_address) != (None, None, None):
        return "port, camera and robot_address are the robot's: the emulated rigs bring their own"
    if not emulated and (r.port is None or r.camera is None):
        return "rig 'robot' needs port and camera"
    misplaced = [name for name, wrong in (
        ("jobs", r.jobs != 1 and r.rig != "lockstep"), ("speed", r.speed != 1.0 and r.rig != "emulated"),
        ("firmware", r.firmware != "python" and not emulated), ("emulate_params", r.emulate_params is not None
                                                                and not emulated),
        ("conditions", r.conditions != RigConditions() and not emulated)) if wrong]
    if misplaced:
        return f"{', '.join(misplaced)}: not with rig {r.rig!r}"
    if r.firmware not in FIRMWARES:
        return f"firmware must be one of {FIRMWARES}, got {r.firmware!r}"
    if (problem := scaling_flag_problem(r.controller_name, r.scaling)) is not None:
        return problem
    for name, value in (("episodes", r.episodes), ("max_episode_steps", r.max_episode_steps), ("jobs", r.jobs)):
        if value < 1:
            return f"{name} must be >= 1, got {value}"
    if r.seed < 0:
        return f"seed must be >= 0, got {r.seed}"
    if not math.isfinite(r.speed) or not SPEED_RANGE[0] <= r.speed <= SPEED_RANGE[1]:
        return f"speed must be in [{SPEED_RANGE[0]}, {SPEED_RANGE[1]}], got {r.speed}"
    if not NICE_RANGE[0] <= r.nice <= NICE_RANGE[1]:
        return f"nice must be in [{NICE_RANGE[0]}, {NICE_RANGE[1]}], got {r.nice}"
    if not 0 < r.solve_fraction <= 1:
        return f"solve_fraction must be in (0, 1], got {r.solve_fraction}"
    if not r.safety.tracking_timeout / r.speed >= MIN_TRACKING_WALL:
        return (f"safety.tracking_timeout / speed must be >= {MIN_TRACKING_WALL} s of wall time, got "
                f"{r.safety.tracking_timeout} at speed {r.speed}")
    if r.control_period is not None and not (math.isfinite(r.control_period) and CONTROL_PERIOD_RANGE[0]
                                             <= r.control_period <= CONTROL_PERIOD_RANGE[1]):
        return f"control_period must be in [{CONTROL_PERIOD_RANGE[0]}, {CONTROL_PERIOD_RANGE[1]}] s, got " \
               f"{r.control_period}"
    return None


@dataclass
class Deployment:
    """A deployment's results, in memory.

    Attributes:
        episodes: Each episode's summary (``episode``, ``return``, ``steps``, ``terminated``, ``truncated``,
            ``safety_stop``, ``success``, ``final_distance`` [m]).
        steps: The step records (``steps.jsonl``'s lines: a reset record, then one per step).
        run_log: The run log's records (``run.jsonl``, ``docs/run-log.md``; its header first).
        link: The radio link's health (counters summed over the episodes in lockstep).
        solver: The NMPC's solve times (p50/p95/max [ms]), failed and late steps, or ``None``.
        wall_time: Wall seconds of the episodes.
        ended: ``""`` (done) or why the robot stopped serving this run (``"taken_over"``, ``"robot_busy"``).
        settings: The env settings the run used.
        summary: ``summary.json``'s content.
        notes: The notes and warnings of the run (each a line, as ``pectoral-deploy`` prints them).
    """

    episodes: list[dict[str, Any]]
    steps: list[dict[str, Any]]
    run_log: list[dict[str, Any]]
    link: dict[str, Any]
    solver: dict[str, Any] | None
    wall_time: float
    ended: str
    settings: dict[str, Any]
    summary: dict[str, Any]
    notes: list[str] = dataclasses.field(default_factory=list)


def summary_report(request: DeployRequest, settings: dict, result: deploy_runs.RunResult) -> dict[str, Any]:
    """``summary.json``'s content for a run of ``request`` with the env ``settings``."""
    summaries, link, solver, wall_time, ended = result
    report = {"controller": request.controller_name, "policy": request.policy,
              "settings": {k: list(v) if isinstance(v, tuple) else dataclasses.asdict(v) if k == "params" else v
                           for k, v in settings.items()},
              "episodes": summaries, "link": link, "ended": ended or "done"}
    report["wall_time"] = wall_time  # s for the episodes (the one field a lockstep rerun changes)
    if request.rig != "robot":
        report["emulation"] = {"lockstep": request.rig == "lockstep", "speed": request.speed, "seed": request.seed,
                               "firmware": request.firmware, "conditions": dataclasses.asdict(request.conditions),
                               "params": None if request.emulate_params is None else dataclasses.asdict(
                                   request.emulate_params)}
    if solver is not None:
        report["solver"] = solver  # its times are wall times: a rerun changes them too
    return report


def _checked_settings(request: DeployRequest) -> tuple[Any, Any, dict, list[str]]:
    """Every check of the request's files, then the policy loaded.

    Returns ``(controller or None for a baseline, camera model, env settings, notes)``.

    A policy folder is code (its pickles run when loaded): only its ``config.yaml`` (YAML, safe) and its files'
    presence are checked before every other input, and it is loaded last.
    """
    name = request.controller_name
    if name == "policy":
        try:
            policy_preflight(request.policy)
        except (OSError, ValueError) as err:
            raise ValueError(f"cannot load policy {request.policy!r}: {err}") from err
    from pectoral_gym.hardware.vision.cameramodel import CameraModel

    try:
        model = CameraModel.default() if request.calibration is None else CameraModel.load(request.calibration)
    except (OSError, ValueError) as err:
        raise ValueError(f"--calibration: cannot load {request.calibration}: {err}") from err
    controller = None if isinstance(request.controller, str) else request.controller
    if name == "policy":  # the pickles, after every other check of the inputs
        from pectoral_gym.agents.training.policy import load_policy  # lazy: agents/ pulls in torch

        try:
            controller = load_policy(request.policy)
        except (OSError, ValueError) as err:
            raise ValueError(f"cannot load policy {request.policy!r}: {err}") from err
    try:
        settings, notes = env_settings(controller, request.task, request.control_period)
    except ValueError as err:
        raise ValueError(f"{'policy ' + repr(request.policy) if request.policy else 'the controller'} does not "
                         f"fit: {err}") from err
    if request.params is not None:  # the robot's own model: the supervisor's stopping distance and outline
        settings["params"] = request.params
    if request.scaling is not None:
        try:
            check_scaling(request.scaling, settings, robot=request.rig == "robot")
        except (OSError, ValueError) as err:
            raise ValueError(f"--scaling: {err}") from err
    if (problem := shipped_k_problem(name, settings.get("params"), request.scaling)) is not None:
        raise ValueError(problem)  # before the probe: a run that cannot plan is refused without moving the robot
    period = settings["control_period"]
    if not CONTROL_PERIOD_RANGE[0] <= period <= CONTROL_PERIOD_RANGE[1]:
        raise ValueError(f"the policy's control period {period} s is outside [{CONTROL_PERIOD_RANGE[0]}, "
                         f"{CONTROL_PERIOD_RANGE[1]}] s")
    return controller, model, settings, notes


def run_deployment(request: DeployRequest, notify: Callable[[str], None] | None = None) -> Deployment:
    """Run ``request``'s episodes; returns them in memory, and writes the files when it has an ``out`` folder.

    Args:
        request: The deployment.
        notify: Called with each note or warning line (the policy's unchecked settings, the probe of ``params``, a
            priority that could not be raised), before the episodes; ``None``: only collected in the result.

    Raises:
        ValueError: A setting is wrong (one line naming it), found by the checks, the devices or the env.
        DeployError: A device did not answer or an episode could not go on.
        KeyboardInterrupt: Ctrl-C (or SIGTERM's ``SystemExit``), after the fins were stopped.
    """
    lines: list[str] = []

    def say(line: str) -> None:
        lines.append(line)
        if notify is not None:
            notify(line)

    controller, model, settings, notes = _checked_settings(request)
    out = None if request.out is None else Path(request.out)
    created = [] if out is None else [p for p in (out, *out.parents) if not p.exists()]
    if out is not None:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ValueError(f"--out: cannot create {out}: {err}") from err
    for note in notes:
        say(f"note: {note}")
    # before any thread starts (threads inherit it); not in lockstep, where simulated time makes priority irrelevant
    warning = "" if request.rig == "lockstep" else raise_priority(request.nice)
    if warning:
        say(f"warning: {warning}")
    log: deploy_runs.Sink = io.StringIO() if out is None else out / "steps.jsonl"
    run_log: deploy_runs.Sink = io.StringIO() if out is None else out / "run.jsonl"
    name = request.controller_name
    try:
        if request.rig == "lockstep":
            if deploy_runs.probe_wanted(request, name):
                deploy_runs.probe_lockstep(request, settings, model, say)
            result = deploy_runs.run_lockstep_episodes(request, name, controller, settings, log, run_log)
        else:
            result = deploy_runs.run_real_time(request, name, controller, settings, model, log, run_log, say)
    except BaseException:  # a bad setting found by the devices, a device, Ctrl-C
        if out is not None:
            _remove_unstarted(out, created)
        raise
    summary = summary_report(request, settings, result)
    if out is not None:
        (out / "summary.json").write_text(json.dumps(summary, indent=2), encoding="utf-8")
        plot_trajectories(out / "steps.jsonl", out / "trajectory.png")
    summaries, link, solver, wall_time, ended = result
    return Deployment(summaries, _records(log), _records(run_log), link, solver, wall_time, ended, settings, summary,
                      lines)


def _records(sink: deploy_runs.Sink) -> list[dict[str, Any]]:
    """The JSON lines a run wrote to a file or a buffer (none where it wrote no file)."""
    if isinstance(sink, Path):
        text = sink.read_text(encoding="utf-8") if sink.is_file() else ""
    else:
        text = sink.getvalue()
    return [json.loads(line) for line in text.splitlines() if line]


def _remove_unstarted(out: Path, created: list[Path]) -> None:
    """Remove a failed run's files if no episode started (no step logged), and the folders made for them."""
    steps = out / "steps.jsonl"
    if steps.is_file() and steps.stat().st_size > 0:
        return  # the log so far: the error message points to it
    for name in ("steps.jsonl", "run.jsonl"):
        with contextlib.suppress(OSError):
            (out / name).unlink()
    for folder in created:  # deepest first
        with contextlib.suppress(OSError):
            folder.rmdir()  # only if empty
