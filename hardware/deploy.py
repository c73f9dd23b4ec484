"""Run a controller (a trained policy, the NMPC or the hand baseline) on the robotic fish (or the emulated one).

Examples::

    python -m pectoral_gym.hardware.deploy --policy runs/ppo-goal --port /dev/ttyUSB0 --camera 0 --episodes 3
    python -m pectoral_gym.hardware.deploy --policy runs/ppo-goal/model.zip --emulate --speed 2 --episodes 1
    python -m pectoral_gym.hardware.deploy --controller nmpc --emulate --episodes 1
    python -m pectoral_gym.hardware.deploy --controller hand --emulate --lockstep --episodes 100

``--controller nmpc`` plans on the averaged model (:class:`pectoral_gym.agents.nmpc.controller.NMPCController`, the same
controller as in simulation) with its step budget set to ``--solve-fraction`` of the control period
(wall time, so divided by ``--speed`` when emulated): a solve that fails or ends later than that is not
applied, and the rest of the last plan (then both fins at rest) is sent instead.

``--emulate --lockstep`` runs the emulated robot and the whole PC stack (the same link, firmware, supervisor,
camera renderer, tracker and observer) in simulated time (:mod:`pectoral_gym.hardware.emurig`): as fast as the
CPU allows, and the same run for the same seed. ``--radio-*``, ``--camera-*`` and ``--pose-noise-*`` degrade the
emulated radio and camera, seeded, in either timing.

Writes ``steps.jsonl`` (one JSON object per step: action, command sent, measured pose, estimate,
reward, ends, link and tracking health, and the true pose when emulated), ``summary.json`` and
``trajectory.png`` into ``--out``. Ctrl-C and SIGTERM stop the fins before the program ends.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from pathlib import Path

import numpy as np

from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.hardware.clock import REAL_CLOCK
from pectoral_gym.hardware.deploy_checks import (
    CONTROL_PERIOD_RANGE,
    DEFAULT_NICE,
    MIN_TRACKING_WALL,
    NICE_RANGE,
    SPEED_RANGE,
    check_frame_size,
    env_settings,
    first_frame,
    raise_priority,
    robot_address,
)
from pectoral_gym.hardware.emurig import RigConditions, open_rig
from pectoral_gym.hardware.safety.rules import SafetyConfig, install_stop_handlers

__all__ = ["main", "make_controller", "run_episodes", "plot_trajectories", "solver_summary"]


def _random_start(rng: np.random.Generator) -> tuple[float, float, float]:
    """A start pose as the simulated goal task draws one (tank inset by 0.3 m, any heading)."""
    x = tk.START_INSET + rng.random() * (tk.TANK_X - 2 * tk.START_INSET)
    y = tk.START_INSET + rng.random() * (tk.TANK_Y - 2 * tk.START_INSET)
    return x, y, -math.pi + 2 * math.pi * rng.random()


def run_episodes(env, controller, episodes: int, log_path: Path, seed: int | None = None, robot=None,
                 progress: bool = True) -> list[dict]:
    """Run ``episodes`` episodes; append one JSON line per step to ``log_path``; return per-episode summaries.

    A step's ``t`` is seconds since the episode's reset on the env's clock (simulated seconds in lockstep).
    """
    from tqdm import tqdm

    clock = getattr(env.unwrapped, "clock", REAL_CLOCK)

    summaries = []
    with open(log_path, "w", encoding="utf-8") as log, tqdm(total=episodes, desc="episodes",
                                                              disable=not progress) as bar:
        for episode in range(episodes):
            ep_seed = None if seed is None else seed + episode
            obs, info = env.reset(seed=ep_seed)
            controller.reset(ep_seed)
            ret, steps, t0 = 0.0, 0, clock.monotonic()
            record = {"episode": episode, "step": 0, "event": "reset", "pose": info["pose"],
                      "target": info["target"]}
            if robot is not None:
                record["true_pose"] = list(robot.pose())
            log.write(json.dumps(record) + "\n")
            while True:
                action = np.asarray(controller.act(obs), dtype=np.float32)
                obs, reward, terminated, truncated, info = env.step(action)
                ret += reward
                steps += 1
                record = {"episode": episode, "step": steps, "t": clock.monotonic() - t0,
                          "action": action.tolist(), "command": info["command"], "pose": info["pose"],
                          "estimate": info["estimate"], "target": env.unwrapped.target, "reward": reward,
                          "terminated": terminated, "truncated": truncated, "safety_stop": info["safety_stop"],
                          "distance": info["distance"], "link": info["link"], "tracking": info["tracking"]}
                if robot is not None:
                    record["true_pose"] = list(robot.pose())
                log.write(json.dumps(record) + "\n")
                if terminated or truncated:
                    break
            log.flush()
            summaries.append({"episode": episode, "return": ret, "steps": steps, "terminated": terminated,
                              "truncated": truncated, "safety_stop": info["safety_stop"],
                              "success": bool(info.get("is_success", False)), "final_distance": info["distance"]})
            bar.update(1)
    return summaries


def plot_trajectories(log_path: Path, png_path: Path) -> None:
    """Tank, measured/estimated path (and the true path when emulated) and targets of every episode."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    episodes: dict[int, list[dict]] = {}
    for line in Path(log_path).read_text(encoding="utf-8").splitlines():
        rec = json.loads(line)
        episodes.setdefault(rec["episode"], []).append(rec)
    fig, ax = plt.subplots(figsize=(9, 5))
    ax.add_patch(plt.Rectangle((0, 0), tk.TANK_X, tk.TANK_Y, fill=False, lw=2, color="k"))
    for k, recs in episodes.items():
        colour = f"C{k % 10}"
        est = np.array([r["estimate"][:2] for r in recs if "estimate" in r])
        if len(est):
            ax.plot(est[:, 0], est[:, 1], "-", color=colour, label=f"episode {k} estimate")
        true = np.array([r["true_pose"][:2] for r in recs if "true_pose" in r])
        if len(true):
            ax.plot(true[:, 0], true[:, 1], ":", color=colour, label=f"episode {k} true")
        start = recs[0]["pose"]
        ax.plot(start[0], start[1], "o", color=colour)
        targets = np.array([r["target"] for r in recs if "target" in r])
        ax.plot(targets[:, 0], targets[:, 1], "x", color=colour, ms=8)
    ax.set(xlim=(-0.05, tk.TANK_X + 0.05), ylim=(-0.05, tk.TANK_Y + 0.05), xlabel="X [m]", ylabel="Y [m]",
           title="Deployment: path (o start, x target)", aspect="equal")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(png_path, dpi=120)
    plt.close(fig)


def make_controller(name: str, config, step_budget: float, safety: SafetyConfig | None = None):
    """The ``nmpc`` or ``hand`` baseline for the robot's env config; NMPC steps end within ``step_budget`` [s].

    The NMPC plans with the stopping-distance band of the env's geofence (``safety``, default
    :class:`pectoral_gym.hardware.safety.rules.SafetyConfig`), so it does not swim into it
    (``pectoral_gym.agents.controllers.stop_band``).
    """
    from pectoral_gym.agents.baselines import make_baseline

    if name == "nmpc":
        safety = safety or SafetyConfig()
        band = (safety.geofence_margin, safety.reaction_time, safety.coast_horizon)
        return make_baseline("nmpc", config, step_budget=step_budget, stop_band=band)
    return make_baseline(name, config)


def solver_summary(controller) -> dict:
    """Solve times (p50/p95/max [ms]), failed and late steps of an NMPC controller."""
    times = np.asarray(controller.solve_times, dtype=float) * 1e3
    if times.size == 0:
        return {"solves": 0, "failures": int(controller.failures), "late": int(controller.late)}
    return {"solves": int(times.size), "p50_ms": float(np.percentile(times, 50)),
            "p95_ms": float(np.percentile(times, 95)), "max_ms": float(times.max()),
            "failures": int(controller.failures), "late": int(controller.late)}


_EXAMPLES = """examples:
  python -m pectoral_gym.hardware.deploy --policy runs/ppo-goal --emulate --speed 2 --episodes 2 --out dryrun
  python -m pectoral_gym.hardware.deploy --controller nmpc --emulate --speed 2 --episodes 1
  python -m pectoral_gym.hardware.deploy --controller hand --emulate --lockstep --episodes 100 --out lockstep
  python -m pectoral_gym.hardware.deploy --controller hand --emulate --lockstep --radio-latency 0.1 \
      --radio-loss 0.1 --camera-drop 0.1 --pose-noise-mm 5 --pose-noise-deg 2
  python -m pectoral_gym.hardware.deploy --policy runs/ppo-goal --port /dev/ttyUSB0 --camera 0 \
      --calibration calibration.json --robot-address 0013A20012345678 --episodes 3 --out tank-run

exit status: 0 done; 1 a device failed (no frame, no fish seen, robot not answering); 2 a bad argument."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m pectoral_gym.hardware.deploy",
                                     description=__doc__.split("\n\n")[0],
                                     epilog=_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    lo_speed, hi_speed = SPEED_RANGE
    lo_period, hi_period = CONTROL_PERIOD_RANGE
    parser.add_argument("--controller", choices=("policy", "nmpc", "hand"), default="policy",
                        help="what drives the fish (default %(default)s: needs --policy)")
    parser.add_argument("--policy", default=None, metavar="RUN_OR_ZIP",
                        help="pectoral_gym.agents.training.train or rl-baselines3-zoo run folder, or an SB3 .zip "
                             "(pectoral_gym.agents.training.policy.load_policy)")
    parser.add_argument("--solve-fraction", type=float, default=0.5, metavar="F",
                        help="nmpc: share of the control period a step's solves may take, in (0, 1] "
                             "(default %(default)s)")
    parser.add_argument("--port", default=None,
                        help="robot radio, a serial URL: /dev/ttyUSB0, socket://HOST:PORT, ... (required without "
                             "--emulate)")
    parser.add_argument("--camera", default=None,
                        help="camera index, stream URL, video file or emu://HOST:PORT (required without --emulate)")
    parser.add_argument("--emulate", action="store_true",
                        help="start an emulated robot and camera in this process (no --port, --camera, "
                             "--robot-address)")
    parser.add_argument("--lockstep", action="store_true",
                        help="--emulate only: run the emulated robot and this program's whole robot stack in "
                             "simulated time, as fast as the CPU allows; the same seed gives the same run "
                             "(no --speed)")
    for flag, unit, text in (("--radio-latency", "S", "one-way delay of each radio frame [s]"),
                             ("--radio-jitter", "S", "extra one-way radio delay, uniform in [0, S] [s]"),
                             ("--radio-loss", "P", "probability that a radio frame is lost, each way, in [0, 1)"),
                             ("--camera-latency", "S", "delay from a frame's capture to the PC [s]"),
                             ("--camera-drop", "P", "probability that a camera frame is lost, in [0, 1]"),
                             ("--pose-noise-mm", "MM", "standard deviation of the noise on the camera's X and Y [mm]"),
                             ("--pose-noise-deg", "DEG", "standard deviation of the noise on its heading [deg]")):
        parser.add_argument(flag, type=float, default=0.0, metavar=unit,
                            help=f"--emulate only, seeded: {text} (default %(default)s)")
    parser.add_argument("--episodes", type=int, default=1, help="number of episodes, >= 1 (default %(default)s)")
    parser.add_argument("--task", choices=("goal", "track"), default=None,
                        help="task (default: the policy's own from its run folder, else goal); a policy is refused "
                             "under another task than it was trained on")
    parser.add_argument("--control-period", type=float, default=None, metavar="S",
                        help=f"seconds between actions, in [{lo_period}, {hi_period}] (default: the policy's own "
                             "from its run folder, else 0.5); a policy is refused at another period")
    parser.add_argument("--max-steps", type=int, default=240, help="steps per episode, >= 1 (default %(default)s)")
    parser.add_argument("--speed", type=float, default=1.0,
                        help=f"emulated clock speed-up, in [{lo_speed}, {hi_speed}] (--emulate only; "
                             "default %(default)s)")
    parser.add_argument("--calibration", default=None, metavar="JSON",
                        help="camera calibration (python -m pectoral_gym.hardware.vision.calibrate), made at the "
                             "camera's resolution (default: the emulator's camera model)")
    parser.add_argument("--geofence", type=float, default=0.05, metavar="M",
                        help="clearance kept from the walls on top of the stopping distance [m] (default %(default)s)")
    parser.add_argument("--robot-address", type=robot_address, default=None, metavar="HEX",
                        help="64-bit address of the robot's XBee, 16 hex digits, e.g. 0013A20012345678 "
                             "(default: broadcast, which every robot on the channel obeys)")
    parser.add_argument("--take-over", action="store_true",
                        help="take control of a robot that another live session (a second PC, a leftover script) "
                             "is driving: the robot then obeys this program only, and the other session is told "
                             "it lost control. Without it such a robot refuses our commands (robot_busy). Use "
                             "only when you know nobody relies on the other session")
    parser.add_argument("--tracking-timeout", type=float, default=0.5, metavar="S",
                        help="stop when the fish has not been seen for this long [s]; at least "
                             f"{MIN_TRACKING_WALL} s of wall time (timeout / speed) (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of targets and emulated starts, >= 0 "
                                                            "(default %(default)s)")
    parser.add_argument("--out", default="deploy_out", help="output folder (default %(default)s)")
    parser.add_argument("--no-prompt", action="store_true",
                        help="do not ask to place the fish before each episode (real robot)")
    parser.add_argument("--nice", type=int, default=DEFAULT_NICE, metavar="N",
                        help="run at this nice value, in [-20, 0]: above the machine's other work, so that frames "
                             "are tracked in time under CPU load (needs root or a 'nice' limit in "
                             "/etc/security/limits.conf; else a warning; 0: leave it) (default %(default)s)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def _check_args(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Every range and combination check of the arguments alone; ``parser.error`` (exit 2) on the first fault."""
    if args.emulate:
        extra = [flag for flag, value in (("--port", args.port), ("--camera", args.camera),
                                          ("--robot-address", args.robot_address)) if value is not None]
        if extra:
            parser.error(f"{' and '.join(extra)} cannot be used with --emulate (the emulated robot brings its own "
                         "radio and camera)")
    elif args.port is None or args.camera is None:
        parser.error("--port and --camera are required unless --emulate is given")
    if args.lockstep and not args.emulate:
        parser.error("--lockstep needs --emulate (a real robot runs in real time)")
    if args.lockstep and args.speed != 1.0:
        parser.error("--speed does not apply with --lockstep (simulated time runs as fast as the CPU allows)")
    if not args.emulate and rig_conditions(args) != RigConditions():
        parser.error("--radio-*, --camera-* and --pose-noise-* degrade the emulated robot: they need --emulate")
    if (args.controller == "policy") != (args.policy is not None):
        parser.error("--policy is needed with --controller policy, and only then")
    for flag, value in (("--episodes", args.episodes), ("--max-steps", args.max_steps)):
        if value < 1:
            parser.error(f"{flag} must be >= 1, got {value}")
    if args.seed < 0:
        parser.error(f"--seed must be >= 0, got {args.seed}")
    if not math.isfinite(args.speed) or not SPEED_RANGE[0] <= args.speed <= SPEED_RANGE[1]:
        parser.error(f"--speed must be in [{SPEED_RANGE[0]}, {SPEED_RANGE[1]}] (what the emulator keeps up with), "
                     f"got {args.speed}")
    if args.speed != 1.0 and not args.emulate:
        parser.error("--speed applies with --emulate only (a real robot runs in real time)")
    if not NICE_RANGE[0] <= args.nice <= NICE_RANGE[1]:
        parser.error(f"--nice must be in [{NICE_RANGE[0]}, {NICE_RANGE[1]}], got {args.nice}")
    if not 0 < args.solve_fraction <= 1:
        parser.error(f"--solve-fraction must be in (0, 1], got {args.solve_fraction}")
    if not (math.isfinite(args.geofence) and args.geofence >= 0):
        parser.error(f"--geofence must be a finite number >= 0 m, got {args.geofence}")
    if not (math.isfinite(args.tracking_timeout) and args.tracking_timeout / args.speed >= MIN_TRACKING_WALL):
        parser.error(f"--tracking-timeout must be a finite number with timeout / speed >= {MIN_TRACKING_WALL} s of "
                     f"wall time (3 frames at 30 fps), got {args.tracking_timeout} at speed {args.speed}")
    if args.control_period is not None and not (
            math.isfinite(args.control_period)
            and CONTROL_PERIOD_RANGE[0] <= args.control_period <= CONTROL_PERIOD_RANGE[1]):
        parser.error(f"--control-period must be in [{CONTROL_PERIOD_RANGE[0]}, {CONTROL_PERIOD_RANGE[1]}] s, "
                     f"got {args.control_period}")


def rig_conditions(args: argparse.Namespace) -> RigConditions:
    """The emulated rig's conditions from the arguments (``ValueError`` if one is out of range)."""
    return RigConditions(args.radio_latency, args.radio_jitter, args.radio_loss, args.camera_latency,
                         args.camera_drop, (args.pose_noise_mm * 1e-3, math.radians(args.pose_noise_deg)))


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status (0 done, 1 a device failed; 2 via SystemExit: bad argument).

    Every resource (emulated robot, radio link, camera, env) is released on every path out.
    """
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        conditions = rig_conditions(args)
    except ValueError as err:
        parser.error(f"--radio-*, --camera-*, --pose-noise-*: {err}")
    _check_args(parser, args)
    controller = None
    if args.controller == "policy":
        from pectoral_gym.agents.training.policy import load_policy  # lazy: agents/ pulls in torch

        try:
            controller = load_policy(args.policy)
        except (OSError, ValueError) as err:
            parser.error(f"cannot load policy {args.policy!r}: {err}")
    try:
        settings, notes = env_settings(controller, args.task, args.control_period)
    except ValueError as err:
        parser.error(f"policy {args.policy!r} does not fit: {err}")
    period = settings["control_period"]
    if not CONTROL_PERIOD_RANGE[0] <= period <= CONTROL_PERIOD_RANGE[1]:
        parser.error(f"the policy's control period {period} s is outside [{CONTROL_PERIOD_RANGE[0]}, "
                     f"{CONTROL_PERIOD_RANGE[1]}] s")
    try:
        safety = SafetyConfig(geofence_margin=args.geofence, tracking_timeout=args.tracking_timeout)
    except ValueError as err:
        parser.error(f"safety settings (--geofence, --tracking-timeout): {err}")
    from pectoral_gym.hardware.env import HardwareFishEnv
    from pectoral_gym.hardware.radio.link import RadioLink
    from pectoral_gym.hardware.vision.cameramodel import CameraModel
    from pectoral_gym.hardware.vision.tracker import MarkerTracker

    try:
        model = CameraModel.default() if args.calibration is None else CameraModel.load(args.calibration)
    except (OSError, ValueError) as err:
        parser.error(f"--calibration: cannot load {args.calibration}: {err}")
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        parser.error(f"--out: cannot create {out}: {err}")
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    warning = raise_priority(args.nice)  # before any thread starts: threads inherit it
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    robot = env = None
    clock = REAL_CLOCK
    with contextlib.ExitStack() as resources:  # released last in, first out, on every path
        try:
            if args.emulate:
                clock, robot, port, camera = open_rig(resources, args.seed, conditions, args.lockstep, args.speed)
                hook = lambda rng: robot.place(*_random_start(rng))  # noqa: E731 - a hand that puts the fish back
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
            resources.callback(install_stop_handlers(env.stop))
            if controller is None:
                controller = make_controller(args.controller, env.config, args.solve_fraction * period / args.speed,
                                             safety)
        except ValueError as err:  # the settings, found wrong by the devices or the env
            parser.error(str(err))
        except (RuntimeError, OSError) as err:  # a device that does not answer or cannot be opened
            print(f"{parser.prog}: error: {err}", file=sys.stderr)
            return 1
        try:
            summaries = run_episodes(env, controller, args.episodes, out / "steps.jsonl", args.seed, robot,
                                     progress=not args.quiet)
        except (RuntimeError, OSError) as err:  # e.g. no fish seen at reset, the robot not confirming a stop
            print(f"{parser.prog}: error: {err} (log so far: {out / 'steps.jsonl'})", file=sys.stderr)
            return 1
    link = env.link.health()
    report = {"controller": args.controller, "policy": None if args.policy is None else str(args.policy),
              "settings": {k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()},
              "episodes": summaries, "link": link}
    if hasattr(controller, "solve_times"):
        report["solver"] = solver_summary(controller)
    (out / "summary.json").write_text(json.dumps(report, indent=2), encoding="utf-8")
    plot_trajectories(out / "steps.jsonl", out / "trajectory.png")
    for s in summaries:
        print(f"episode {s['episode']}: return {s['return']:.3f}, {s['steps']} steps, "
              f"stop: {s['safety_stop'] or ('success' if s['success'] else 'end')}")
    print(f"log {out / 'steps.jsonl'}, plot {out / 'trajectory.png'}; link: sent {link['sent']}, "
          f"acked {link['acked']}, retries {link['retries']}, crc errors {link['crc_errors']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
