"""The safety supervisor: watches the fish and the link in its own thread and stops the fins at once.

The control loop (``HardwareFishEnv.step``) runs only when the program calls it; between calls (a slow policy, a
training library between rollouts, a breakpoint, an exception) nothing in it runs. The supervisor does, every camera
period: it takes the newest frame from a :class:`pectoral_gym.hardware.vision.frames.FrameGrabber` (which reads the
camera in a thread of its own, so a camera that blocks can never hold up the rules), rejects frames that are not new
sightings (:class:`pectoral_gym.hardware.vision.framecheck.FrameCheck`), tracks the fish, and applies the rules: the
operator's stop, loss of control of the robot (``RadioLink.control_lost``), the link timeout, the geofence with
stopping distance (:class:`pectoral_gym.hardware.safety.geofence.Geofence`, speeds bounded by
:class:`pectoral_gym.hardware.safety.geofence.SpeedBound`) and the tracking timeout. Each rule that trips is latched
and sends STOP; commands are refused (:meth:`Supervisor.send`) until the next :meth:`Supervisor.arm`, and the
operator's stop until :meth:`Supervisor.rearm`. When several have tripped, :attr:`Supervisor.reason` is the first of
:data:`PRIORITY` (``docs/guide/safety.md``, "Failsafe priority"). The robot's own lease (``docs/protocol.md``) stops
the fins even if this thread and the whole PC die.
"""

from __future__ import annotations

import collections
import math
import threading
from collections.abc import Callable

from pectoral_gym.hardware.clock import REAL_CLOCK, Clock
from pectoral_gym.hardware.safety.blind import CommandedGain, ls_velocity, unseen_reason
from pectoral_gym.hardware.safety.geofence import Geofence, SpeedBound
from pectoral_gym.hardware.safety.latch_reports import LatchReports
from pectoral_gym.hardware.safety.liveness import LivenessWatch
from pectoral_gym.hardware.safety.rules import SafetyConfig, TrackingWatch, effective_reaction_time
from pectoral_gym.hardware.vision.framecheck import FrameCheck
from pectoral_gym.hardware.vision.frames import FrameGrabber
from pectoral_gym.hardware.vision.latency import afforded_latency, check_latency, pipeline_latency
from pectoral_gym.model.finrules import FirmwareConfig

__all__ = ["Supervisor", "PRIORITY", "CONTROL_LOST", "ls_velocity"]

# Stop reasons, highest priority first; a RadioLink.control_lost reason ranks as "control_lost".
PRIORITY = ("stop", "control_lost", "link_lost", "geofence", "tracking_lost", "episode_end")
CONTROL_LOST = ("taken_over", "robot_busy", "robot_rebooted")
_VELOCITY_WINDOW = 1.0  # poses up to this old [experiment s] give the least-squares velocity
_Z = 2.0  # standard errors added to the velocity towards each wall


def _rank(reason: str) -> int:
    key = "control_lost" if reason in CONTROL_LOST else reason
    return PRIORITY.index(key) if key in PRIORITY else PRIORITY.index("control_lost")


class Supervisor:
    """Safety rules applied at all times, in a thread of their own.

    Args:
        link: A :class:`pectoral_gym.hardware.radio.link.RadioLink` (``set_fins``, ``stop``, ``status_age``,
            ``control_lost``).
        camera: A frame source; the supervisor reads it through a :class:`FrameGrabber` it owns (and closes).
        tracker: ``track(frame, near=box) -> TrackResult`` (``near``: the last sighting's box while the fish is seen).
        geofence: The wall rule (from ``safety.stop_rule``); its rule's reaction time is every rule's budget.
        safety: Timeouts and limits.
        speed: Experiment seconds per wall second.
        poll_period: Rule period [experiment s].
        origin: ``clock.monotonic()`` at experiment time 0.
        bound: The physical speed bound (default from the geofence's fish and ``safety.limits``).
        clock: The clock of every time, wait and thread (:mod:`pectoral_gym.hardware.clock`); a camera given as a
            plain source is read by a :class:`FrameGrabber` on it.

    Attributes:
        reason: The latched stop reason of highest priority (:data:`PRIORITY`) or ``""``; ``fired`` holds them all.
        stop_requested: The operator's stop, latched until :meth:`rearm` (set without a lock by signal handlers).
        watch: Tracking timeout bookkeeping; ``watch.reason`` says why the fish was last not seen.
        frame_check: Timestamp and novelty checks.
        last_frame: The newest accepted frame (for rendering).
        pose: Last measured ``(X, Y, psi)``; ``velocity``: least-squares world velocity ``(vX, vY)``,
            ``spread``: its standard errors times 2 (``inf`` when there is no estimate).
        bound: :class:`SpeedBound`, fed every command sent.
    """

    def __init__(self, link, camera, tracker, geofence: Geofence, safety: SafetyConfig, speed: float = 1.0,
                 poll_period: float = 1.0 / 30.0, origin: float | None = None, bound: SpeedBound | None = None,
                 clock: Clock = REAL_CLOCK):
        self.link, self.tracker, self.geofence = link, tracker, geofence
        self.safety, self.speed, self.poll_period = safety, float(speed), float(poll_period)
        self.clock = clock
        self._origin = clock.monotonic() if origin is None else float(origin)
        self.camera = camera if isinstance(camera, FrameGrabber) else FrameGrabber(
            camera, max_rate=self.speed / self.poll_period, stale_after=safety.tracking_timeout / self.speed,
            clock=clock)
        self.watch = TrackingWatch(safety.tracking_timeout)
        self.frame_check = FrameCheck(safety.max_frame_lead, safety.tracking_timeout / self.speed)
        self.bound = bound or SpeedBound(geofence.params, safety.limits)
        self.bound.unknown(self.now())
        self.gain = CommandedGain(geofence.params, safety.limits)  # the blind rule's speed gain
        self._watchdog = FirmwareConfig(limits=safety.limits).watchdog_timeout
        self.liveness = LivenessWatch(geofence.params, self.bound, safety.pose_noise, limits=safety.limits)
        self._not_live = ""  # why the camera's poses do not follow our fins (latched until the next arm)
        self.fired: dict[str, float] = {}
        self.armed = False
        self.stop_requested = False  # set by a signal handler (no lock there); latched until rearm()
        self.last_frame = None
        self.pose = (math.nan, math.nan, math.nan)
        self.velocity, self.spread = (0.0, 0.0), (math.inf, math.inf)
        self.confidence = 0.0
        self.track_ok = False
        self.frames = self.lost_frames = 0
        self.afforded_latency = afforded_latency(safety.tracking_timeout, geofence.rule.reaction_time)
        self._last_read = -math.inf  # experiment time the last frame was read
        self._box = None
        self._since = -math.inf
        self._reads = self._reads_at_sighting = 0  # frames read; frames read up to the last sighting
        self._read_times: collections.deque[float] = collections.deque(maxlen=256)  # experiment s of recent reads
        self._recent: collections.deque[tuple[float, float, float]] = collections.deque(maxlen=128)
        self._measurements: list[tuple[float, float, float, float]] = []
        self.latches = LatchReports(link, self._stamp)  # the robot's, to the liveness check, then the env's run log
        self._lock = threading.RLock()
        self._closed = clock.event()
        self._thread = clock.thread(self._run, "safety-supervisor")

    @property
    def reason(self) -> str:
        """The latched reason of highest priority, ``""`` if none."""
        fired = dict(self.fired)
        return min(fired, key=_rank) if fired else ""

    # ------------------------------------------------------------ clock
    def now(self) -> float:
        """Experiment time [s]."""
        return (self.clock.monotonic() - self._origin) * self.speed

    def _stamp(self, monotonic: float) -> float:
        return (monotonic - self._origin) * self.speed

    # ------------------------------------------------------------ life cycle
    def start(self) -> Supervisor:
        """Start the thread; returns ``self``."""
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the thread and the frame grabber, closing the camera (idempotent); the caller stops the fins."""
        self._closed.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        self.camera.close()

    def arm(self, since: float = -math.inf) -> None:
        """Start applying the rules (after the fish was found), with no reason latched but the operator's stop.

        Poses captured before ``since`` [experiment s] (the reset: the fish may have been moved by hand
        or by the emulator's reset hook) are forgotten, so the jump to where the fish is now never
        reads as a speed towards a wall. An operator's stop stays latched (:meth:`rearm`).
        """
        with self._lock:
            recent = [p for p in self._recent if p[0] >= since]
            self._recent.clear()
            self._recent.extend(recent)
            self._since = since
            self._estimate()  # from the poses since the reset only
            self.liveness.reset(self.now())  # armed after a confirmed stop: the fins are still
            self.gain.reset(self.now())
            self._not_live = ""
            self.fired.clear()
            self.armed = True

    def disarm(self) -> None:
        """Stop applying the rules (during a reset: the fish may be in a hand, out of view)."""
        with self._lock:
            self.armed = False
            self.watch.last_seen = None
            self.frame_check.reset()
            self.velocity, self.spread = (0.0, 0.0), (math.inf, math.inf)
            self._recent.clear()
            self._measurements.clear()
            self._box = None
            self._since = -math.inf

    def ready(self, after: float, span: float = 0.9 * _VELOCITY_WINDOW) -> bool:
        """Whether poses captured at or after ``after`` [experiment s] span ``span`` s and give a velocity."""
        with self._lock:
            poses = [p for p in self._recent if p[0] >= after]
            return bool(poses) and poses[-1][0] - poses[0][0] >= span and \
                ls_velocity(poses, self.safety.pose_noise) is not None

    def rearm(self) -> None:
        """Clear the operator's stop (the explicit operator action; nothing else clears it)."""
        with self._lock:
            self.stop_requested = False
            self.fired.pop("stop", None)

    # ------------------------------------------------------------ commands
    def send(self, beats, lease: float) -> bool:
        """Send a fin command with a new lease unless a rule has tripped (checked now); returns whether it was sent."""
        with self._lock:
            if not self.armed:
                return False
            reasons = self._rules()
            if reasons:  # judged again on the newest frame, if the poll thread has not got round to it yet
                self._take_frame()  # (only then: a frame costs milliseconds, and the command would wait for them)
                reasons = self._rules()
            for reason in reasons:
                self.trip(reason)
            if self.fired or self.stop_requested:
                return False
            now = self.now()
            if now > self.bound.run_until:  # the last lease may have ended: a command in flight then starts whole
                self.gain.still(self.bound.run_until - self._round_trip())
            # The fins may run until the lease ends, plus the reaction time (firmware tick) and the radio's delay.
            self.bound.running(now, now + lease + self.geofence.rule.reaction_time + self._radio_delay())
            seq = self.link.set_fins(beats, lease)
            acknowledged = self._acknowledgement(seq)
            self.liveness.command(now, beats, acknowledged)
            self.gain.command(now, beats, acknowledged)
            return True

    def _round_trip(self) -> float:
        """The link's smoothed round trip [experiment s], 0 before one is measured."""
        rtt = getattr(self.link, "rtt", None)
        value = rtt() if callable(rtt) else None
        return float(value) * self.speed if value is not None and math.isfinite(value) else 0.0

    def _radio_delay(self) -> float:
        """What the radio adds to the reaction time [s] (:func:`effective_reaction_time`)."""
        return effective_reaction_time(self.geofence.rule, self._round_trip()) - self.geofence.rule.reaction_time

    def _acknowledgement(self, seq) -> Callable[[], float | None] | None:
        """When a STATUS acknowledging ``seq`` or later arrived [experiment s]; ``None`` before (or: cannot tell)."""
        acknowledged_at = getattr(self.link, "acknowledged_at", None)
        if acknowledged_at is None or not isinstance(seq, int) or seq < 0:
            return None  # a link that does not tell: the command counts as started when sent

        def arrival() -> float | None:
            t = acknowledged_at(seq)
            return None if t is None else self._stamp(t)
        return arrival

    def trip(self, reason: str) -> None:
        """Latch ``reason`` (every one is kept; :attr:`reason` reports by priority) and send STOP."""
        with self._lock:
            if not self.armed:
                return
            self.fired.setdefault(reason, self.now())
            self.link.stop()
            self.gain.still(self.now())

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
            except Exception as error:  # noqa: BLE001 - a broken rule must stop the fish, not the thread
                self._broken(error)

    def _broken(self, error: Exception) -> None:
        """A tracker or rule raised: the fish counts as unseen, with the error as the reason."""
        with self._lock:
            self.watch.reason = f"supervisor error: {type(error).__name__}: {error}"
            self.watch.last_seen = None if self.watch.last_seen is None else -math.inf
            self.track_ok = False
        self.trip("tracking_lost")

    def poll(self) -> str:
        """One round: newest frame, frame checks, tracker, rules; returns the first reason that holds now, or ``""``."""
        with self._lock:
            self.latches.take(self.liveness if self.armed else None)  # before the frame they may explain
            self._take_frame()
            reasons = self._rules()
            for reason in reasons if self.armed else ():
                self.trip(reason)
            return reasons[0] if reasons else ""

    def _take_frame(self) -> None:
        """Process the newest frame the camera has, if any (never blocks)."""
        frame = self.camera.read()
        if frame is not None:
            self._reads += 1
            self._last_read = self.now()
            self._read_times.append(self._last_read)
            try:
                self._frame(frame)
            except Exception as error:  # noqa: BLE001 - whichever thread met it, a broken tracker stops the fish
                self._broken(error)
        elif self.camera.lost_reason and not self.track_ok:
            self.watch.reason = self.watch.reason or self.camera.lost_reason

    def _frame(self, frame) -> None:
        verdict = self.frame_check.check(frame, self.clock.monotonic(), region=self._box)
        t = self.now()
        if verdict:
            self.watch.update(t, False, verdict)
            self.track_ok, self.confidence = False, 0.0
            self.lost_frames += 1
            return
        t = self._stamp(frame.timestamp)
        self.last_frame = frame
        result = self.tracker.track(frame, near=self._box if self.track_ok else None)  # near the last sighting first
        self.frames += 1
        self.watch.update(t, result.ok, result.reason)
        self.track_ok = bool(result.ok)
        if not result.ok:
            self.lost_frames += 1
            self.confidence = 0.0
            return
        self.confidence = float(result.confidence)
        self._reads_at_sighting = self._reads
        self._box = getattr(result, "box", None)
        self.pose = (float(result.x), float(result.y), float(result.psi))
        self._measurements.append((t, *self.pose))
        if self.armed and t >= self._since and not self._not_live:
            self._not_live = self.liveness.sighting(t, *self.pose)
        if t >= self._since:
            self._recent.append((t, self.pose[0], self.pose[1]))
        self._estimate()

    def _estimate(self) -> None:
        """Least-squares velocity over the newest poses (no estimate: ``spread`` inf, the physical bound rules)."""
        newest = self._recent[-1][0] if self._recent else math.inf
        estimate = ls_velocity([p for p in self._recent if p[0] >= newest - _VELOCITY_WINDOW], self.safety.pose_noise)
        self.velocity, self.spread = estimate if estimate else ((0.0, 0.0), (math.inf, math.inf))

    def _geofence(self, now: float, blind: bool) -> bool:
        """The wall rule on the last pose; ``blind``: also the fastest speed gain the fins allow while unseen."""
        seen = self.watch.last_seen
        age = now - seen
        # A STOP reaches the robot a forward delay (at most the round trip) after it is sent: the fins run on.
        radio = self._radio_delay()
        bound = self.bound.peak(seen, now + self.geofence.rule.reaction_time + radio)
        # Unseen beyond the reaction budget and the camera's measured latency: a frame that arrives late but
        # regularly is a sighting of an older time (its age already lengthens the stopping distance, speed x age).
        unseen = max(0.0, age - self.geofence.rule.reaction_time - self.latency_budget)
        gain = 0.0
        if blind and unseen > 0 and self.bound.run_until >= seen:  # the most the commanded fins add while unseen
            end = now + self.geofence.rule.reaction_time + radio
            gain = min(self.gain.accel(seen, now, end, self._round_trip()), self.bound.accel) * unseen
        spread = tuple(_Z * s for s in self.spread)
        # ``age`` feeds only ``react = reaction_time + age``: adding the radio's delay is the longer reaction time.
        return self.geofence.breached(*self.pose, *self.velocity, age=age + radio, spread=spread, bound=bound,
                                      gain=gain)

    def _unseen_reason(self, now: float, seen: float) -> str:
        """What the blind rule saw: no frames (with counts), frames that arrive too late, or frames without the fish."""
        budget = f"the reaction time {self.geofence.rule.reaction_time:.2f} s plus the measured camera latency " \
                 f"{self.latency_budget:.2f} s"
        recent = sum(1 for t in self._read_times if t >= now - 1.0)
        return unseen_reason(now, seen, self._last_read, self._reads > self._reads_at_sighting, recent,
                             self.poll_period, self.geofence.rule.reaction_time, budget)

    # ------------------------------------------------------------ camera latency
    @property
    def latency(self) -> float:
        """The camera pipeline's measured latency [experiment s] (:func:`pipeline_latency`); ``nan`` before frames."""
        return pipeline_latency(tuple(getattr(self.camera, "ages", ()))) * self.speed

    @property
    def latency_budget(self) -> float:
        """The latency the blind rule credits [s]: the measured one, at most :attr:`afforded_latency` (0 unmeasured)."""
        latency = self.latency
        return min(latency, self.afforded_latency) if math.isfinite(latency) else 0.0

    def check_latency(self) -> float:
        """The measured latency [s]; raises :class:`CameraLatencyError` if the tank cannot afford it."""
        return check_latency(self.latency, self.safety.tracking_timeout, self.geofence.rule.reaction_time)

    def _rules(self) -> list[str]:
        """Every reason that holds now, highest priority first (:data:`PRIORITY`)."""
        out = []
        if self.stop_requested:
            out.append("stop")
        lost = getattr(self.link, "control_lost", "")
        if lost:
            out.append(str(lost))
        status_age = self.link.status_age() * self.speed
        if status_age > self.safety.link_timeout:
            out.append("link_lost")
        now = self.now()
        round_trip = self._round_trip()
        # A robot that heard nothing for its watchdog stops its fins; the PC then hears no STATUS for the watchdog
        # less the return delay's spread (at most a round trip; at least half the watchdog is assumed).
        if status_age > max(self._watchdog - round_trip, 0.5 * self._watchdog):
            self.gain.still(now - status_age - round_trip)
        seen = self.watch.last_seen
        if self._not_live:  # the camera's poses do not follow our fins: the fish is not seen
            self.watch.reason = self._not_live
            out.append("tracking_lost")
        elif seen is not None and math.isfinite(seen) and self._geofence(now, blind=False):
            out.append("geofence")
        elif seen is not None and math.isfinite(seen) and self._geofence(now, blind=True):
            # Unseen for so long that the fastest motion the fins allow could reach the stopping band.
            self.watch.reason = self.watch.reason or self.camera.lost_reason or self._unseen_reason(now, seen)
            out.append("tracking_lost")
        if self.watch.expired(now) and "tracking_lost" not in out:
            if not self.watch.reason:
                self.watch.reason = self.camera.lost_reason or "no frames from the camera"
            out.append("tracking_lost")
        return out
