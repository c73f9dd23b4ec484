"""An emulated robot rig for ``deploy --emulate``: the robot, its radio and its camera, under seeded conditions.

:func:`open_rig` starts an :class:`pectoral_gym.hardware.emulator.EmulatedRobot` and gives the PC side its radio
port and camera, in one of two timings:

* real time (``lockstep=False``): the robot serves TCP on loopback; a
  :class:`pectoral_gym.hardware.radio.radioproxy.RadioProxy` sits in between when the radio is degraded; its
  clock runs ``speed`` times the wall clock;
* lockstep (``lockstep=True``): every thread of the robot and of the PC's stack runs on one
  :class:`pectoral_gym.hardware.clock.VirtualClock`, the radio is an in-process
  :class:`pectoral_gym.hardware.radio.pipe.StreamPair`: simulated time, as fast as the CPU allows, the same
  run for the same seed.

Both apply the same :class:`RigConditions`: radio latency, jitter and loss
(:class:`pectoral_gym.hardware.radio.channel.RadioChannel`), camera latency and frame drops
(:class:`pectoral_gym.hardware.vision.camerafaults.FaultyCamera`) and pose noise
(:class:`pectoral_gym.hardware.vision.camera.EmulatedCamera`), each from a generator of its own seeded by the
rig's seed (a lockstep deployment opens one rig per episode ``k``, seeded with ``--seed + k``:
:mod:`pectoral_gym.hardware.lockstep_jobs`).
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Any

from pectoral_gym.hardware.clock import REAL_CLOCK, Clock, VirtualClock
from pectoral_gym.hardware.radio.channel import RadioChannel

__all__ = ["RigConditions", "open_rig", "lockstep_session"]

# Generator streams derived from the rig's seed, one per condition (the camera's image noise uses the seed itself).
_RADIO_STREAM, _CAMERA_STREAM, _SESSION_STREAM = 2, 3, 4


@dataclass(frozen=True)
class RigConditions:
    """Seeded imperfections of the emulated radio and camera (defaults: none).

    Attributes:
        radio_latency: One-way delay of each radio frame [robot s], >= 0.
        radio_jitter: Extra one-way delay, uniform in ``[0, radio_jitter]`` [robot s], >= 0 (frames keep order).
        radio_loss: Probability that a radio frame is lost, each direction, in ``[0, 1)``.
        camera_latency: Delay from a frame's capture to its delivery to the PC [robot s], >= 0.
        camera_drop: Probability that a camera frame is lost, in ``[0, 1]``.
        pose_noise: ``(metres, radians)`` standard deviations of Gaussian noise on each rendered pose.
    """

    radio_latency: float = 0.0
    radio_jitter: float = 0.0
    radio_loss: float = 0.0
    camera_latency: float = 0.0
    camera_drop: float = 0.0
    pose_noise: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("radio_latency", "radio_jitter", "camera_latency"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number of seconds >= 0, got {value!r}")
        if not 0.0 <= self.radio_loss < 1.0:
            raise ValueError(f"radio_loss must be in [0, 1), got {self.radio_loss!r}")
        if not 0.0 <= self.camera_drop <= 1.0:
            raise ValueError(f"camera_drop must be in [0, 1], got {self.camera_drop!r}")
        if len(self.pose_noise) != 2 or not all(math.isfinite(v) and v >= 0 for v in self.pose_noise):
            raise ValueError(f"pose_noise must be (metres, radians), finite and >= 0, got {self.pose_noise!r}")

    @property
    def radio(self) -> bool:
        """Whether the radio is degraded."""
        return bool(self.radio_latency or self.radio_jitter or self.radio_loss)

    @property
    def camera(self) -> bool:
        """Whether the camera's delivery is degraded (latency or drops; pose noise is the renderer's)."""
        return bool(self.camera_latency or self.camera_drop)

    def channel(self, seed: int | None) -> RadioChannel:
        """The radio channel of these conditions (its own generator, from ``seed``)."""
        return RadioChannel((self.radio_latency, self.radio_latency + self.radio_jitter), self.radio_loss,
                            seed=None if seed is None else [int(seed), _RADIO_STREAM])


def lockstep_session(seed: int) -> int:
    """The radio session of a lockstep rig: from its seed, so that its logs repeat.

    A real robot's session is never seeded (a restarted PC must not reuse one); a lockstep run's robot is
    an emulated one made afresh in the same process, which no other PC can reach.
    """
    import numpy as np

    return int(np.random.default_rng([int(seed), _SESSION_STREAM]).integers(1, 2 ** 32))


def open_rig(resources: contextlib.ExitStack, seed: int, conditions: RigConditions = RigConditions(),
             lockstep: bool = False, speed: float = 1.0, params: Any = None,
             firmware: str = "python") -> tuple[Clock, Any, Any, Any]:
    """Start an emulated robot; returns ``(clock, robot, port, camera)`` for the PC side.

    Everything started is registered in ``resources`` (closed last in, first out). ``port`` is a URL (real
    time) or a :class:`pectoral_gym.hardware.radio.link.RadioLink` on the stream's PC end (lockstep, with its
    session from :func:`lockstep_session`); ``camera`` is a frame source.

    Args:
        resources: Where every resource is registered for release.
        seed: Seed of the robot (boot id, image noise) and of every condition.
        conditions: Radio and camera conditions.
        lockstep: Run on a :class:`VirtualClock` (then ``speed`` must be 1).
        speed: Emulated seconds per wall second (real time only).
        params: The emulated fish's :class:`pectoral_gym.model.params.FishParams` (``None``: Table 1's), e.g. a
            robot other than the one the controller was made for.
        firmware: The emulated robot's rules (``pectoral_gym.hardware.emulated_firmware.FIRMWARES``).
    """
    from pectoral_gym.hardware.emulator import EmulatedRobot

    if lockstep and speed != 1.0:
        raise ValueError(f"a lockstep emulation runs on simulated time: speed must be 1, got {speed!r}")
    clock: Clock = VirtualClock() if lockstep else REAL_CLOCK
    if lockstep:
        from pectoral_gym.hardware.radio.link import RadioLink
        from pectoral_gym.hardware.radio.pipe import StreamPair

        pair = StreamPair(clock, conditions.channel(seed) if conditions.radio else None)
        robot = EmulatedRobot(speed=1.0, seed=seed, clock=clock, stream=pair.robot, params=params,
                              firmware_impl=firmware).start()
        resources.callback(robot.stop)
        port = RadioLink(pair.pc, session=lockstep_session(seed), clock=clock)
        resources.callback(port.close)
    else:
        robot = EmulatedRobot(speed=speed, seed=seed, params=params, firmware_impl=firmware).start()
        resources.callback(robot.stop)
        port = robot.url
        if conditions.radio:
            from pectoral_gym.hardware.radio.radioproxy import RadioProxy

            channel = conditions.channel(seed)
            proxy = RadioProxy(robot.url, channel.latency, channel.loss, seed=None if seed is None else
                               [int(seed), _RADIO_STREAM], speed=speed)
            resources.callback(proxy.close)
            port = proxy.url
    camera = robot.camera(seed=seed)
    camera.pose_noise = conditions.pose_noise
    if conditions.camera:
        from pectoral_gym.hardware.vision.camerafaults import FaultyCamera

        camera = FaultyCamera(camera, drop=conditions.camera_drop, latency=conditions.camera_latency / speed,
                              seed=None if seed is None else [int(seed), _CAMERA_STREAM], clock=clock)
    resources.callback(camera.close)
    return clock, robot, port, camera
