"""The safety supervisor: watches the fish and the link in its own thread and stops the fins at once.

The control loop (``HardwareFishEnv.step``) runs only when the program calls it; between calls (a
slow policy, a training library between rollouts, a breakpoint, an exception) nothing in it runs. The
supervisor does, every camera period: it reads the camera, rejects frames that are not new sightings
(:class:`hardware.framecheck.FrameCheck`), tracks the fish, and applies the geofence with stopping
distance (:class:`hardware.safety.Geofence`), the tracking timeout and the link timeout. The first rule
that trips latches its reason and sends STOP; commands are refused (:meth:`Supervisor.send`) until
the next :meth:`Supervisor.arm`. The robot's own lease (``docs/protocol.md``) stops the fins even if
this thread and the whole PC die.
"""

from __future__ import annotations

import collections
import math
import threading
import time

import numpy as np

from hardware.framecheck import FrameCheck
from hardware.safety import Geofence, SafetyConfig, TrackingWatch

__all__ = ["Supervisor"]

_VELOCITY_WINDOW = 0.2  # poses this far apart [experiment s] give the speed for the stopping distance
_MIN_GAP, _MAX_GAP = 0.02, 1.0  # closer poses are too noisy, further ones too stale for a speed [s]


class Supervisor:
    """Safety rules applied at all times, in a thread of their own.

    Args:
        link: A :class:`hardware.link.RadioLink` (``set_fins``, ``stop``, ``status_age``).
        camera: A frame source (``read``); only this thread reads it.
        tracker: ``track(frame) -> TrackResult``.
        geofence: The wall rule.
        safety: Timeouts.
        speed: Experiment seconds per wall second.
        poll_period: Camera polling period [experiment s].

    Attributes:
        reason: The latched stop reason (``"geofence"``, ``"tracking_lost"``, ``"link_lost"``, ``"stop"``)
            or ``""``.
        watch: Tracking timeout bookkeeping; ``watch.reason`` says why the fish was last not seen.
        frame_check: Timestamp and novelty checks.
        last_frame: The newest accepted frame (for rendering).
        pose: Last measured ``(X, Y, psi)``; ``velocity``: world velocity ``(vX, vY)`` from the poses.
    """

    def __init__(self, link, camera, tracker, geofence: Geofence, safety: SafetyConfig, speed: float = 1.0,
                 poll_period: float = 1.0 / 30.0, origin: float | None = None):
        self.link, self.camera, self.tracker, self.geofence = link, camera, tracker, geofence
        self.safety, self.speed, self.poll_period = safety, float(speed), float(poll_period)
        self._origin = time.monotonic() if origin is None else float(origin)
        self.watch = TrackingWatch(safety.tracking_timeout)
        self.frame_check = FrameCheck(safety.max_frame_lead, safety.tracking_timeout / self.speed)
        self.reason = ""
        self.armed = False
        self.stop_requested = False  # set by a signal handler (no lock there); the thread latches it
        self.last_frame = None
        self.pose = (math.nan, math.nan, math.nan)
        self.velocity = (0.0, 0.0)
        self.confidence = 0.0
        self.track_ok = False
        self.frames = self.lost_frames = 0
        self._recent: collections.deque[tuple[float, float, float]] = collections.deque(maxlen=64)
        self._measurements: list[tuple[float, float, float, float]] = []
        self._lock = threading.RLock()
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._run, name="safety-supervisor", daemon=True)

    # ------------------------------------------------------------ clock
    def now(self) -> float:
        """Experiment time [s]."""
        return (time.monotonic() - self._origin) * self.speed

    def _stamp(self, monotonic: float) -> float:
        return (monotonic - self._origin) * self.speed

    # ------------------------------------------------------------ life cycle
    def start(self) -> Supervisor:
        """Start the thread; returns ``self``."""
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the thread (idempotent); the caller stops the fins."""
        self._closed.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def arm(self, since: float = -math.inf) -> None:
        """Start applying the rules (after the fish was found), with no reason latched.

        Poses captured before ``since`` [experiment s] (the reset: the fish may have been moved by hand
        or by the emulator's reset hook) are forgotten, so the jump to where the fish is now never
        reads as a speed towards a wall.
        """
        with self._lock:
            recent = [p for p in self._recent if p[0] >= since]
            self._recent.clear()
            self._recent.extend(recent)
            self.velocity = (0.0, 0.0)  # measured again from the next frame on
            self.reason, self.armed, self.stop_requested = "", True, False

    def disarm(self) -> None:
        """Stop applying the rules (during a reset: the fish may be in a hand, out of view)."""
        with self._lock:
            self.armed = False
            self.watch.last_seen = None
            self.frame_check.reset()
            self.velocity = (0.0, 0.0)
            self._recent.clear()
            self._measurements.clear()

    # ------------------------------------------------------------ commands
    def send(self, beats: np.ndarray, lease: float) -> bool:
        """Send a fin command with a new lease unless a rule has tripped (checked now); returns whether it was sent."""
        with self._lock:
            if not self.armed:
                return False
            reason = self._rules()
            if reason:
                self.trip(reason)
            if self.reason:
                return False
            self.link.set_fins(beats, lease)
            return True

    def trip(self, reason: str) -> None:
        """Latch ``reason`` (the first one wins) and send STOP."""
        with self._lock:
            if not self.armed:
                return
            if not self.reason:
                self.reason = reason
            self.link.stop()

    def drain(self) -> list[tuple[float, float, float, float]]:
        """Good measurements ``(t, X, Y, psi)`` since the last call, oldest first (for the observer)."""
        with self._lock:
            out, self._measurements = self._measurements, []
            return out

    # ------------------------------------------------------------ the rules
    def _run(self) -> None:
        while not self._closed.wait(self.poll_period / self.speed):
            try:
                self.poll()
            except Exception:  # noqa: BLE001 - a broken camera or tracker must stop the fish, not the thread
                self.watch.reason = "supervisor error"
                self.trip("tracking_lost")

    def poll(self) -> str:
        """One round: camera, frame checks, tracker, rules; returns the reason that tripped now, or ``""``."""
        frame = self.camera.read()
        with self._lock:
            if frame is not None:
                self._frame(frame)
            reason = self._rules()
            if reason and self.armed:
                self.trip(reason)
            return reason

    def _frame(self, frame) -> None:
        verdict = self.frame_check.check(frame, time.monotonic())
        t = self.now()
        if verdict:
            self.watch.update(t, False, verdict)
            self.track_ok, self.confidence = False, 0.0
            self.lost_frames += 1
            return
        t = self._stamp(frame.timestamp)
        self.last_frame = frame
        result = self.tracker.track(frame)
        self.frames += 1
        self.watch.update(t, result.ok, result.reason)
        self.track_ok = bool(result.ok)
        if not result.ok:
            self.lost_frames += 1
            self.confidence = 0.0
            return
        self.confidence = float(result.confidence)
        self.pose = (float(result.x), float(result.y), float(result.psi))
        self._measurements.append((t, *self.pose))
        self._recent.append((t, self.pose[0], self.pose[1]))
        # The newest pose at least _VELOCITY_WINDOW older (or the oldest one, if the camera is slow).
        old = next((p for p in reversed(self._recent) if t - p[0] >= _VELOCITY_WINDOW), self._recent[0])
        if _MIN_GAP <= t - old[0] <= _MAX_GAP:
            self.velocity = ((self.pose[0] - old[1]) / (t - old[0]), (self.pose[1] - old[2]) / (t - old[0]))

    def _rules(self) -> str:
        if self.stop_requested:
            return "stop"
        seen = self.watch.last_seen
        if seen is not None and self.geofence.breached(*self.pose, *self.velocity, age=self.now() - seen):
            return "geofence"
        if self.watch.expired(self.now()):
            if not self.watch.reason:
                self.watch.reason = "no frames from the camera"
            return "tracking_lost"
        if self.link.status_age() * self.speed > self.safety.link_timeout:
            return "link_lost"
        return ""
