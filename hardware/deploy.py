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

This module is the command line of :func:`pectoral_gym.hardware.library.run_deployment` (the same run from Python,
its episodes returned in memory): it maps the arguments to a :class:`~pectoral_gym.hardware.library.DeployRequest`
and the library's errors to exit statuses.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from pectoral_gym.hardware.deploy_checks import env_settings
from pectoral_gym.hardware.deploy_cli import check_args, make_parser, rig_conditions
from pectoral_gym.hardware.deploy_controllers import make_controller, solver_summary
from pectoral_gym.hardware.deploy_episodes import plot_trajectories, random_start, run_episode, run_episodes
from pectoral_gym.hardware.library import DeployError, Deployment, DeployRequest, run_deployment
from pectoral_gym.hardware.safety.rules import SafetyConfig
from pectoral_gym.model.tank import ROBOT_STOP_RULE

# re-exported, where callers have long found them: the episode loop, the controllers, the env settings
__all__ = ["EXIT_DISPLACED", "build_parser", "env_settings", "main", "make_controller", "plot_trajectories",
           "random_start", "report_lines", "run_episode", "run_episodes",
           "solver_summary"]

#: Exit status of a run displaced by another session (``taken_over``, ``robot_busy``): it ended at once.
EXIT_DISPLACED = 3

_DISPLACED_TEXT = {"taken_over": "another session took the robot over (taken_over)",
                   "robot_busy": "the robot serves another live session (robot_busy; --take-over takes it over)"}


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


def request_from_args(parser: argparse.ArgumentParser, args: argparse.Namespace) -> DeployRequest:
    """The request the arguments ask for; ``parser.error`` (exit 2) on a fault of the arguments alone."""
    try:
        conditions = rig_conditions(args)
    except ValueError as err:
        parser.error(f"--radio-*, --camera-*, --pose-noise-*: {err}")
    check_args(parser, args)
    try:
        rule = dataclasses.replace(ROBOT_STOP_RULE, margin=args.geofence)  # the rule checks the margin
    except ValueError as err:
        parser.error(f"--geofence: {err}")
    try:
        safety = SafetyConfig(stop_rule=rule, tracking_timeout=args.tracking_timeout)
    except ValueError as err:
        parser.error(f"safety settings (--tracking-timeout): {err}")
    rig = "robot" if not args.emulate else "lockstep" if args.lockstep else "emulated"
    try:
        return DeployRequest(
            controller=args.controller, policy=args.policy, episodes=args.episodes, seed=args.seed, task=args.task,
            control_period=args.control_period, rig=rig, port=args.port, camera=args.camera,
            robot_address=args.robot_address, prompt=not args.no_prompt, speed=args.speed, conditions=conditions,
            emulate_params=args.emulate_params, firmware=args.firmware, take_over=args.take_over, safety=safety,
            params=args.params, scaling=args.scaling, calibration=args.calibration,
            solve_fraction=args.solve_fraction, jobs=args.jobs, max_episode_steps=args.max_steps, nice=args.nice,
            out=args.out, progress=not args.no_progress)
    except ValueError as err:  # what check_args lets through: the request's own checks
        parser.error(str(err))


def _main(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    request = request_from_args(parser, args)
    try:
        run = run_deployment(request, notify=lambda line: print(line, file=sys.stderr))
    except ValueError as err:  # a setting, found wrong by the checks, the devices or the env
        parser.error(str(err))
    except DeployError as err:
        print(f"{parser.prog}: error: {err}", file=sys.stderr)
        return 1
    return _report(parser, request, run)


def report_lines(request: DeployRequest, run: Deployment) -> list[str]:
    """The lines ``pectoral-deploy`` prints once a run is done: each episode's ending, the log, the link."""
    out = Path(request.out) if request.out is not None else None
    lines = [f"episode {s['episode']}: return {s['return']:.3f}, {s['steps']} steps, "
             f"stop: {s['safety_stop'] or ('success' if s['success'] else 'end')}" for s in run.episodes]
    link = run.link
    where = "in memory" if out is None else f"log {out / 'steps.jsonl'}, plot {out / 'trajectory.png'}"
    lines.append(f"{where}; link: sent {link['sent']}, acked {link['acked']}, retries {link['retries']}, crc errors "
                 f"{link['crc_errors']}; {len(run.episodes)} episodes in {run.wall_time:.1f} s wall time")
    return lines


def _report(parser: argparse.ArgumentParser, request: DeployRequest, run: Deployment) -> int:
    """Print the run's lines; returns the exit status (0, or :data:`EXIT_DISPLACED`, said so)."""
    for line in report_lines(request, run):
        print(line)
    if run.ended:
        print(f"{parser.prog}: {_DISPLACED_TEXT[run.ended]}: this run ended after {len(run.episodes)} of "
              f"{request.episodes} episodes and sends nothing more (summary.json: ended)", file=sys.stderr)
        return EXIT_DISPLACED
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
