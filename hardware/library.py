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
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pectoral_gym.hardware import deploy_runs
from pectoral_gym.hardware.deploy_checks import (
    CONTROL_PERIOD_RANGE,
    check_scaling,
    env_settings,
    policy_preflight,
    raise_priority,
    shipped_k_problem,
)
from pectoral_gym.hardware.deploy_episodes import plot_trajectories
from pectoral_gym.hardware.deploy_request import CONTROLLERS, RIGS, DeployRequest  # re-exported: the request
from pectoral_gym.hardware.deploy_runs import DeployError

__all__ = ["CONTROLLERS", "RIGS", "DeployError", "DeployRequest", "Deployment", "run_deployment", "summary_report"]


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
    if name == "excite":  # an identification run has no goal: no episode ends by reaching one by chance
        settings["goal_radius"] = 0.0
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


def run_deployment(request: DeployRequest, notify: Callable[[str], None] | None = None,
                   workers: Any = None) -> Deployment:
    """Run ``request``'s episodes; returns them in memory, and writes the files when it has an ``out`` folder.

    Args:
        request: The deployment.
        notify: Called with each note or warning line (the policy's unchecked settings, the probe of ``params``, a
            priority that could not be raised), before the episodes; ``None``: only collected in the result.
        workers: For ``rig="lockstep"`` only: lockstep workers started before the request was known
            (:func:`pectoral_gym.hardware.lockstep_jobs.start_pool` with ``request.jobs``), which then run its
            episodes; the run ends them. ``None``: the run starts its own where ``request.jobs > 1``, before its
            checks, so that their start-up runs beside this process's (its imports, the policy's load).

    Raises:
        ValueError: A setting is wrong (one line naming it), found by the checks, the devices or the env.
        DeployError: A device did not answer or an episode could not go on.
        KeyboardInterrupt: Ctrl-C (or SIGTERM's ``SystemExit``), after the fins were stopped.
    """
    if workers is not None and request.rig != "lockstep":
        raise ValueError(f"workers serve lockstep runs only, not rig={request.rig!r}")
    if (workers is None and request.rig == "lockstep" and 1 < request.jobs <= request.episodes
            and isinstance(request.controller, str)):
        from pectoral_gym.hardware.lockstep_jobs import start_pool

        # at the workers' own priority: the run waits for their start-up, which never waits long for a core
        workers = start_pool(request.jobs, policy=request.controller == "policy", idle=False)
        try:
            return _run_deployment(request, notify, workers)
        finally:
            workers.close()  # a run that started has ended them already; one refused by the checks has not
    return _run_deployment(request, notify, workers)


def _run_deployment(request: DeployRequest, notify: Callable[[str], None] | None, workers: Any) -> Deployment:
    """:func:`run_deployment` with its workers (a pool, or ``None``) settled."""
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
            result = deploy_runs.run_lockstep_episodes(request, name, controller, settings, log, run_log, workers)
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
