"""Run logs with a known truth: an emulated robot with other parameters than Table 1, driven by identification commands.

The fish is simulated as the emulator simulates it (``hardware/emulator.py``): the full model at its
reference steps, its fins run by the firmware's rules through
:class:`pectoral_gym.model.finreplay.FinReplay` (:func:`~pectoral_gym.model.finrules.apply_firmware` and
:func:`~pectoral_gym.model.finrules.advance_with_firmware`, the emulator's own two functions). The
commands are an identification sequence: seeded random fin patterns from the envs' action space
(:meth:`pectoral_gym.envs.config.EnvConfig.decode`, within the servo envelope), each held 2-6 s, some with
both fins still so the fish coasts. A camera at 30 fps stamps each frame with its capture time, adds
Gaussian pose noise and drops frames at random, seeded. When the fish's outline comes within
``wall_margin`` of a wall the fins are stopped and, after a pause, the fish is placed at rest at the
tank's centre with a random heading in a new episode, as a user would.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from pectoral_gym.envs.config import EnvConfig
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import CHUNK, FirmwareConfig
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.servo import ROBOT_MAX_FIN_RATE
from pectoral_gym.model.tank import TANK_LENGTH, TANK_WIDTH, Outline, clearance
from pectoral_gym.runlog import RunLogWriter
from pectoral_gym.scaling.calibration.identifiability import UNCERTAIN_FIELDS

__all__ = ["UNCERTAIN_FIELDS", "Camera", "identification_beats", "perturbed_params", "write_synthetic_log"]



@dataclass(frozen=True)
class Camera:
    """The emulated camera of a synthetic log.

    Attributes:
        fps: Frame rate [1/s].
        position_noise: Standard deviation of each position coordinate [m].
        heading_noise: Standard deviation of the heading [rad].
        drop: Probability that a frame is lost [-].
    """

    fps: float = 30.0
    position_noise: float = 0.001
    heading_noise: float = math.radians(0.5)
    drop: float = 0.0


#: The degraded camera of the calibration's targets: 5 mm, 2 deg, 10 % of the frames lost.
DEGRADED = Camera(position_noise=0.005, heading_noise=math.radians(2.0), drop=0.1)


def perturbed_params(seed: int, spread: float = 0.3, base: FishParams | None = None,
                     fields: tuple[str, ...] = UNCERTAIN_FIELDS) -> FishParams:
    """``base`` (Table 1) with each of ``fields`` times a seeded factor drawn from ``U(1 - spread, 1 + spread)``."""
    base = base or FishParams()
    rng = np.random.default_rng([27, seed])
    factors = rng.uniform(1.0 - spread, 1.0 + spread, len(fields))
    return base.replace(**{name: getattr(base, name) * float(f) for name, f in zip(fields, factors, strict=True)})


def asymmetric_params(seed: int, base: FishParams, force_spread: float = 0.3,
                      offset_spread: float = 0.1) -> FishParams:
    """``base`` with fins that differ, seeded.

    The left fin's force factor from ``U(1 - force_spread, 1 + force_spread)`` and each fin's servo offset from
    ``U(-offset_spread, offset_spread)`` [rad]: the fields ``calibrate --asymmetric`` fits
    (:data:`~pectoral_gym.scaling.calibration.identifiability.ASYMMETRY_FIELDS`).
    """
    rng = np.random.default_rng([28, seed])
    return base.replace(fin_force_scale_left=float(rng.uniform(1.0 - force_spread, 1.0 + force_spread)),
                        fin_angle_offset_right=float(rng.uniform(-offset_spread, offset_spread)),
                        fin_angle_offset_left=float(rng.uniform(-offset_spread, offset_spread)))


def identification_beats(rng: np.random.Generator, coast: float = 0.15) -> np.ndarray:
    """One identification command ``(2, 4)``: a random pattern per fin from the envs' action space, or a coast.

    With probability ``coast`` both fins hold still at 90 deg (the fish coasts: drag against mass).
    """
    if rng.random() < coast:
        return np.stack([FinBeat.rest().as_array()] * 2)
    config = EnvConfig(servo_limit=ROBOT_MAX_FIN_RATE)
    return config.decode(rng.uniform(-1.0, 1.0, (2, 4)))


def _place(replay: FinReplay, x: float, y: float, psi: float) -> None:
    """A hand puts the fish at rest at ``(x, y, psi)``; the servos stay where they are (``EmulatedRobot.place``)."""
    model = replay.model
    time_now = model.time
    angles = model.fin_angles()[0][0]
    model.reset(np.array([x, y, psi, 0.0, 0.0, 0.0]), right=FinBeat.rest(float(angles[0])),
                left=FinBeat.rest(float(angles[1])), index=np.arange(1))
    model.time = time_now


def write_synthetic_log(path: str | os.PathLike, params: FishParams, seed: int, duration: float = 180.0,
                        camera: Camera | None = None, hold: tuple[float, float] = (2.0, 6.0),
                        episode_length: float | None = None, tank: bool = True, wall_margin: float = 0.12,
                        known_params: dict[str, float] | None = None,
                        firmware: FirmwareConfig | None = None, tick_aligned: bool = True) -> dict[str, float]:
    """Write a run log of an emulated robot with parameters ``params`` (the truth), seeded.

    Args:
        path: The log to write.
        params: The emulated robot's parameters.
        seed: Seeds the commands, the headings, the camera noise and the frame drops.
        duration: Logged robot time [s] (the sum of the episodes, pauses excluded).
        camera: Frame rate, pose noise and frame drops (default :class:`Camera`: 1 mm, 0.5 deg, no drops).
        hold: Range of the time each command is held [s].
        episode_length: End an episode (stop, new episode at the centre) after this long [s]; ``None``: only at
            the walls.
        tank: Stop and re-place the fish near the walls; ``False``: the model has no walls, the fish swims on
            (held-out open-loop runs longer than the tank allows).
        wall_margin: Least clearance of the fish's outline from a wall before it is re-placed [m].
        known_params: Written to the header's ``known_params``.
        firmware: The firmware settings (default :class:`FirmwareConfig`).
        tick_aligned: Stamp frames and commands on the firmware's 10 ms tick grid (frames 3-4 ticks apart), so
            the PC's replay ticks where the emulated robot ticked. ``False``: the emulated robot ticks between
            frames at other instants than the replay, and a latch can fall a tick apart, as on a real robot
            (:mod:`pectoral_gym.model.finreplay`); the fit then meets that mismatch as model error
            (docs/calibration.md).

    Returns:
        ``{"episodes": count, "duration": logged robot time [s]}``.
    """
    rng = np.random.default_rng([27, 1, seed])
    camera = camera or Camera()
    firmware = firmware or FirmwareConfig()
    replay = FinReplay(params, firmware)  # the emulator's fins and body: full model, reference steps
    outline = Outline.from_params(params)
    dt = 1.0 / camera.fps
    t, logged, episode = 0.0, 0.0, 0
    with RunLogWriter(path, "synthetic", 0.5, firmware, known_params) as log:
        while logged < duration - 1e-9:
            _place(replay, 0.5 * TANK_LENGTH, 0.5 * TANK_WIDTH, rng.uniform(-math.pi, math.pi))
            log.episode(episode, t)
            start, next_command, frame = t, t, t
            grid = (lambda s: round(s / CHUNK) * CHUNK) if tick_aligned else (lambda s: s)
            limit = min(duration - logged, episode_length or math.inf)
            while True:
                if grid(frame) >= grid(next_command) - 1e-12:
                    log.command(grid(next_command), (beats := identification_beats(rng)))
                    replay.command(grid(next_command), beats)
                    next_command += rng.uniform(*hold)
                replay.advance(grid(frame))
                x, y, psi = replay.model.state[0, :3]
                if rng.random() >= camera.drop:
                    noisy = rng.normal(0.0, [camera.position_noise, camera.position_noise, camera.heading_noise])
                    heading = math.remainder(psi + noisy[2], 2.0 * math.pi)
                    log.pose(grid(frame), x + noisy[0], y + noisy[1], heading, float(rng.uniform(0.9, 1.0)))
                near_wall = tank and float(np.min(clearance(x, y, psi, outline))) < wall_margin
                if near_wall or frame - start >= limit:
                    break
                frame += dt
            replay.stop(grid(frame))
            log.stop(grid(frame))
            logged += frame - start
            t = grid(frame + 1.0)  # the hand's pause between episodes
            replay.advance(t)
            episode += 1
    return {"episodes": episode, "duration": logged}
