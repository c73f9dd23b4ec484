"""Run a controller (a trained policy, the NMPC or the hand baseline) on the robotic fish (or the emulated one).

Examples (``pectoral-deploy``, also ``python -m pectoral_gym.hardware.deploy``)::

    pectoral-deploy --policy runs/ppo-goal --port /dev/ttyUSB0 --camera 0 --episodes 3
    pectoral-deploy --policy runs/ppo-goal/model.zip --emulate --speed 2 --episodes 1
    pectoral-deploy --controller nmpc --emulate --episodes 1
    pectoral-deploy --controller hand --emulate --lockstep --episodes 100 --jobs 2

``--controller nmpc`` plans on the averaged model (:class:`pectoral_gym.agents.nmpc.controller.NMPCController`, the same
controller as in simulation) with its step budget set to ``--solve-fraction`` of the control period
(wall time, so divided by ``--speed`` when emulated): a solve that fails or ends later than that is not
applied, and the rest of the last plan (then both fins at rest) is sent instead. In lockstep a step's
computing costs no simulated time (as in PX4's lockstep), so no budget applies: measure a controller's
timing in real time.

``--emulate --lockstep`` runs the emulated robot and the whole PC stack (the same link, firmware, supervisor,
camera renderer, tracker and observer) in simulated time (:mod:`pectoral_gym.hardware.emurig`): as fast as the
CPU allows, and the same run for the same seed. Each lockstep episode ``k`` runs on a fresh rig seeded with
``--seed + k``, so it does not depend on the episodes before it; ``--jobs J`` runs the episodes in ``J`` worker
processes with the same output (:mod:`pectoral_gym.hardware.lockstep_jobs`). ``--radio-*``, ``--camera-*`` and
``--pose-noise-*`` degrade the emulated radio and camera, seeded, in either timing.

Writes ``steps.jsonl`` (one JSON object per step: action, command sent, measured pose, estimate,
reward, ends, link and tracking health, and the true pose when emulated), ``run.jsonl`` (the run log a
model's calibration reads: episode starts, commands and stops as sent, every camera pose; ``docs/run-log.md``;
in lockstep the episodes follow one another, each shifted from its own clock), ``summary.json`` and
``trajectory.png`` into ``--out``. ``--emulate-params FILE`` gives the emulated fish other parameters than
Table 1's (a robot other than the one the controller was made for); ``--params FILE`` tells the PC side the
robot's own model: the geofence's stopping distance and outline, the fin replay; ``--scaling FILE`` the K
identified for it, which the hand law and the NMPC plan with. Ctrl-C and SIGTERM stop the fins before the program
ends.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np

from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.hardware.clock import REAL_CLOCK
from pectoral_gym.hardware.deploy_checks import (
    CONTROL_PERIOD_RANGE,
    check_frame_size,
    check_scaling,
    env_settings,
    first_frame,
    policy_preflight,
    raise_priority,
    shipped_k_problem,
)
from pectoral_gym.hardware.deploy_cli import check_args, make_parser, rig_conditions
from pectoral_gym.hardware.deploy_episodes import (  # re-exported: the deploy's episode loop
    EXIT_DISPLACED,
    displaced_reason,
    plot_trajectories,
    random_start,
    run_episode,
    run_episodes,
    write_report,
)
from pectoral_gym.hardware.emurig import RigConditions, open_rig
from pectoral_gym.hardware.params_probe import check_on_lockstep_rig, check_on_robot, probe_start
from pectoral_gym.hardware.safety.rules import SafetyConfig, install_stop_handlers
from pectoral_gym.hardware.signal_latch import SignalLatch
from pectoral_gym.model.params import FishParams

__all__ = ["EXIT_DISPLACED", "build_parser", "main", "make_controller", "plot_trajectories", "random_start",
           "run_episode",
           "run_episodes", "solver_summary"]


def make_controller(name: str, config, step_budget: float, safety: SafetyConfig | None = None,
                    scaling: str | None = None):
    """The ``nmpc`` or ``hand`` baseline for the robot's env config; NMPC steps end within ``step_budget`` [s].

    ``scaling``: the K file they plan with (:func:`pectoral_gym.agents.controllers.fin_map.planning_spec`), the
    robot's own where ``config.params`` are not Table 1's; ``None``: the shipped K.

    Both keep out of the stopping band of the env's geofence (``safety``, default
    :class:`pectoral_gym.hardware.safety.rules.SafetyConfig`) widened by
    :data:`pectoral_gym.registration.MEASUREMENT_MARGIN`, the band the v1 envs train and evaluate them with: the
    NMPC plans with it (``pectoral_gym.agents.controllers.stop_band``) and both filter their commands through
    the backup shield (``pectoral_gym.agents.controllers.band_shield``) with it, predicting through the firmware's
    command path; the NMPC's shield there also keeps a backup's side and wants
    :data:`pectoral_gym.agents.nmpc.shield.ROBOT_RESERVE` safe backups after a command. The NMPC plans no on-the-spot
    spins here (``spin=False``: through the robot's command path the spin cycle drifts where the planning model
    turns it on the spot); the shield keeps its spin backups. The measurements behind these choices are in the
    research notes (``docs/notes/2026-12-03-robot-stack-rounds.md``, ``docs/notes/2026-12-04-nmpc-stops-2.md``).
    """
    from pectoral_gym.agents.baselines import make_baseline
    from pectoral_gym.model.tank import StopRule
    from pectoral_gym.registration import MEASUREMENT_MARGIN

    safety = safety or SafetyConfig()
    band = StopRule(safety.geofence_margin + MEASUREMENT_MARGIN, safety.reaction_time, safety.contact_speed)
    if (problem := shipped_k_problem(name, config.params, scaling)) is not None:
        raise ValueError(problem)
    if name == "nmpc":
        return make_baseline("nmpc", config, step_budget=step_budget, stop_band=tuple(band), spin=False,
                             scaling=scaling)
    if name == "hand":
        return make_baseline("hand", config, shield={"band": band}, scaling=scaling)
    return make_baseline(name, config)


def solver_summary(controller) -> dict:
    """Solve times (p50/p95/max [ms]), failed and late steps of an NMPC controller."""
    times = np.asarray(controller.solve_times, dtype=float) * 1e3
    if times.size == 0:
        return {"solves": 0, "failures": int(controller.failures), "late": int(controller.late)}
    return {"solves": int(times.size), "p50_ms": float(np.percentile(times, 50)),
            "p95_ms": float(np.percentile(times, 95)), "max_ms": float(times.max()),
            "failures": int(controller.failures), "late": int(controller.late)}


class _RunError(Exception):
    """A device or an episode failed (exit status 1); the message says what and where."""


# summaries, link health, solver summary, wall time [s], why the run ended early ("" or a DISPLACED reason)
_RunResult = tuple[list[dict], dict, dict | None, float, str]


def _run_log(path: Path, args: argparse.Namespace, settings: dict):
    """The run's :class:`pectoral_gym.runlog.RunLogWriter` (header written) at ``path``."""
    from pectoral_gym.runlog import RunLogWriter

    return RunLogWriter(path, "emulator" if args.emulate else "robot", settings["control_period"])


def _run_real_time(parser: argparse.ArgumentParser, args: argparse.Namespace, controller, settings: dict,
                   safety: SafetyConfig, conditions: RigConditions, model, log_path: Path) -> _RunResult:
    """The episodes on one robot (real or emulated in real time), one after another on one rig and env.

    Returns:
        ``(summaries, link health, solver summary or None, wall time [s], ended)``: ``ended`` is
        ``"taken_over"`` or ``"robot_busy"`` if the robot came to serve another session (the run then ended at
        once and sent nothing more), else ``""``.

    Raises:
        _RunError: A device did not answer or an episode could not go on.
    """
    from pectoral_gym.hardware.env import HardwareFishEnv
    from pectoral_gym.hardware.radio.link import RadioLink
    from pectoral_gym.hardware.vision.tracker import MarkerTracker

    robot = env = None
    clock = REAL_CLOCK
    with contextlib.ExitStack() as resources:  # released last in, first out, on every path
        try:
            if args.emulate:
                clock, robot, port, camera = open_rig(resources, args.seed, conditions, False, args.speed,
                                                      args.emulate_params, args.firmware)
                inset = settings.get("start_inset", tk.START_INSET)  # the policy's own, as it trained
                hook = lambda rng: robot.place(*random_start(rng, inset))  # noqa: E731 - a hand puts the fish back
            else:
                from pectoral_gym.hardware.vision.camera import open_source

                camera = open_source(args.camera)
                resources.callback(camera.close)  # idempotent: the env closes it too
                port = args.port
                if args.robot_address is not None:
                    extra = {"take_over": True} if args.take_over else {}
                    port = RadioLink(args.port, dest64=args.robot_address, **extra)
                    resources.callback(port.close)
                hook = None if args.no_prompt else (lambda rng: input("Place the fish in the tank and press Enter: "))
            check_frame_size(first_frame(camera, clock=clock), model, args.calibration)
            env = HardwareFishEnv(port, camera, safety=safety, speed=args.speed, max_episode_steps=args.max_steps,
                                  reset_hook=hook, tracker=MarkerTracker(model), take_over=args.take_over,
                                  clock=clock, **settings)
            resources.callback(env.close)
            env.run_log = resources.enter_context(_run_log(log_path.with_name("run.jsonl"), args, settings))
            resources.callback(install_stop_handlers(env.stop))
            if controller is None:
                budget = args.solve_fraction * settings["control_period"] / args.speed
                controller = make_controller(args.controller, env.config, budget, safety, args.scaling)
            if _probe_wanted(args):
                _probe_note(check_on_robot(
                    env, settings.get("params", FishParams()), (lambda rng: robot.place(*probe_start()))
                    if args.emulate else None if args.no_prompt else (lambda rng: input(
                        "Place the fish near the tank's centre, heading along its length, for a 12 s check of "
                        "--params against the robot, and press Enter: ")), args.seed))
        except ValueError as err:  # the settings, found wrong by the devices or the env
            parser.error(str(err))
        except (RuntimeError, OSError) as err:  # a device that does not answer or cannot be opened
            raise _RunError(str(err)) from err
        started = time.perf_counter()
        try:
            summaries = run_episodes(env, controller, args.episodes, log_path, args.seed, robot,
                                     progress=not args.no_progress)
        except (RuntimeError, OSError) as err:  # e.g. no fish seen at reset, the robot not confirming a stop
            raise _RunError(f"{err} (log so far: {log_path})") from err
        wall_time = time.perf_counter() - started
        ended = displaced_reason(env)
    solver = solver_summary(controller) if hasattr(controller, "solve_times") else None
    return summaries, env.link.health(), solver, wall_time, ended  # the link's health once the env closed it


def _probe_wanted(args: argparse.Namespace) -> bool:
    """Whether the run checks its model against the robot first (:mod:`pectoral_gym.hardware.params_probe`).

    Every run on a real robot, and every emulated one whose robot or model is not Table 1's (``--params``,
    ``--emulate-params``; without either the emulated robot is the model by construction), but an identification
    run (``--controller excite``), whose purpose is to find the parameters the probe would check.
    """
    return args.controller != "excite" and (not args.emulate or args.params is not None
                                            or args.emulate_params is not None)


def _probe_note(result) -> None:
    print(f"note: --params checked against the robot: {result.excess * 1000:.1f} mm beyond the camera's noise "
          f"over a {result.duration:.0f} s probe", file=sys.stderr)


def _run_lockstep(parser: argparse.ArgumentParser, args: argparse.Namespace, controller, settings: dict,
                  safety: SafetyConfig, conditions: RigConditions, log_path: Path) -> _RunResult:
    """The episodes in lockstep, each on a fresh rig (:mod:`pectoral_gym.hardware.lockstep_jobs`), in ``--jobs``.

    ``log_path`` gets each episode's steps in episode order as soon as the episodes before it are done.

    Returns:
        ``(summaries, link health, solver summary or None, wall time [s])``: the link's counters summed over
        the episodes (:func:`pectoral_gym.hardware.lockstep_jobs.merge_link`).

    Raises:
        _RunError: An episode failed (its index and the error named; the log holds the episodes before it).
    """
    from pectoral_gym.hardware.lockstep_jobs import (
        EpisodeError,
        LockstepJob,
        merge_link,
        merge_solver,
        run_lockstep,
        shift_records,
    )

    job = LockstepJob(args.controller, None if args.policy is None else str(args.policy), args.seed, conditions,
                      settings, safety, args.max_steps, args.calibration, args.take_over, args.emulate_params,
                      args.scaling, args.firmware)
    started = time.perf_counter()
    with open(log_path, "w", encoding="utf-8") as log, _run_log(log_path.with_name("run.jsonl"), args,
                                                                  settings) as run_log, SignalLatch() as latch:
        written, last = 0, None

        def write(result) -> None:
            nonlocal written, last
            log.write(result.log)
            log.flush()
            records, last = shift_records(result.run_log, result.episode, last)
            for record in records:  # each through the writer's own check
                getattr(run_log, record.pop("type"))(**record)
            run_log.flush()
            written += 1
            latch.check()  # a signal whose exception the interpreter swallowed ends the run here

        try:
            results = run_lockstep(job, range(args.episodes), args.jobs, write, progress=not args.no_progress,
                                   controller=controller)
            latch.check()  # a signal lost during the last episode's clean-up
        except EpisodeError as err:
            if err.setup:  # the settings, found wrong by the rig or the env
                parser.error(str(err))
            if err.episode == written:  # the episodes before it are in: its own steps follow them
                log.write(err.log)
            raise _RunError(f"episode {err.episode}: {err} (log so far: {log_path})") from err
    wall_time = time.perf_counter() - started
    return ([r.summary for r in results], merge_link([r.link for r in results]),
            merge_solver([r.solver for r in results]), wall_time, "")  # a fresh rig per episode: nobody else


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-deploy`` (:func:`pectoral_gym.hardware.deploy_cli.make_parser`)."""
    return make_parser(__doc__.split("\n\n")[0])


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status.

    0 done, 1 a device failed, 2 via SystemExit: a bad argument, :data:`EXIT_DISPLACED` (3): the robot came to
    serve another session (``summary.json``'s ``ended``), 130: interrupted (Ctrl-C, after the fins were stopped).
    A run that fails before its first episode leaves no files behind (nor the ``--out`` folder it created).
    Every resource (emulated robot, radio link, camera, env) is released on every path out.
    """
    parser = build_parser()
    try:
        return _main(parser, parser.parse_args(argv))
    except KeyboardInterrupt:  # the stop handlers sent STOP first; the resources were released on the way out
        print(f"{parser.prog}: interrupted: the fins were stopped", file=sys.stderr)
        return 130


def _checked_inputs(parser: argparse.ArgumentParser, args: argparse.Namespace):
    """Every check of the arguments and their files that runs no code from them; ``parser.error`` on a fault.

    Returns ``(conditions, safety, camera model)``. A policy folder is code (its pickles run when loaded): only
    its ``config.yaml`` (YAML, safe) and its files' presence are checked here; :func:`_load_policy` comes last.
    """
    try:
        conditions = rig_conditions(args)
    except ValueError as err:
        parser.error(f"--radio-*, --camera-*, --pose-noise-*: {err}")
    check_args(parser, args)
    if args.controller == "policy":
        try:
            policy_preflight(args.policy)
        except (OSError, ValueError) as err:
            parser.error(f"cannot load policy {args.policy!r}: {err}")
    try:
        safety = SafetyConfig(geofence_margin=args.geofence, tracking_timeout=args.tracking_timeout)
    except ValueError as err:
        parser.error(f"safety settings (--geofence, --tracking-timeout): {err}")
    from pectoral_gym.hardware.vision.cameramodel import CameraModel

    try:
        model = CameraModel.default() if args.calibration is None else CameraModel.load(args.calibration)
    except (OSError, ValueError) as err:
        parser.error(f"--calibration: cannot load {args.calibration}: {err}")
    return conditions, safety, model


def _main(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    conditions, safety, model = _checked_inputs(parser, args)
    controller = None
    if args.controller == "policy":  # the pickles, after every other check of the inputs
        from pectoral_gym.agents.training.policy import load_policy  # lazy: agents/ pulls in torch

        try:
            controller = load_policy(args.policy)
        except (OSError, ValueError) as err:
            parser.error(f"cannot load policy {args.policy!r}: {err}")
    try:
        settings, notes = env_settings(controller, args.task, args.control_period)
    except ValueError as err:
        parser.error(f"policy {args.policy!r} does not fit: {err}")
    if args.params is not None:  # the robot's own model: the supervisor's stopping distance and outline come from it
        settings["params"] = args.params
    if args.scaling is not None:
        try:
            check_scaling(args.scaling, settings, robot=not args.emulate)
        except (OSError, ValueError) as err:
            parser.error(f"--scaling: {err}")
    if (problem := shipped_k_problem(args.controller, settings.get("params"), args.scaling)) is not None:
        parser.error(problem)  # before the probe: a run that cannot plan is refused without moving the robot
    period = settings["control_period"]
    if not CONTROL_PERIOD_RANGE[0] <= period <= CONTROL_PERIOD_RANGE[1]:
        parser.error(f"the policy's control period {period} s is outside [{CONTROL_PERIOD_RANGE[0]}, "
                     f"{CONTROL_PERIOD_RANGE[1]}] s")
    out = Path(args.out)
    created = [p for p in (out, *out.parents) if not p.exists()]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        parser.error(f"--out: cannot create {out}: {err}")
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    # before any thread starts (threads inherit it); not in lockstep, where simulated time makes priority irrelevant
    warning = "" if args.lockstep else raise_priority(args.nice)
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    try:
        if args.lockstep:
            if _probe_wanted(args):
                from pectoral_gym.hardware.vision.tracker import MarkerTracker

                try:
                    _probe_note(check_on_lockstep_rig(args.seed, conditions, args.emulate_params, safety=safety,
                                                      tracker=MarkerTracker(model), take_over=args.take_over,
                                                      **settings))
                except ValueError as err:
                    parser.error(str(err))
                except (RuntimeError, OSError) as err:
                    raise _RunError(str(err)) from err
            result = _run_lockstep(parser, args, controller, settings, safety, conditions, out / "steps.jsonl")
        else:
            result = _run_real_time(parser, args, controller, settings, safety, conditions, model,
                                    out / "steps.jsonl")
    except _RunError as err:
        _remove_unstarted(out, created)
        print(f"{parser.prog}: error: {err}", file=sys.stderr)
        return 1
    except BaseException:  # a bad setting found by the devices (SystemExit 2), Ctrl-C
        _remove_unstarted(out, created)
        raise
    return write_report(parser, args, out, settings, conditions, result)


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


if __name__ == "__main__":
    raise SystemExit(main())
