"""The command line of ``pectoral-deploy``: its arguments and every check of them alone."""

from __future__ import annotations

import argparse
import math

from pectoral_gym.hardware.deploy_checks import (
    CONTROL_PERIOD_RANGE,
    DEFAULT_NICE,
    MIN_TRACKING_WALL,
    NICE_RANGE,
    SPEED_RANGE,
    robot_address,
)
from pectoral_gym.hardware.emulated_firmware import FIRMWARES
from pectoral_gym.hardware.emurig import RigConditions
from pectoral_gym.model.tank import ROBOT_STOP_RULE
from pectoral_gym.tools.cli_common import HelpFormatter, prog_name

__all__ = ["check_args", "make_parser", "rig_conditions"]

_EXAMPLES = """examples:
  pectoral-deploy --policy runs/ppo-goal --emulate --speed 2 --episodes 2 --out dryrun
  pectoral-deploy --controller nmpc --emulate --speed 2 --episodes 1
  pectoral-deploy --controller hand --emulate --lockstep --episodes 100 --out lockstep
  pectoral-deploy --controller hand --emulate --lockstep --episodes 100 --jobs 2
  pectoral-deploy --controller hand --emulate --lockstep --radio-latency 0.1 \\
      --radio-loss 0.1 --camera-drop 0.1 --pose-noise-mm 5 --pose-noise-deg 2
  pectoral-deploy --policy runs/ppo-goal --port /dev/ttyUSB0 --camera 0 \\
      --calibration calibration.json --robot-address 0013A20012345678 --episodes 3 --out tank-run
  pectoral-deploy --controller excite --port /dev/ttyUSB0 --camera 0 \\
      --calibration calibration.json --episodes 6 --max-episode-steps 60 --out id-run   # an identification run
  pectoral-deploy --controller excite --emulate --lockstep --emulate-params robot_true.json \\
      --episodes 6 --max-episode-steps 60 --out id-run                                  # ... on an emulated robot

exit status: 0 done; 1 a device failed (no frame, no fish seen, robot not answering); 2 a bad argument;
  3 the robot serves another session (another PC took it over, or it was never ours): the run ended at once
  and sent nothing more, not even STOP (Ctrl-C still sends the operator's STOP)."""


def make_parser(description: str) -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-deploy`` (``description``: its first line)."""
    parser = argparse.ArgumentParser(prog=prog_name("pectoral-deploy", "pectoral_gym.hardware.deploy"),
                                     description=description, epilog=_EXAMPLES, formatter_class=HelpFormatter)
    lo_speed, hi_speed = SPEED_RANGE
    lo_period, hi_period = CONTROL_PERIOD_RANGE
    parser.add_argument("--controller", choices=("policy", "nmpc", "hand", "excite"), default="policy",
                        help="what drives the fish (default %(default)s: needs --policy; excite: an identification "
                             "run, seeded random fin patterns for the model's calibration, docs/run-log.md)")
    parser.add_argument("--policy", default=None, metavar="RUN_OR_ZIP",
                        help="pectoral_gym.agents.training.train or rl-baselines3-zoo run folder, or an SB3 .zip "
                             "(pectoral_gym.agents.training.policy.load_policy). A policy folder is code: its zip's "
                             "data section and vecnormalize.pkl are pickles, which run what they hold when loaded; "
                             "deploy only folders you made or trust (they are loaded after every other check)")
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
                             "simulated time, as fast as the CPU allows, each episode k on a fresh rig seeded "
                             "with --seed + k; the same seed gives the same run (no --speed)")
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
    parser.add_argument("--jobs", type=int, default=1, metavar="J",
                        help="--lockstep only: run the episodes in J worker processes, >= 1; the output is the same "
                             "for any J (default %(default)s: in this process)")
    parser.add_argument("--task", choices=("goal", "track"), default=None,
                        help="task (default: the policy's own from its run folder, else goal); a policy is refused "
                             "under another task than it was trained on")
    parser.add_argument("--control-period", type=float, default=None, metavar="S",
                        help=f"seconds between actions, in [{lo_period}, {hi_period}] (default: the policy's own "
                             "from its run folder, else 0.5); a policy is refused at another period")
    parser.add_argument("--max-episode-steps", dest="max_steps", type=int, default=240, metavar="N",
                        help="steps per episode, >= 1 (default %(default)s)")
    parser.add_argument("--speed", type=float, default=1.0,
                        help=f"emulated clock speed-up, in [{lo_speed}, {hi_speed}] (--emulate only; "
                             "default %(default)s)")
    parser.add_argument("--emulate-params", type=fish_params, default=None, metavar="JSON",
                        help="--emulate only: the emulated fish's parameters (a FishParams file, e.g. a robot "
                             "calibrated from its run logs; default: Table 1's)")
    parser.add_argument("--firmware", choices=FIRMWARES, default="python",
                        help="--emulate only: the emulated robot's rules, the Python reference, the C firmware "
                             "core, or the reference ticked every 10 ms as the C core is (default %(default)s)")
    parser.add_argument("--params", type=fish_params, default=None, metavar="JSON",
                        help="the robot's model parameters (a FishParams file, e.g. pectoral-scaling calibrate's "
                             "robot.json): the geofence's stopping distance and fish outline, the PC's fin replay "
                             "use them (default: Table 1's; a robot that coasts further or is larger than Table 1's "
                             "fish needs its own). Checked: every field within physical bounds, then, before the "
                             "first episode, a 12 s open-loop probe of the robot seen by the camera against the "
                             "model under these parameters (refused if they miss it; not with --controller excite). "
                             "The hand law and the NMPC plan with K: give them the robot's with --scaling")
    parser.add_argument("--scaling", default=None, metavar="JSON",
                        help="--controller hand|nmpc: the K file they plan with, identified for the robot's --params "
                             "(pectoral-scaling identify --params robot.json writes it: k/scaling_coefficients.json; "
                             "default: the shipped K, identified for Table 1's fish, which they refuse for other "
                             "--params)")
    parser.add_argument("--calibration", default=None, metavar="JSON",
                        help="camera calibration (pectoral-camera-calibrate), made at the "
                             "camera's resolution (default: the emulator's camera model)")
    parser.add_argument("--geofence", type=float, default=ROBOT_STOP_RULE.margin, metavar="M",
                        help="clearance kept from the walls on top of the stopping distance [m]: the margin of the "
                             "robot's stop rule, whose reaction time and contact speed stay the robot's "
                             "(default %(default)s)")
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
    parser.add_argument("--seed", type=int, default=0, help="seed of targets and emulated starts (episode k: "
                                                            "seed + k), >= 0 (default %(default)s)")
    parser.add_argument("--out", default="deploy_out", help="output folder (default %(default)s)")
    parser.add_argument("--no-prompt", action="store_true",
                        help="do not ask to place the fish before each episode (real robot)")
    parser.add_argument("--nice", type=int, default=DEFAULT_NICE, metavar="N",
                        help="run at this nice value, in [-20, 0]: above the machine's other work, so that frames "
                             "are tracked in time under CPU load (needs root or a 'nice' limit in "
                             "/etc/security/limits.conf; else a warning; 0: leave it as it is; not with --lockstep, "
                             "where simulated time makes it irrelevant) (default %(default)s)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def check_args(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Every range and combination check of the arguments alone; ``parser.error`` (exit 2) on the first fault."""
    if args.lockstep and not args.emulate:
        parser.error("--lockstep needs --emulate (a real robot runs in real time)")
    if args.emulate:
        extra = [flag for flag, value in (("--port", args.port), ("--camera", args.camera),
                                          ("--robot-address", args.robot_address)) if value is not None]
        if extra:
            parser.error(f"{' and '.join(extra)} cannot be used with --emulate (the emulated robot brings its own "
                         "radio and camera)")
    elif args.port is None or args.camera is None:
        parser.error("--port and --camera are required unless --emulate is given")
    if args.jobs < 1:
        parser.error(f"--jobs must be >= 1, got {args.jobs}")
    if args.jobs != 1 and not args.lockstep:
        parser.error("--jobs needs --emulate --lockstep (episodes run in parallel only in simulated time)")
    if args.lockstep and args.speed != 1.0:
        parser.error("--speed does not apply with --lockstep (simulated time runs as fast as the CPU allows)")
    if args.firmware != "python" and not args.emulate:
        parser.error("--firmware chooses the emulated robot's rules: it needs --emulate")
    if args.emulate_params is not None and not args.emulate:
        parser.error("--emulate-params gives the emulated fish its parameters: it needs --emulate")
    if not args.emulate and rig_conditions(args) != RigConditions():
        parser.error("--radio-*, --camera-* and --pose-noise-* degrade the emulated robot: they need --emulate")
    if (args.controller == "policy") != (args.policy is not None):
        parser.error("--policy is needed with --controller policy, and only then")
    from pectoral_gym.agents.baselines import scaling_flag_problem

    if (problem := scaling_flag_problem(args.controller, args.scaling)) is not None:
        parser.error(problem)
    for flag, value in (("--episodes", args.episodes), ("--max-episode-steps", args.max_steps)):
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
    if not (math.isfinite(args.tracking_timeout) and args.tracking_timeout / args.speed >= MIN_TRACKING_WALL):
        parser.error(f"--tracking-timeout must be a finite number with timeout / speed >= {MIN_TRACKING_WALL} s of "
                     f"wall time (3 frames at 30 fps), got {args.tracking_timeout} at speed {args.speed}")
    if args.control_period is not None and not (
            math.isfinite(args.control_period)
            and CONTROL_PERIOD_RANGE[0] <= args.control_period <= CONTROL_PERIOD_RANGE[1]):
        parser.error(f"--control-period must be in [{CONTROL_PERIOD_RANGE[0]}, {CONTROL_PERIOD_RANGE[1]}] s, "
                     f"got {args.control_period}")


def fish_params(path: str):
    """``--params``, ``--emulate-params``: a plausible robot's ``FishParams`` from a file.

    argparse's type: the file is read bounded (:mod:`pectoral_gym.inputfile`) and its parameters must pass the
    plausibility bounds (:func:`pectoral_gym.model.plausible.check_params`): both describe a robot.
    """
    from pectoral_gym.model.params import load_params
    from pectoral_gym.model.plausible import check_params

    try:
        params = load_params(path)
        check_params(params, path)
    except (OSError, ValueError) as err:
        raise argparse.ArgumentTypeError(f"cannot load {path!r}: {err}") from None
    from pectoral_gym.hardware.vision.tracker import TrackerConfig

    tracker = TrackerConfig()
    span = tracker.front_offset - tracker.back_offset + 2 * tracker.marker_radius
    if params.body_length < span:
        raise argparse.ArgumentTypeError(f"{path}: body_length {params.body_length:.3f} m cannot carry the tracker's "
                                         f"markers, {span:.3f} m from end to end (hardware/vision/scene.py)")
    return params


def rig_conditions(args: argparse.Namespace) -> RigConditions:
    """The emulated rig's conditions from the arguments (``ValueError`` if one is out of range)."""
    return RigConditions(args.radio_latency, args.radio_jitter, args.radio_loss, args.camera_latency,
                         args.camera_drop, (args.pose_noise_mm * 1e-3, math.radians(args.pose_noise_deg)))
