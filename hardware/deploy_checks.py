"""Checks of the deployment's settings before anything moves: ranges, the policy against the env, the camera.

The settings are ``pectoral_gym.hardware.deploy``'s.

Every check raises ``ValueError`` with a one-line message naming the setting and what is wrong (the command
line turns it into an argparse error, exit status 2), or ``RuntimeError`` for a device that does not
answer (exit status 1).

Bounds (argued where they are defined):

* :data:`SPEED_RANGE`: the emulated clock's speed-up.
* :data:`CONTROL_PERIOD_RANGE`: seconds between actions.
* :data:`MIN_TRACKING_WALL`: the tracking timeout in wall seconds.
* :data:`NICE_RANGE`: the scheduling priority (:func:`raise_priority`).
"""

from __future__ import annotations

import argparse
import math
import os
import re
from pathlib import Path
from typing import Any

from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.envs.layout import ACTION_SIZE
from pectoral_gym.envs.observation import OBS_SIZE, observation_size
from pectoral_gym.hardware.clock import REAL_CLOCK, Clock
from pectoral_gym.versions import ENV_VERSIONS, ROBOT, SIMULATION_IDS

__all__ = ["CONTROL_PERIOD_RANGE", "DEFAULT_NICE", "FIRST_FRAME_TIMEOUT", "MIN_TRACKING_WALL", "NICE_RANGE",
           "ROBOT_ENV_BASE", "SPEED_RANGE", "check_frame_size", "check_scaling", "env_settings", "first_frame",
           "policy_preflight", "raise_priority", "robot_address", "shipped_k_problem"]

# Nice values the deploy may ask for: [-20, 0] (never below the default priority). The PC's stack tracks 30 frames
# a second and must judge each within the safety rules' reaction budget (0.15 s); at the default priority, other
# work on a loaded machine delays it by more than that, and the supervisor stops the fish for want of a fresh
# pose (tracking_lost). A control process runs above the machine's other work, as real-time robot stacks do.
NICE_RANGE = (-20, 0)
DEFAULT_NICE = -5


def raise_priority(nice: int) -> str:
    """Run this thread, and every thread it starts afterwards, at nice value ``nice`` if that is higher priority.

    Call it before any thread starts (Linux keeps the nice value per thread; new threads inherit it). ``0``
    leaves the priority as it is (also a lower one the caller chose, e.g. ``nice -n 19``).

    Returns:
        ``""``, or why the priority could not be raised (no permission: root or a ``nice`` limit in
        ``/etc/security/limits.conf`` is needed).
    """
    current = os.getpriority(os.PRIO_PROCESS, 0)
    if nice == 0 or nice >= current:
        return ""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
    except OSError as err:
        return (f"could not raise this process's priority to nice {nice} ({err}); under CPU load its frames may be "
                "tracked late and the supervisor then stops the fish (tracking_lost): run it as a user allowed to "
                "(a 'nice' limit in /etc/security/limits.conf), or keep the machine otherwise idle")
    return ""

# Emulated speed-up [emulated s per wall s]. Below 0.1 a default episode (240 steps of 0.5 s) takes over 20 min
# of wall time: a slower value is a typo (1e-9 never progresses). Above 5 the PC cannot keep up with the
# emulator: the env's ACK timeout (0.05 s / speed) falls to 10 ms of wall time, 5 of the emulator's 2 ms I/O
# polls, and the in-process camera renders and tracks a 640x360 frame in 10-30 ms of wall time, i.e. one
# frame per 50-150 emulated ms at 5x: fewer than 4 frames in the default 0.5 s tracking timeout.
SPEED_RANGE = (0.1, 5.0)

# Seconds between actions [experiment s]. Below 0.1 s a step is shorter than the radio's keep-alive period
# (0.1 s: no copy of a command is repeated before the next replaces it, so one lost message loses the step)
# and holds fewer than 3 frames of a 30 fps camera (the step's mean velocity comes from them). The firmware
# lease (at most protocol.MAX_LEASE = 1 s per command, 0.8 s from step()) sets no upper bound because
# step() renews the lease while it runs; 2 s, the longest fin-beat period of the action space, is the
# longest a controller can act on and still change a pattern within each beat (the defaults train at 0.5 s).
CONTROL_PERIOD_RANGE = (0.1, 2.0)

# The tracking timeout in wall seconds (timeout / speed) must hold 3 frames of a 30 fps camera, so one dropped
# or late frame does not end the episode as tracking_lost. The upper bound is physical (the time to reach a
# wall from the last seen pose), checked by pectoral_gym.hardware.safety.rules.SafetyConfig.
MIN_TRACKING_WALL = 0.1

#: The id whose settings a robot env starts from: ``HardwareFishEnv`` builds a full-model ``EnvConfig`` with only
#: its own arguments set, on the defaults, which are this simulation-only id's (a setting absent from a policy's
#: run folder or from the deploy's arguments is this id's). Not the robot-ready latest id: its band and servo limit
#: imitate the supervisor and the firmware, which run for real on the robot (``hardware.stack.env_config``).
ROBOT_ENV_BASE = SIMULATION_IDS["full"]

FIRST_FRAME_TIMEOUT = 5.0  # wall seconds to wait for the camera's first frame (as the env's reset_timeout)

_HEX16 = re.compile(r"(0[xX])?([0-9A-Fa-f]{16})")


def robot_address(text: str) -> int:
    """The argparse type of ``--robot-address``: exactly 16 hex digits (an XBee's SH+SL), optional ``0x``."""
    match = _HEX16.fullmatch(text.strip())
    if match is None:
        raise argparse.ArgumentTypeError(f"expected the robot XBee's 64-bit address as 16 hex digits (SH then SL, "
                                         f"e.g. 0013A20012345678), got {text!r}")
    return int(match.group(2), 16)


def _same(a: Any, b: Any) -> bool:
    """Equal settings: numbers within 1e-9 relative, sequences element-wise (YAML gives lists, EnvConfig tuples)."""
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    return a == b


def _robot_env_defaults() -> EnvConfig:
    """The settings of :data:`ROBOT_ENV_BASE`: what a robot env runs with where nothing sets otherwise."""
    return EnvConfig(**ENV_VERSIONS[ROBOT_ENV_BASE].settings())


def env_settings(controller: Any, task: str | None, control_period: float | None) -> tuple[dict[str, Any], list[str]]:
    """The env settings to run ``controller`` with, checked against what it was trained on.

    A trained policy (:class:`pectoral_gym.agents.training.policy.SB3Controller`) must meet the env's action size (8)
    and one of its observation layouts (19 entries, or 27 with the replayed fin block: ``observe_fins``). Where its run
    folder records them (``trained``), the task and the control period default to the policy's own and an
    explicit other value is refused; the action ranges and the track reference speed are the policy's. A
    controller without ``trained`` runs any task; the hand and NMPC baselines (``controller`` ``None``) get the
    goals of the robot-ready envs (:data:`pectoral_gym.versions.ROBOT`). A policy trained through
    the simulated camera (``sensing``) or with the simulated control-loop timing (``timing``) gets a note, never
    the setting: ``HardwareFishEnv`` refuses both.

    Args:
        controller: The controller (or ``None`` for a baseline built from the env later).
        task: ``--task``, or ``None`` for the policy's own (``"goal"`` when unknown).
        control_period: ``--control-period`` [s], or ``None`` for the policy's own (0.5 s when unknown).

    Returns:
        ``(kwargs, notes)``: ``HardwareFishEnv`` keyword arguments (``task``, ``control_period``,
        ``observe_fins`` and any recorded action ranges), and notes on what could not be checked.

    Raises:
        ValueError: On a mismatch, naming the setting, both values and where the policy's comes from.
    """
    defaults = _robot_env_defaults()
    trained = dict(getattr(controller, "trained", None) or {})
    notes: list[str] = []
    kwargs: dict[str, Any] = {}
    obs_size = getattr(controller, "obs_size", None)
    if obs_size is not None:
        action_size = int(getattr(controller, "action_size", ACTION_SIZE))
        if action_size != ACTION_SIZE:
            raise ValueError(f"the policy returns {action_size} actions; the fish takes {ACTION_SIZE}")
        layouts = {observation_size(False): False, observation_size(True): True}
        if obs_size not in layouts:
            raise ValueError(f"the policy takes {obs_size} observation entries; the fish envs give {OBS_SIZE} "
                             f"(or {observation_size(True)} with observe_fins)")
        kwargs["observe_fins"] = layouts[obs_size]
        if "observe_fins" in trained and bool(trained["observe_fins"]) != layouts[obs_size]:
            raise ValueError(f"{controller.trained_from} says observe_fins={trained['observe_fins']} but the model "
                             f"takes {obs_size} observation entries: the run folder is inconsistent")
    source = getattr(controller, "trained_from", None) or "its run folder"
    for key, flag, given, fallback in (("task", "--task", task, defaults.task),
                                       ("control_period", "--control-period", control_period,
                                        defaults.control_period)):
        if key in trained:
            if given is not None and not _same(given, trained[key]):
                raise ValueError(f"the policy was trained with {key} {trained[key]!r} ({source}), not {given!r}: "
                                 f"pass {flag} {trained[key]} or leave {flag} out")
            kwargs[key] = trained[key]
        else:
            kwargs[key] = fallback if given is None else given
            if obs_size is not None:
                notes.append(f"the policy records no {key} (no pectoral_gym.agents.training.train config.yaml "
                             f"beside it): {flag} "
                             f"{kwargs[key]} is not checked against its training; only its observation size "
                             f"({obs_size}) and action size are")
    for key in ("bias_range", "amplitude_range", "period_range", "ratio_range", "ref_speed", "start_inset",
                "goal_inset"):
        if key in trained and not _same(trained[key], getattr(defaults, key)):
            kwargs[key] = tuple(trained[key]) if isinstance(trained[key], (list, tuple)) else trained[key]
    if trained.get("sensing") is not None:  # never passed on: the robot env observes through its own camera
        notes.append(f"the policy trained through the simulated camera (sensing, {source}); the robot env observes "
                     "through the real camera and observer, so sensing is not applied")
    if trained.get("timing") is not None:  # never passed on: the robot's loop and radio have their own timing
        notes.append(f"the policy trained with simulated command delays (timing, {source}); on the robot the radio "
                     "and the control loop bring their own, so timing is not applied")
    if controller is None and not _same(ROBOT.goal_inset, defaults.goal_inset):
        kwargs["goal_inset"] = ROBOT.goal_inset  # a baseline: the robot-ready envs' goals, the band leaves reachable
    return kwargs, notes


def first_frame(camera: Any, timeout: float = FIRST_FRAME_TIMEOUT, clock: Clock = REAL_CLOCK):
    """The camera's first frame, polling ``camera.read()`` for up to ``timeout`` seconds on ``clock``.

    Raises:
        RuntimeError: If no frame comes in time.
    """
    deadline = clock.monotonic() + timeout
    while True:
        frame = camera.read()
        if frame is not None:
            return frame
        if clock.monotonic() >= deadline:
            raise RuntimeError(f"no frame from the camera in {timeout:.0f} s; check --camera and the cable")
        clock.sleep(0.01)


def check_frame_size(frame: Any, model: Any, calibration: str | Path | None) -> None:
    """``ValueError`` unless ``frame``'s image has the size the camera model (``calibration``'s) is for."""
    height, width = frame.image.shape[:2]
    if (width, height) != (model.width, model.height):
        what = f"the calibration {calibration}" if calibration is not None else "the default camera model (no " \
                                                                                 "--calibration)"
        raise ValueError(f"the camera gives {width}x{height} px frames but {what} is for {model.width}x"
                         f"{model.height} px: calibrate at the camera's resolution "
                         "(pectoral-camera-calibrate) or set the camera to the calibrated one")


def check_scaling(path: str, settings: dict[str, Any], robot: bool = True) -> None:
    """``ValueError`` (one line) unless the K file ``path`` loads, bounded, and is plausible over the env's envelope.

    The envelope: the action ranges of ``settings`` (``env_settings``'s), else the env's defaults
    (:func:`pectoral_gym.model.plausible.check_k`). For a real ``robot`` the file must also hold the spline an
    identification writes; an emulated one also takes a ``--quick`` identification's file, which has none.
    """
    from pectoral_gym.model.kfunctions import ScalingFunctions
    from pectoral_gym.model.plausible import check_k

    defaults = _robot_env_defaults()
    ranges = tuple(tuple(settings.get(key, getattr(defaults, key)))
                   for key in ("bias_range", "amplitude_range", "period_range", "ratio_range"))
    check_k(ScalingFunctions.load(path), ranges, path, spline=robot)  # type: ignore[arg-type]


# Largest policy files read [bytes]: an SB3 zip of the MLPs trained here is under 1 MB, its VecNormalize pickle
# under 10 kB, a config.yaml under 10 kB; the bounds leave 100 times that for larger networks.
_POLICY_FILE_BYTES = {".zip": 256 << 20, ".pkl": 16 << 20, ".yaml": 1 << 20, ".yml": 1 << 20}


def policy_preflight(policy: str) -> None:
    """Check a ``--policy`` run folder or zip without running any of its code (nothing is unpickled).

    A policy folder is code: SB3's zip holds the policy's weights as torch state dicts but also a data section
    in which some entries are pickled, and ``vecnormalize*.pkl`` is a pickle; loading either runs whatever
    they hold. This checks what can be checked before that: the model file is there, every file the loader may
    read (the zip, the pickles, ``config.yaml``) is a regular file of plausible size (:data:`_POLICY_FILE_BYTES`;
    no device, no endless file), the zip is a zip, and ``config.yaml`` is a YAML mapping (read safely).

    Raises:
        FileNotFoundError: Neither a run folder with a model nor a ``.zip``.
        ValueError: A file that cannot be what it claims, naming it.
    """
    import zipfile

    path = Path(policy)
    if path.is_dir():
        folder, models = path, [path / name for name in ("best_model.zip", "model.zip")]
        models += sorted(path.glob("*.zip"))  # rl-baselines3-zoo: <env>.zip
        if not any(m.is_file() for m in models):
            raise FileNotFoundError(f"{path} has no model zip (best_model.zip, model.zip); is it a run folder?")
    elif path.suffix == ".zip" and path.exists():
        folder, models = path.parent, [path]
    else:
        raise FileNotFoundError(f"{path} is neither a run folder nor an SB3 .zip file")
    candidates = [*models, *folder.glob("*.pkl"), *folder.glob("*/*.pkl"), folder / "config.yaml"]
    for file in candidates:
        if not file.exists() and not file.is_symlink():
            continue
        if not file.is_file():
            raise ValueError(f"{file}: not a regular file (a device or a broken link)")
        limit = _POLICY_FILE_BYTES.get(file.suffix.lower(), 1 << 20)
        if file.stat().st_size > limit:
            raise ValueError(f"{file}: {file.stat().st_size} bytes, more than {limit} (not a policy file of ours)")
    for model in models:
        if model.is_file() and not zipfile.is_zipfile(model):
            raise ValueError(f"{model}: not a zip file (an SB3 model is one)")
    from pectoral_gym.agents.training.policy import read_config  # YAML's safe loader: runs no code

    read_config(folder)


def shipped_k_problem(controller: str, params: Any, scaling: str | None) -> str | None:
    """Why ``controller`` cannot plan with the shipped K for the robot ``params`` (``None``: it can, or needs no K).

    The hand law and the NMPC plan with K; the shipped K were identified for Table 1's fish.
    """
    if scaling is not None or controller not in ("hand", "nmpc") or params is None:
        return None
    from pectoral_gym.model.kfunctions import ScalingFunctions

    differ = sorted(ScalingFunctions.load(None).params_mismatch(params))
    if not differ:
        return None
    return (f"--controller {controller} plans with K, and the shipped K were identified for Table 1's fish, whose "
            f"{', '.join(differ)} differ from --params: give the robot's K with --scaling FILE (pectoral-scaling "
            "identify --params FILE writes it)")
