"""The blind rule's take-time tree (hardware/safety/blind_phase.py): the robot's half-strokes, whatever the takes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pectoral_gym.hardware.safety import blind_phase
from pectoral_gym.hardware.safety.blind import CommandedGain, fin_force_bound
from pectoral_gym.hardware.safety.rules import CommandFilter
from pectoral_gym.model import strokes
from pectoral_gym.model.dynamics import fin_force_right
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.params import FishParams, body_coefficients
from pectoral_gym.model.servo import ServoLimits

P = FishParams()
LIMITS = ServoLimits()
MASS = min(body_coefficients(P).m1, body_coefficients(P).m2)
GENTLE = np.array([[1.57, 0.2, 1.5, 1.0], [1.57, 0.2, 1.5, 1.0]])  # peak pi 0.4 / 1.5 = 0.84 rad/s per fin


def _robot_strokes(replay: FinReplay) -> list[tuple[float, float]]:
    """Per fin, ``(peak rate [rad/s], duration [s])`` of the replayed half-stroke in progress (``(0, inf)``: still)."""
    out = []
    for f in range(2):
        fin = replay.fins[0][f]
        d, swing = fin[strokes.DURATION], fin[strokes.ANGLE_TO] - fin[strokes.ANGLE_FROM]
        moving = d > 0 and swing != 0 and fin[strokes.ELAPSED] < d
        out.append((math.pi * abs(swing) / (2.0 * d), float(d)) if moving else (0.0, math.inf))
    return out


def _robot_force(replay: FinReplay) -> float:
    """The two fins' force magnitudes [N] on the body now (eqs. 9-17 through ``fin_force_right``), summed."""
    total = 0.0
    for f in range(2):
        fin = replay.fins[0][f]
        d, elapsed, a0, a1 = fin[strokes.DURATION], fin[strokes.ELAPSED], fin[strokes.ANGLE_FROM], fin[strokes.ANGLE_TO]
        if d <= 0 or elapsed >= d or a0 == a1:
            continue
        half, w, phase = 0.5 * (a1 - a0), math.pi / d, math.pi * elapsed / d
        fx, fy = fin_force_right(0.5 * (a0 + a1) - half * math.cos(phase), half * w * math.sin(phase),
                                 half * w * w * math.cos(phase), P.fin_drag_constant, P.fin_inertia_constant)
        total += math.hypot(fx, fy)
    return total


def _wild(rng):
    return np.stack([rng.uniform(0.5, 2.6, 2), rng.uniform(0, 0.8, 2), rng.uniform(0.4, 3, 2),
                     rng.uniform(0.5, 6, 2)], axis=1)


def _drifting(rng):
    """A swimming policy's commands: each parameter drifts a little per step."""
    return np.array([[1.57, 0.25, 1.5, 2.0]] * 2) + rng.normal(0.0, [0.3, 0.1, 0.3, 0.8], size=(2, 4))


def _steering(rng):
    """Gentle strokes whose bias jumps (the all-of row's steering), now and then a zero-amplitude park."""
    beats = GENTLE.copy()
    beats[:, 0] = rng.uniform(0.5, 2.6, 2)
    beats[:, 1] = rng.choice([0.0, 0.1, 0.3], 2)
    return beats


def _episode(seed: int, policy, rtt: float = 0.2, loss: float = 0.15, steps: int = 50, halt: bool = False):
    """The robot's fins under ``policy`` with random take times, returns and losses; the gain fed as the PC is.

    Each command is sent every 0.5 s and taken uniformly within the round trip after its send, or lost; its
    acknowledgement (a STATUS after the robot took it or a later one) comes a random return delay later, and
    the firmware acts on a take at its next tick. The first command is gentle (a rest angle the tree can leave
    unknown); a halt at the arm leaves the fins at a random angle. ``halt``: twice the PC learns that the fins may
    have halted after some time (a lease's end, a watchdog), before it sends its next command, and they do, at a
    random time in between. Returns the gain and the robot's history ``(t, force [N], [(rate, duration)] per
    fin)`` every 5 ms.
    """
    rng = np.random.default_rng(seed)
    robot = FinReplay(P, FirmwareConfig(limits=LIMITS))
    robot.reset(0.0)
    robot.command(0.0, _wild(rng).clip(0.3, 2.8))
    robot.stop(float(rng.uniform(0.2, 1.0)))  # halted at a random angle
    armed = 1.0
    gain = CommandedGain(P, LIMITS)
    gain.reset(armed)
    commands = CommandFilter(LIMITS)
    acks: dict[int, float] = {}
    pending: list[tuple[float, np.ndarray]] = []
    history = []
    t = armed

    sends = []
    for step in range(steps):
        sent = armed + 0.1 + 0.5 * step
        beats = commands(GENTLE if step == 0 else policy(np.random.default_rng([seed, step])), 0.5)
        take = sent + float(rng.uniform(0.0, rtt))
        if step == 0 or rng.uniform() > loss:
            pending.append((take, beats))
            acks[step] = take + float(rng.uniform(0.0, 0.5 * rtt))
        sends.append((sent, beats))
    told = [armed + 10.3, armed + 17.05] if halt else []  # when the PC learns the fins may have halted
    halts = []
    for step, (sent, beats) in enumerate(sends):
        for h in told:
            if sent - 0.5 < h <= sent:  # told before the next command is sent; the halt falls in between
                gain.still(h)
                halts.append(float(rng.uniform(h, sent)))
        # The PC learns of an acknowledgement of this command or a later one (a lost command's successor's).
        later = [acks[j] for j in acks if j >= step]
        ack = min(later) if later else None
        gain.command(sent, beats, lambda ack=ack: ack)
    end = armed + 0.5 * steps + 0.6
    while t < end - 1e-9:
        t = round(t + 0.005, 9)
        if halts and halts[0] <= t:
            robot.stop(halts.pop(0))
        for item in [p for p in pending if p[0] <= t]:
            robot.command(item[0], item[1])
            pending.remove(item)
        robot.advance(t)
        history.append((t, _robot_force(robot), _robot_strokes(robot)))
    return gain, history, armed


def _violations(gain: CommandedGain, history, armed: float, with_box: bool = True) -> tuple[int, int, float, float]:
    """Spans of 0.6 s where the robot ran a half-stroke the tree did not hold, or more force than the gain allows.

    Returns those, the spans checked, the mean gains of the tree and of the box [m/s^2]. ``with_box``: the gain is
    the tighter of the box's and the tree's (the box needs its halts told in time order; else the tree's alone).
    """
    bad, checked, tree_gain, box_gain = 0, 0, 0.0, 0.0
    for end in np.arange(armed + 1.0, history[-1][0], 0.25):
        start = end - 0.6
        span = [h for h in history if start <= h[0] <= end]
        tree = gain._tree(start, end)
        if tree is None:
            continue  # nothing claimed (a first stroke from rest the firmware may stretch): the box rules alone
        for fin in range(2):
            pairs = tree[fin]
            for rate, duration in {h[2][fin] for h in span if h[2][fin][0] > 0}:
                # The robot's half-stroke is held by one of the tree's: at least its rate, at most its duration (the
                # same half-stroke but for a first one from rest, whose rate the tree takes from the far end of the
                # servo range and whose period the rest angle may stretch).
                bad += not np.any((pairs[:, 0] >= rate - 1e-9) & (pairs[:, 1] <= duration + 1e-9))
        force = max(h[1] for h in span) / MASS
        allowed = sum(max((fin_force_bound(P, LIMITS, w, d, f) for w, d in tree[f]), default=0.0)
                      for f in range(2)) / MASS
        if with_box:
            assert gain.accel(start, end, end, 0.2) <= allowed * (1 + 1e-12)
            allowed = gain.accel(start, end, end, 0.2)
        bad += force > allowed * (1 + 1e-9)
        checked += 1
        tree_gain += allowed
        box_gain += _box_accel(gain, start, end) if with_box else 0.0
    return bad, checked, tree_gain / max(checked, 1), box_gain / max(checked, 1)


def _box_accel(gain: CommandedGain, start: float, end: float) -> float:
    rates, shortest = gain.box_strokes(start, end, end, 0.2)
    return sum(fin_force_bound(P, LIMITS, w, d, f) for f, (w, d) in enumerate(zip(rates, shortest, strict=True))) / MASS


@pytest.mark.parametrize(("seed", "policy"), [(0, _wild), (1, _drifting), (2, _steering), (3, _steering)])
def test_the_robots_half_strokes_are_in_the_tree_whatever_the_take_times(seed, policy):
    gain, history, armed = _episode(seed, policy)
    bad, checked, tree_gain, box_gain = _violations(gain, history, armed)
    assert checked > 80 and bad == 0
    assert tree_gain <= box_gain  # never looser than the box (the gain takes the tighter)


@pytest.mark.parametrize(("seed", "policy"), [(11, _wild), (13, _wild), (14, _steering)])
def test_fins_that_halted_and_restarted_stay_in_the_tree(seed, policy):
    # The tree alone (the box needs its halts told in time order, which this test does not do).
    gain, history, armed = _episode(seed, policy, halt=True)
    assert any(h[2][0][0] == 0.0 for h in history if h[0] > armed + 10.3)  # the fins did halt
    bad, checked, _, _ = _violations(gain, history, armed, with_box=False)
    assert checked >= 90 and bad == 0
    gain._halts, gain._memo = [], {}  # the mutation: the halts not told; the restarts' strokes fall outside the tree
    assert _violations(gain, history, armed, with_box=False)[0] > 0


def test_a_narrowed_take_interval_misses_the_robots_strokes(monkeypatch):
    # The mutation: every command taken when sent (the replay's own timing, no round trip). The robot's
    # half-strokes then fall outside the tree: the check above can fail.
    def sent_only(commands):
        sent = np.array([c[0] for c in commands], dtype=float)
        return sent, sent.copy()

    monkeypatch.setattr(blind_phase, "_takes", sent_only)
    found = 0
    for seed in (1, 2):
        gain, history, armed = _episode(seed, _steering if seed == 2 else _drifting)
        found += _violations(gain, history, armed)[0]
    assert found > 0


def _by_hand(rate: float, duration: float) -> float:
    """Two fins' force over the smaller mass at peak rate ``rate`` [rad/s], half-strokes of ``duration`` [s]."""
    force = P.fin_drag_constant * rate ** 2 + P.fin_inertia_constant * math.sqrt(rate ** 4 +
                                                                                  (math.pi * rate / duration) ** 2)
    return 2.0 * force / MASS


def test_a_steering_stroke_that_ended_before_the_span_is_not_counted():
    # Gentle strokes at bias 1.0 from 0.1 s, a jump to bias 2.0 sent at 2.1 s, each command acknowledged 50 ms after
    # its send. The first latch from rest falls in [0.1, 0.16] s, so the turning points in [0.85, 0.91] + 0.75 k s:
    # the jump (taken by 2.16 s) is latched at [2.35, 2.41] s, the end of a power stroke (the first from rest is
    # one), and its transitional stroke, a recovery from 1.2 to 1.8 rad (pi 0.6 / 1.5 = 1.26 rad/s; the bias slews
    # pi rad/s x 0.75 s, past the jump), is over by 3.16 s. From 3.25 s only the steady strokes run, 0.84 rad/s in
    # 0.75 s. The box, reaching back a round trip (0.2 s) and a half-stroke (0.75 s) to the replay's old bias,
    # pairs the old lower turning point (0.8 rad) with the new upper one (2.2 rad): pi 1.4 / 1.5 = 2.93 rad/s.
    gain = CommandedGain(P, LIMITS)
    gain.reset(0.0)
    low, high = GENTLE.copy(), GENTLE.copy()
    low[:, 0], high[:, 0] = 1.0, 2.0
    for k in range(8):
        sent = 0.1 + 0.5 * k
        gain.command(sent, low if k < 4 else high, lambda sent=sent: sent + 0.05)
    assert gain.accel(3.25, 3.3, 3.9, 0.2) == pytest.approx(_by_hand(math.pi * 0.4 / 1.5, 0.75), rel=1e-6)
    assert _box_accel(gain, 3.25, 3.9) == pytest.approx(_by_hand(math.pi * 1.4 / 1.5, 0.75), rel=1e-6)
    # While the transitional stroke may still run, it is counted.
    assert gain.accel(3.0, 3.1, 3.6, 0.2) == pytest.approx(_by_hand(math.pi * 0.6 / 1.5, 0.75), rel=1e-6)


def test_a_first_stroke_the_rest_angle_may_stretch_is_taken_at_its_fastest_and_shortest():
    # A = 1.2 rad at 0.4 s, ratio 1: the clip stretches the period to pi 1.2 x 2 / 13 = 0.58 s (power stroke 0.29 s).
    # From rest at an unknown angle the swing to bias + A = 2.77 rad is at most 2.77 - 10 deg = 2.60 rad: the
    # firmware may stretch it further (period unknown, at least 0.58 s); the tree takes 13 rad/s (capped) and 0.29 s.
    fast = CommandedGain(P, LIMITS)
    fast.reset(0.0)
    fast.command(0.1, np.array([[1.57, 1.2, 0.4, 1.0]] * 2), lambda: 0.2)
    for pairs in fast._tree(0.3, 0.4):
        assert pairs[:, 0].max() == pytest.approx(13.0)
        assert pairs[:, 1].min() == pytest.approx(math.pi * 1.2 * 2.0 / 13.0 / 2.0, rel=1e-3)
    # A power stroke to 0.3 rad in a seventh of 0.4 s: from the far end the period stretches to
    # pi 2.67 x 7 / (2 x 13) = 2.26 s, and the rate rule (4 s/s x 0.32 s) cannot bring it back to 0.4 s at the next
    # turning point, while from a near angle it is 0.4 s: what the fin runs next depends on the rest angle, and the
    # tree claims nothing (the box rules).
    parked = CommandedGain(P, LIMITS)
    parked.reset(0.0)
    parked.command(0.1, np.array([[0.3, 0.0, 0.4, 6.0]] * 2), lambda: 0.2)
    assert parked._tree(0.3, 1.0) is None
    assert parked.accel(0.3, 0.4, 1.0, 0.2) == pytest.approx(_box_accel(parked, 0.3, 1.0), rel=1e-12)
