"""The blind rule's speed gain from the commanded fins (hardware/safety/blind.py) and its use by the supervisor."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from pectoral_gym.hardware.safety.blind import CommandedGain, box_rate, fin_force_bound, first_stroke
from pectoral_gym.hardware.safety.geofence import Geofence, SpeedBound
from pectoral_gym.hardware.safety.rules import CommandFilter, SafetyConfig
from pectoral_gym.hardware.safety.supervisor import Supervisor
from pectoral_gym.hardware.vision.frames import FrameGrabber
from pectoral_gym.model import strokes
from pectoral_gym.model.dynamics import fin_force_right
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.params import TANK_LENGTH, FishParams, body_coefficients
from pectoral_gym.model.servo import ServoLimits, clip_beats, peak_rates
from pectoral_gym.model.tank import StopRule

P = FishParams()
LIMITS = ServoLimits()
GENTLE = np.array([[1.57, 0.2, 1.5, 1.0], [1.57, 0.2, 1.5, 1.0]])  # peak 0.84 rad/s per fin


def test_the_force_bound_at_the_servo_limit_is_the_speed_bounds():
    # By hand (docs/guide/safety.md, "Fin force"): d_min = 0.4 s / 7, F_f = k 13^2 + I_p sqrt(13^4 + (pi 13 / d_min)^2)
    d_min = 0.4 / 7.0
    inertia = math.sqrt(13.0 ** 4 + (math.pi * 13.0 / d_min) ** 2)
    by_hand = P.fin_drag_constant * 169.0 + P.fin_inertia_constant * inertia
    assert fin_force_bound(P, LIMITS, 13.0) == pytest.approx(by_hand, rel=1e-12)
    assert by_hand == pytest.approx(1.27, abs=0.005)
    gain = CommandedGain(P, LIMITS)
    assert gain.full == pytest.approx(SpeedBound(P, LIMITS).accel, rel=1e-12)  # nothing known: as before
    assert fin_force_bound(P, LIMITS, 0.0) == 0.0


def test_box_rate_of_one_pattern_is_its_own_peak_rate():
    rng = np.random.default_rng(3)
    for _ in range(200):
        raw = np.stack([rng.uniform(0.2, 2.9, 2), rng.uniform(0, 1.4, 2), rng.uniform(0.4, 4, 2),
                        rng.uniform(0.5, 6, 2)], axis=1)
        beats = clip_beats(raw, LIMITS)[0]
        expected = peak_rates(beats).max(axis=1)  # the firmware's own formula (eq. 21's half-cosines)
        assert box_rate(beats[None], LIMITS) == pytest.approx(expected, rel=1e-9)


def _robot_strokes(replay: FinReplay) -> tuple[np.ndarray, np.ndarray]:
    """``(2,)`` peak rate [rad/s] and ``(2,)`` duration [s] of the replayed fins' half-strokes in progress."""
    fins = replay.fins[0]
    rate, duration = np.zeros(2), np.full(2, math.inf)
    for f in range(2):
        d, swing = fins[f, strokes.DURATION], fins[f, strokes.ANGLE_TO] - fins[f, strokes.ANGLE_FROM]
        if d > 0 and swing != 0 and fins[f, strokes.ELAPSED] < d:
            rate[f], duration[f] = math.pi * abs(swing) / (2.0 * d), d
    return rate, duration


def _robot_force(replay: FinReplay) -> float:
    """Sum over the two fins of the force's magnitude [N] on the body now (eqs. 9-17, ``fin_force_right``)."""
    fins = replay.fins[0]
    total = 0.0
    for f in range(2):
        d, elapsed = fins[f, strokes.DURATION], fins[f, strokes.ELAPSED]
        if d <= 0 or elapsed >= d or fins[f, strokes.ANGLE_TO] == fins[f, strokes.ANGLE_FROM]:
            continue
        a0, a1 = fins[f, strokes.ANGLE_FROM], fins[f, strokes.ANGLE_TO]
        half, w, phase = 0.5 * (a1 - a0), math.pi / d, math.pi * elapsed / d
        g = 0.5 * (a0 + a1) - half * math.cos(phase)
        fx, fy = fin_force_right(g, half * w * math.sin(phase), half * w * w * math.cos(phase),
                                 P.fin_drag_constant, P.fin_inertia_constant)
        total += math.hypot(fx, fy)
    return total


def _wild(rng, _):
    return np.stack([rng.uniform(0.5, 2.6, 2), rng.uniform(0, 0.8, 2), rng.uniform(0.4, 3, 2),
                     rng.uniform(0.5, 6, 2)], axis=1)


_START = np.array([[1.57, 0.25, 1.5, 2.0]] * 2)


def _drifting(rng, step):
    """A swimming policy's commands: each parameter drifts a little per step."""
    return _START + rng.normal(0.0, [0.3, 0.1, 0.3, 0.8], size=(2, 4))


@pytest.mark.parametrize(("seed", "policy", "tighter"), [(0, _wild, 0.0), (1, _drifting, 0.65), (2, _drifting, 0.65)])
def test_the_gain_covers_the_robots_fins_whatever_the_take_times(seed, policy, tighter):
    # The robot takes each command somewhere in a round trip after its send (the PC learns when by the STATUS):
    # the fins' force at their true peak rate over any span never exceeds what the gain allows for it.
    rng = np.random.default_rng(seed)
    rtt = 0.2
    gain = CommandedGain(P, LIMITS)
    gain.reset(0.0)
    robot = FinReplay(P, FirmwareConfig(limits=LIMITS))
    robot.reset(0.0)
    commands = CommandFilter(LIMITS)
    pending = []  # (take time, beats)
    mass = min(body_coefficients(P).m1, body_coefficients(P).m2)
    history: list[tuple[float, np.ndarray]] = []
    t, checked, below_full = 0.0, 0, 0
    for step in range(60):
        sent = 0.5 * step
        beats = commands(policy(np.random.default_rng([seed, step]), step), 0.5)
        take = sent + rng.uniform(0.0, rtt)
        gain.command(sent, beats, lambda take=take: take)
        pending.append((take, beats))
        while t < sent + 0.5 - 1e-9:  # the robot's fins over this step, 5 ms at a time
            t = round(t + 0.005, 9)
            for item in [p for p in pending if p[0] <= t]:
                robot.command(item[0], item[1])
                pending.remove(item)
            robot.advance(t)
            history.append((t, _robot_force(robot), *_robot_strokes(robot)))
        for end in (sent + 0.25, sent + 0.5):
            if end <= 1.0:
                continue
            start = end - 0.4
            span = [h for h in history if start <= h[0] <= end]
            force = max(h[1] for h in span) / mass
            rates, shortest = gain.strokes(start, end, end, rtt)
            assert np.all(np.max([h[2] for h in span], axis=0) <= rates + 1e-9), (end, rates)
            assert np.all(np.min([h[3] for h in span], axis=0) >= shortest - 1e-9), (end, shortest)
            allowed = gain.accel(start, end, end, rtt)
            assert force <= allowed * (1 + 1e-9), (end, force, allowed)
            checked += 1
            below_full += allowed < 0.5 * gain.full
    assert checked > 100 and below_full >= tighter * checked  # gentle fins: often under half the servos' gain


def _by_hand(rate: float, shortest: float) -> float:
    """Two fins' force over the smaller mass at peak rate ``rate``, half-strokes of at least ``shortest`` s."""
    force = P.fin_drag_constant * rate ** 2 + P.fin_inertia_constant * math.sqrt(rate ** 4 +
                                                                                  (math.pi * rate / shortest) ** 2)
    return 2.0 * force / min(body_coefficients(P).m1, body_coefficients(P).m2)


def test_a_fin_that_may_latch_from_still_gets_its_first_strokes_bound():
    gain = CommandedGain(P, LIMITS)
    assert gain.accel(0.0, 0.0, 1.0, 0.0) == gain.full  # never reset: nothing known
    gain.reset(0.0)
    assert gain.accel(0.0, 0.5, 0.6, 0.0) == 0.0  # still fins, no command
    gain.command(1.0, GENTLE, lambda: 1.05)
    # Its first power stroke runs from wherever the fin is (at worst the servo's far end, 10 deg) to bias + A =
    # 1.77 rad in T_p / 2 = 0.75 s: peak pi 1.5955 / 1.5 = 3.34 rad/s, not the servos' 13.
    swing = 1.77 - math.radians(10.0)
    first = gain.accel(1.0, 1.2, 1.3, 0.1)
    assert first == pytest.approx(_by_hand(math.pi * swing / 1.5, 0.75), rel=1e-9)
    assert first < 0.1 * gain.full
    late = gain.accel(4.0, 4.2, 4.3, 0.1)  # steady strokes: peak pi 0.2 2 / 1.5 = 0.84 rad/s
    assert late == pytest.approx(_by_hand(math.pi * 0.4 / 1.5, 0.75), rel=1e-9)
    gain.still(4.5)  # a lease ended (or a watchdog may have fired): the next command is latched whole
    fast = np.array([[1.57, 1.2, 0.4, 1.0]] * 2)
    gain.command(5.0, fast, lambda: None)  # not acknowledged yet: taken at any time until now
    rate, shortest = first_stroke(clip_beats(fast, LIMITS)[0][None], LIMITS)
    assert rate == pytest.approx([LIMITS.max_speed] * 2)  # 1.2 rad in 0.2 s needs more than the servos' peak
    # The clip stretches its period so a 2.4 rad half-stroke peaks at 13 rad/s: d = pi 2.4 / (2 13) = 0.29 s, far
    # longer than the servos' shortest 0.057 s, so the fin's inertia adds less than the servo limit's bound.
    assert shortest == pytest.approx([math.pi * 2.4 / 26.0] * 2, rel=1e-9)
    assert gain.accel(5.0, 5.3, 5.4, 0.1) == pytest.approx(_by_hand(13.0, math.pi * 2.4 / 26.0), rel=1e-5)  # the wire
    assert 0.85 * gain.full < gain.accel(5.0, 5.3, 5.4, 0.1) < gain.full


@pytest.mark.parametrize("seed", [4, 5])
def test_the_first_stroke_from_still_is_covered_from_wherever_the_fins_halted(seed):
    # The robot's fins halt mid-stroke (a STOP) at random angles; the next command is latched whole and taken
    # anywhere in a round trip after its send: the fins' true force never exceeds the gain over any span.
    rng = np.random.default_rng(seed)
    mass = min(body_coefficients(P).m1, body_coefficients(P).m2)
    tighter = 0
    for trial in range(12):
        robot = FinReplay(P, FirmwareConfig(limits=LIMITS))
        robot.reset(0.0)
        robot.command(0.0, clip_beats(_wild(rng, 0), LIMITS)[0])
        halt = float(rng.uniform(0.3, 2.0))
        robot.stop(halt)
        gain = CommandedGain(P, LIMITS)
        gain.reset(halt)
        beats = clip_beats(_wild(rng, 0) if trial % 2 else _drifting(rng, 0), LIMITS)[0]
        sent = halt + 0.5
        take = sent + float(rng.uniform(0.0, 0.2))
        gain.command(sent, beats, lambda take=take: take)
        robot.advance(take)
        robot.command(take, beats)
        history, t = [], take
        while t < take + 1.2:
            t = round(t + 0.005, 9)
            robot.advance(t)
            history.append((t, _robot_force(robot), *_robot_strokes(robot)))
        assert max(h[1] for h in history) > 0  # the fins did move
        for start in np.arange(sent, sent + 1.0, 0.1):
            end = start + 0.15
            span = [h for h in history if start <= h[0] <= end]
            force = max([h[1] for h in span] or [0.0]) / mass
            rates, shortest = gain.strokes(start, end, end, 0.2)
            if span:
                assert np.all(np.max([h[2] for h in span], axis=0) <= rates + 1e-9), (trial, start, rates)
                assert np.all(np.min([h[3] for h in span], axis=0) >= shortest - 1e-9), (trial, start, shortest)
            allowed = gain.accel(start, end, end, 0.2)
            assert force <= allowed * (1 + 1e-9), (trial, start, force, allowed)
            tighter += allowed < 0.5 * gain.full
    assert tighter > 0


class _AckLink:
    """A link that acknowledges every command 10 ms after its send (experiment s)."""

    def __init__(self, sup_now):
        self.control_lost, self.stops, self.sent, self._now, self._acks = "", 0, 0, sup_now, {}

    def status_age(self):
        return 0.0

    def rtt(self):
        return 0.02

    def stop(self, wait=0.0):
        self.stops += 1
        return True

    def set_fins(self, beats, lease):
        self.sent += 1
        return self.sent

    def acknowledged_at(self, seq):
        return self._acks.get(seq)


class _NoCamera:
    def read(self):
        return None

    def close(self):
        pass


def _blind_supervisor(beats):
    """A supervisor whose fish was last seen 0.37 s ago moving at 0.1 m/s towards X = L, frames 0.2 s late."""
    camera = FrameGrabber(_NoCamera(), stale_after=100.0)  # the grabber's own silence alarm kept out of it
    sup = Supervisor(None, camera, None, Geofence(P, StopRule(0.05, 0.15, 0.03)), SafetyConfig())
    sup.link = _AckLink(sup.now)
    sup.arm()
    sup.camera.ages.extend([0.2] * 60)  # the measured latency: 0.2 s
    now = sup.now()
    sup.gain.reset(now - 5.0)
    sup.bound.reset(now - 5.0)
    for k in range(10):  # a command every 0.5 s, each acknowledged 10 ms after its send
        sent = now - 5.0 + 0.5 * k
        sup.gain.command(sent, beats, lambda sent=sent: sent + 0.01)
        sup.bound.running(sent, sent + 0.8 + 0.15)
    return sup, now


@pytest.mark.parametrize("x", [TANK_LENGTH - 0.48, TANK_LENGTH - 0.52])
def test_a_run_of_dropped_frames_with_gentle_fins_is_not_a_stop_but_a_dead_camera_is(x):
    # The all-of row's stop: 0.2 s camera latency, then 5 frames dropped (0.17 s): the last pose is 0.37 s old.
    for beats, stops in ((GENTLE, False), (np.array([[1.57, 1.2, 0.4, 1.0]] * 2), True)):
        sup, now = _blind_supervisor(beats)
        try:
            sup.watch.last_seen, sup.pose = now - 0.37, (x, 0.575, 0.0)
            sup._last_read = now - 0.17
            sup._read_times.extend(np.linspace(now - 0.8, now - 0.17, 20))  # 20 frames before the gap
            sup.velocity, sup.spread = (0.1, 0.0), (0.005, 0.005)
            assert sup.latency_budget == pytest.approx(0.2)
            old_rule = sup.geofence.breached(x, 0.575, 0.0, 0.1, 0.0, age=0.37 + sup._radio_delay(),
                                             spread=(0.01, 0.01), gain=sup.bound.accel * 0.02)
            assert old_rule  # the fastest gain the servos allow would have stopped it
            reason = sup.poll()
            assert (reason == "tracking_lost") == stops, (beats, reason)
            if stops:  # fins at full rate: the same gap stops it, saying what the camera did
                assert re.match(r"no frames from the camera for 0\.\d\d s \(\d+\.\d frame periods; 20 frames arrived "
                                r"in the last second", sup.watch.reason), sup.watch.reason
            # A dead camera: nothing for the tracking timeout from the capture; it stops whatever the fins.
            sup.watch.last_seen, sup._last_read = now - 0.51, now - 0.31
            assert sup.poll() == "tracking_lost"
            assert sup.watch.reason.startswith("no frames from the camera")
        finally:
            sup.close()


def test_drops_during_the_first_gentle_stroke_after_the_arm_are_not_a_stop_but_a_dead_camera_is():
    # The all-of row's early stops: the fins were still at the arm, the first command (a gentle stroke) was latched
    # whole, and 5 dropped frames behind 0.2 s of latency left the pose 0.37 s old during its first power stroke.
    # The servos' fastest gain (what the rule gave every first stroke) stops the fish; the stroke's own cannot.
    x = TANK_LENGTH - 0.36
    sup, now = _blind_supervisor(GENTLE)
    try:
        sup.gain.reset(now - 0.5)  # armed 0.5 s ago, fins still; one command since, acknowledged 10 ms after its send
        sup.gain.command(now - 0.45, GENTLE, lambda: now - 0.44)
        sup.watch.last_seen, sup.pose = now - 0.37, (x, 0.575, 0.0)
        sup._last_read = now - 0.17
        sup._read_times.extend(np.linspace(now - 0.8, now - 0.17, 20))
        sup.velocity, sup.spread = (0.02, 0.0), (0.005, 0.005)
        unseen = 0.37 - 0.15 - 0.2
        assert sup.geofence.breached(x, 0.575, 0.0, 0.02, 0.0, age=0.37 + sup._radio_delay(), spread=(0.01, 0.01),
                                     gain=sup.bound.accel * unseen)  # the servo limit's gain: a stop
        assert sup.poll() == ""
        sup.watch.last_seen, sup._last_read = now - 0.51, now - 0.31  # a dead camera: the tracking timeout
        assert sup.poll() == "tracking_lost"
        assert sup.watch.reason.startswith("no frames from the camera")
    finally:
        sup.close()
