"""The robot stack under :class:`pectoral_gym.hardware.env.HardwareFishEnv`: devices, rules and their waits.

:func:`open_stack` opens the radio link and the camera and builds what runs on them (tracker, observer,
command filter, fin replay, geofence, safety supervisor), all on one clock (:mod:`pectoral_gym.hardware.clock`);
:class:`RobotStack` holds them, releases them (:meth:`RobotStack.release`), and does the two waits of a
reset on the devices: the robot's confirmed stop (:meth:`RobotStack.confirm_stop`) and the first sightings
of the fish (:meth:`RobotStack.wait_for_fish`). The env keeps the task: observations, rewards, ends.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.hardware.clock import REAL_CLOCK, Clock
from pectoral_gym.hardware.radio.link import DisplacedError, RadioLink
from pectoral_gym.hardware.safety.geofence import Geofence
from pectoral_gym.hardware.safety.rules import CommandFilter, SafetyConfig
from pectoral_gym.hardware.safety.supervisor import Supervisor
from pectoral_gym.hardware.vision.track_result import check_tracker
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import FirmwareConfig

__all__ = ["SIMULATION_ONLY", "RobotStack", "check_not_displaced", "env_config", "open_stack"]


def check_not_displaced(link: Any) -> None:
    """``DisplacedError`` if ``link`` knows the robot serves another session (a link without the notion: never)."""
    if getattr(link, "displaced", False):
        reason = link.control_lost
        raise DisplacedError(reason, "another session took the robot over (taken_over): this run stopped sending"
                        if reason == "taken_over" else "the robot serves another live session (robot_busy): "
                        "this run sends nothing; pass --take-over only if nobody relies on that session")

#: ``EnvConfig`` option groups that simulate what the robot stack really does: the robot env refuses them, saying why.
SIMULATION_ONLY = {
    "sensing": "observes through its real camera and observer: sensing (the simulated envs' camera, "
               "EnvConfig.sensing)",
    "timing": "runs on the robot's own clock and radio: timing (the simulated envs' command delays, "
              "EnvConfig.timing)",
}


def env_config(task: str, control_period: float, kwargs: dict[str, Any]) -> EnvConfig:
    """The full-model :class:`EnvConfig` of a robot env (``HardwareFishEnv``'s ``**kwargs`` on top).

    It starts from ``EnvConfig``'s defaults, the simulation-only id's settings
    (:data:`pectoral_gym.versions.SIMULATION_IDS`, ``hardware.deploy_checks.ROBOT_ENV_BASE``), not from
    :data:`pectoral_gym.versions.LATEST`'s robot-ready ones, on purpose. Those make a *simulated* env act like the
    robot stack: ``stop_band`` stands for the supervisor's geofence (with
    :data:`~pectoral_gym.versions.MEASUREMENT_MARGIN` more margin, for a band judged on camera speeds) and
    ``servo_limit`` for the firmware's rate rule. On the robot those rules run for real (the
    :class:`~pectoral_gym.hardware.safety.supervisor.Supervisor` with ``SafetyConfig.stop_rule``, the
    :class:`~pectoral_gym.hardware.safety.rules.CommandFilter`, the firmware); set here as well they would act
    twice: episodes ended 5 cm before the geofence, and periods lengthened by ``decode`` before the filter and the
    firmware stretch them, which changes what a policy's action sends. What the robot-ready ids add that the robot
    needs comes in through ``kwargs``: ``observe_fins`` from the policy's observation size and the baselines' goal
    inset (:func:`pectoral_gym.hardware.deploy_checks.env_settings`); the model's integration settings play no part
    on the robot.

    Raises:
        ValueError: A :data:`SIMULATION_ONLY` group is set, an argument is unknown, or a setting is invalid.
    """
    for name, why in SIMULATION_ONLY.items():
        if kwargs.get(name) is not None:
            raise ValueError(f"HardwareFishEnv {why} must not be set here; leave it out")
    try:
        return EnvConfig(model="full", task=task, control_period=control_period, **kwargs)
    except TypeError as err:
        raise ValueError(f"unknown HardwareFishEnv argument: {err}") from None


@dataclass
class RobotStack:
    """The opened devices and the rules on them (see :func:`open_stack`).

    Attributes:
        link: The radio link.
        camera: The frame source (read by the supervisor's frame grabber).
        tracker: Marker tracker (``track(frame, near=None)``, as
            :class:`~pectoral_gym.hardware.vision.tracker.MarkerTracker`).
        observer: State observer (``reset``, ``update``, ``predict``).
        filter: The PC-side command filter (servo limits, rate limit).
        fin_replay: The fins replayed from the commands sent (``observe_fins``), else ``None``.
        geofence: The wall rule.
        supervisor: The safety supervisor (started).
        clock: The clock all of them run on.
    """

    link: Any
    camera: Any
    tracker: Any
    observer: Any
    filter: CommandFilter
    fin_replay: FinReplay | None
    geofence: Geofence
    supervisor: Supervisor
    clock: Clock

    def release(self) -> None:
        """Stop the supervisor, close the link (sending STOP) and the camera; each step runs whatever fails."""
        _release(self.supervisor, self.link, self.camera)

    def confirm_stop(self, timeout: float) -> None:
        """Send STOP until the robot confirms its fins are still, at most ``timeout`` s (clock seconds).

        Raises:
            DisplacedError: The robot serves another session (:attr:`RadioLink.displaced`): no STOP is sent, the
                takeover halted our fins and a STOP of ours could only halt the new controller's.
            RuntimeError: No confirmation in time.
        """
        deadline = self.clock.monotonic() + timeout
        while True:
            check_not_displaced(self.link)
            remaining = deadline - self.clock.monotonic()
            if remaining <= 0:
                raise RuntimeError(f"the robot did not confirm it stopped within {timeout:.1f} s "
                                   f"(link: {self.link.health()}); the reset hook was not called; check the "
                                   "radio and the robot")
            # One STOP, then wait for the robot's word: its retries and the keep-alive's STOP copies (newer
            # sequence numbers, which also confirm it) cover lost frames; a fresh STOP per short wait would
            # restart the wait before a slow radio's answer (one round trip or more) could arrive.
            if self.link.stop(wait=remaining):
                return
            check_not_displaced(self.link)

    def wait_for_fish(self, after: float, timeout: float, poll: float) -> None:
        """Wait for sightings in frames captured at or after ``after`` [experiment s] that give a velocity.

        Args:
            after: Experiment time the frames must be captured at or after [s].
            timeout: Longest wait [clock s].
            poll: Period of the checks [clock s].

        Raises:
            RuntimeError: No such sightings in time.
        """
        sup = self.supervisor
        deadline = self.clock.monotonic() + timeout
        while self.clock.monotonic() < deadline:
            seen = sup.watch.last_seen
            if seen is not None and seen >= after and sup.ready(after):
                return
            self.clock.sleep(poll)
        raise RuntimeError(f"no fish seen for {timeout:.1f} s at reset "
                           f"(tracker: {sup.watch.reason or 'no frames'}); check the camera and the markers")


def _release(*parts) -> None:
    for part in parts:
        close = getattr(part, "close", None)
        if close is not None:
            try:
                close()
            except Exception:  # noqa: BLE001 - release the rest; the first error is the one raised
                pass


def open_stack(port, camera, config: EnvConfig, safety: SafetyConfig, speed: float = 1.0,
               frame_period: float = 1.0 / 30.0, calibration=None, tracker=None, observer=None,
               observer_epsilon: float = 0.1, take_over: bool = False, origin: float | None = None,
               clock: Clock = REAL_CLOCK) -> RobotStack:
    """Open the link and the camera and build the rest on them; whatever was opened is released on a failure.

    Args:
        port: A ``serial_for_url`` URL (a :class:`RadioLink` is opened on it, timed for ``speed``), a serial-like
            object without a link (e.g. a :class:`pectoral_gym.hardware.radio.pipe.StreamEnd`: the same), or a
            :class:`RadioLink` (used as it is).
        camera: A ``camera.open_source`` spec or a frame source.
        config: The env's settings (fish parameters, ``observe_fins``).
        safety: Timeouts and limits.
        speed: Experiment seconds per clock second (an accelerated emulator).
        frame_period: Camera polling period [experiment s].
        calibration: Calibration JSON for the default tracker (``None``: the default camera model).
        tracker: Anything with ``track(frame, near=None) -> TrackResult`` (default a ``MarkerTracker`` of the
            camera model).
        observer: State observer (default a ``HighGainObserver`` with ``observer_epsilon``).
        observer_epsilon: Time constant of the default observer [s].
        take_over: Take the robot from another live session (a link opened here).
        origin: ``clock.monotonic()`` at experiment time 0 (default now).
        clock: The clock of every part.

    Raises:
        TypeError: ``tracker`` is not called as the supervisor calls it
            (:func:`pectoral_gym.hardware.vision.track_result.check_tracker`); nothing is opened.
    """
    if tracker is not None:
        check_tracker(tracker)  # before anything is opened: a tracker the supervisor cannot call stops every frame
    link = cam = None
    try:
        if isinstance(port, RadioLink):
            link = port
        else:
            extra = {"take_over": True} if take_over else {}
            link = RadioLink(port, keepalive_period=0.1 / speed, ack_timeout=0.05 / speed, clock=clock, **extra)
        link.lease_scale = 1.0 / speed  # the robot counts leases in its own (emulated) seconds
        if isinstance(camera, (str, int)):
            from pectoral_gym.hardware.vision.camera import open_source

            camera = open_source(camera)
        cam = camera
        if tracker is None:
            from pectoral_gym.hardware.vision.cameramodel import CameraModel
            from pectoral_gym.hardware.vision.tracker import MarkerTracker

            model = CameraModel.default() if calibration is None else CameraModel.load(calibration)
            tracker = MarkerTracker(model)
        if observer is None:
            from pectoral_gym.hardware.vision.observer import HighGainObserver

            observer = HighGainObserver(epsilon=observer_epsilon)
        # observe_fins: the robot reports no fin angles, so the PC replays its fins from the commands it sends
        fin_replay = FinReplay(config.params, FirmwareConfig(limits=safety.limits)) if config.observe_fins else None
        geofence = Geofence(config.params, safety.stop_rule)
        supervisor = Supervisor(link, camera, tracker, geofence, safety, speed, frame_period,
                                origin=clock.monotonic() if origin is None else origin, clock=clock).start()
    except BaseException:
        _release(link, cam)  # as the env always did: what it was given is closed too
        raise
    return RobotStack(link, camera, tracker, observer, CommandFilter(safety.limits), fin_replay, geofence,
                      supervisor, clock)

