"""Fin kinematics: eq. (21), its derivatives, the integrator's half-stroke form, the parameter-change rule.

Eq. (21) is written out again here (``eq21``) straight from the paper; derivatives
are checked against central finite differences of the angle.
"""

import math

import numpy as np
import pytest

from pectoral_gym import FinBeat, FullModel
from pectoral_gym.model.dynamics import fin_angle_eq21, stroke_kinematics

PATTERNS = [
    (math.radians(90), math.radians(20), 1.0, 4.0),
    (math.radians(100), math.radians(12), 0.8, 5.0),
    (math.radians(60), math.radians(30), 0.5, 0.5),  # zeta < 1: recovery faster than power
    (math.radians(120), math.radians(45), 2.0, 1.0),  # zeta = 1: symmetric beat
]


def eq21(t, g0, ga, tp, zeta):
    """Eq. (21) of the paper, one period repeated (plain Python, scalar)."""
    t = t % tp
    t1 = tp / (zeta + 1.0)
    if t <= t1:
        return g0 - ga * math.cos(math.pi * (zeta + 1.0) / tp * t)
    return g0 + ga * math.cos(math.pi * (zeta + 1.0) / (zeta * tp) * (t - t1))


def eq21_vec(t, *beat):
    return np.array([eq21(float(ti), *beat) for ti in np.atleast_1d(t)])


@pytest.mark.parametrize("beat", PATTERNS)
def test_fin_angle_eq21_matches_paper(beat):
    t = np.linspace(0.0, 3.0 * beat[2], 1001)
    g, _, _ = fin_angle_eq21(t, *beat)
    np.testing.assert_allclose(g, eq21_vec(t, *beat), rtol=0, atol=1e-12)


@pytest.mark.parametrize("beat", PATTERNS)
def test_fin_angle_eq21_extremes_and_range(beat):
    g0, ga, tp, zeta = beat
    t = np.linspace(0.0, tp, 20001)
    g, _, _ = fin_angle_eq21(t, *beat)
    assert g.min() >= g0 - ga - 1e-12 and g.max() <= g0 + ga + 1e-12
    assert g.max() == pytest.approx(g0 + ga, abs=1e-6)  # sampled, so the exact top may fall between samples
    assert g[0] == pytest.approx(g0 - ga, abs=1e-15)  # starts at the front turning point
    assert fin_angle_eq21(np.array([tp / (zeta + 1.0)]), *beat)[0][0] == pytest.approx(g0 + ga, abs=1e-12)


@pytest.mark.parametrize("beat", PATTERNS)
def test_derivatives_match_central_differences(beat):
    tp, zeta = beat[2], beat[3]
    t1 = tp / (zeta + 1.0)
    h = 1e-6
    # sample strictly inside the two half-strokes (g'' jumps at the boundaries)
    t = np.concatenate([np.linspace(0.02, 0.98, 37) * t1, t1 + np.linspace(0.02, 0.98, 37) * (tp - t1)])
    t = np.concatenate([t, t + tp])  # second cycle too
    g, gd, gdd = fin_angle_eq21(t, *beat)
    gp, gdp, _ = fin_angle_eq21(t + h, *beat)
    gm, gdm, _ = fin_angle_eq21(t - h, *beat)
    scale_d = beat[1] * math.pi * (zeta + 1.0) / tp * max(1.0, 1.0 / zeta)
    np.testing.assert_allclose(gd, (gp - gm) / (2 * h), rtol=0, atol=1e-6 * scale_d)
    np.testing.assert_allclose(gdd, (gdp - gdm) / (2 * h), rtol=0, atol=1e-5 * scale_d**2 / max(beat[1], 1e-3))
    np.testing.assert_allclose(gdd, (gp - 2 * g + gm) / h**2, rtol=0, atol=2e-3 * scale_d**2 / max(beat[1], 1e-3))


@pytest.mark.parametrize("beat", PATTERNS)
def test_angle_and_rate_continuous_at_stroke_boundaries(beat):
    g0, ga, tp, zeta = beat
    t1 = tp / (zeta + 1.0)
    eps = 1e-9
    for tb in (t1, tp, t1 + tp, 2 * tp):
        g, gd, _ = fin_angle_eq21(np.array([tb - eps, tb + eps]), *beat)
        assert abs(g[1] - g[0]) < 1e-7
        peak_accel = ga * (math.pi * (zeta + 1.0) / tp * max(1.0, 1.0 / zeta)) ** 2
        assert abs(gd[0]) <= 1.01 * peak_accel * eps  # turning point: rate vanishes on both sides
        assert abs(gd[1]) <= 1.01 * peak_accel * eps


@pytest.mark.parametrize("beat", PATTERNS)
def test_power_stroke_duration_and_direction(beat):
    g0, ga, tp, zeta = beat
    t = np.linspace(0.0, tp, 100001)[:-1]
    _, gd, _ = fin_angle_eq21(t, *beat)
    dt = t[1] - t[0]
    # power stroke: g increasing (backward sweep)
    t_power = np.count_nonzero(gd > 0) * dt
    assert t_power == pytest.approx(tp / (zeta + 1.0), abs=3 * dt)
    # the recovery stroke is zeta times slower: its peak rate is 1/zeta of the power stroke's
    assert -gd.min() == pytest.approx(gd.max() / zeta, rel=1e-6)
    # and both strokes cover the same angle 2 gA
    assert np.sum(gd[gd > 0]) * dt == pytest.approx(2 * ga, rel=1e-4)
    assert np.sum(gd[gd < 0]) * dt == pytest.approx(-2 * ga, rel=1e-4)


def test_stroke_kinematics_half_cosine_and_derivatives():
    a, b, d = 0.3, 1.2, 0.7
    for s in np.linspace(0.0, d, 11):
        g, gd, gdd = stroke_kinematics(s, d, a, b)
        assert g == pytest.approx(0.5 * (a + b) - 0.5 * (b - a) * math.cos(math.pi * s / d), abs=1e-14)
        h = 1e-6
        gp = stroke_kinematics(s + h, d, a, b)
        gm = stroke_kinematics(s - h, d, a, b)
        assert gd == pytest.approx((gp[0] - gm[0]) / (2 * h), abs=1e-7)
        assert gdd == pytest.approx((gp[1] - gm[1]) / (2 * h), abs=1e-6)
    assert stroke_kinematics(0.0, d, a, b)[0] == pytest.approx(a)
    assert stroke_kinematics(d, d, a, b)[0] == pytest.approx(b)
    assert stroke_kinematics(0.0, d, a, b)[1] == pytest.approx(0.0, abs=1e-15)
    assert stroke_kinematics(d, d, a, b)[1] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("beat", PATTERNS)
def test_stroke_kinematics_reproduces_eq21_half_strokes(beat):
    g0, ga, tp, zeta = beat
    t1 = tp / (zeta + 1.0)
    for s in np.linspace(0.0, t1, 7):
        np.testing.assert_allclose(stroke_kinematics(s, t1, g0 - ga, g0 + ga),
                                   [x[0] for x in fin_angle_eq21(np.array([s]), *beat)], atol=1e-9)
    for s in np.linspace(0.0, tp - t1, 7)[1:]:
        np.testing.assert_allclose(stroke_kinematics(s, tp - t1, g0 + ga, g0 - ga)[:2],
                                   [x[0] for x in fin_angle_eq21(np.array([t1 + s]), *beat)[:2]], atol=1e-9)


# --------------------------------------------------------------------------- integrator fin state


def _sample_model(model, dt, n_steps):
    times, angles, rates = [model.time], [], []
    a, r = model.fin_angles()
    angles.append(a.copy())
    rates.append(r.copy())
    for _ in range(n_steps):
        model.advance(dt)
        a, r = model.fin_angles()
        times.append(model.time)
        angles.append(a.copy())
        rates.append(r.copy())
    return np.array(times), np.array(angles), np.array(rates)


@pytest.mark.parametrize("beat", PATTERNS)
def test_model_fin_angles_follow_eq21_over_several_cycles(beat):
    model = FullModel(1)
    right = FinBeat(*beat)
    left = FinBeat(math.radians(80), math.radians(15), 0.7, 2.0)
    model.reset(right=right, left=left)
    dt = 0.0137  # incommensurate with the strokes
    n = int(4 * max(beat[2], 0.7) / dt)
    t, ang, rate = _sample_model(model, dt, n)
    np.testing.assert_allclose(ang[:, 0, 0], eq21_vec(t, *beat), atol=1e-9)
    np.testing.assert_allclose(ang[:, 0, 1], eq21_vec(t, *left.as_array()), atol=1e-9)
    _, gd_r, _ = fin_angle_eq21(t, *beat)
    _, gd_l, _ = fin_angle_eq21(t, *left.as_array())
    np.testing.assert_allclose(rate[:, 0, 0], gd_r, atol=1e-7)
    np.testing.assert_allclose(rate[:, 0, 1], gd_l, atol=1e-7)


def test_model_fin_angles_batched_independent():
    model = FullModel(len(PATTERNS))
    beats = np.array(PATTERNS)
    model.reset(right=beats, left=beats[::-1])
    t, ang, _ = _sample_model(model, 0.021, 150)
    for i, b in enumerate(PATTERNS):
        np.testing.assert_allclose(ang[:, i, 0], eq21_vec(t, *b), atol=1e-9)
        np.testing.assert_allclose(ang[:, i, 1], eq21_vec(t, *PATTERNS[::-1][i]), atol=1e-9)


# --------------------------------------------------------------------------- parameter-change rule

P1 = (math.radians(90), math.radians(20), 1.0, 4.0)  # power stroke 0.2 s, recovery 0.8 s
P2 = (math.radians(95), math.radians(10), 0.8, 3.0)  # power 0.2 s, recovery 0.6 s; turning points 85, 105 deg


def _assert_continuous(angles, rates, dt):
    """No jump larger than what the sampled rate allows (plus a small curvature margin)."""
    jumps = np.abs(np.diff(angles))
    allowed = np.maximum(np.abs(rates[:-1]), np.abs(rates[1:])) * dt * 1.05 + 1e-9
    assert np.all(jumps <= allowed), f"largest excess {np.max(jumps - allowed)} rad"
    rate_jumps = np.abs(np.diff(rates))
    assert rate_jumps.max() < 0.05 * np.abs(rates).max()


def test_change_during_power_stroke_waits_for_turning_point():
    model = FullModel(1)
    model.reset(right=FinBeat(*P1))
    model.advance(0.1)  # middle of the first power stroke (0 .. 0.2 s)
    model.command(right=FinBeat(*P2))
    dt = 1e-3
    t, ang, rate = _sample_model(model, dt, 2500)
    g, gd = ang[:, 0, 0], rate[:, 0, 0]
    _assert_continuous(g, gd, dt)
    # until the turning point at t = 0.2 s the old stroke continues (eq. 21 of P1)
    before = t <= 0.2 + 1e-9
    np.testing.assert_allclose(g[before], eq21_vec(t[before], *P1), atol=1e-9)
    # transition: half-cosine recovery from P1's top (110 deg) to P2's front turning point (85 deg),
    # with P2's recovery duration zeta T / (zeta + 1) = 0.6 s
    trans = (t > 0.2 + 1e-9) & (t <= 0.8)
    top, front, dur = P1[0] + P1[1], P2[0] - P2[1], 0.6
    expect = 0.5 * (top + front) + 0.5 * (top - front) * np.cos(math.pi * (t[trans] - 0.2) / dur)
    np.testing.assert_allclose(g[trans], expect, atol=1e-9)
    # afterwards: eq. (21) of P2 shifted to start its power stroke at t = 0.8 s
    after = t >= 0.8
    np.testing.assert_allclose(g[after], eq21_vec(t[after] - 0.8, *P2), atol=1e-9)


def test_active_pattern_switches_only_at_turning_point():
    model = FullModel(1)
    model.reset(right=FinBeat(*P1))
    model.advance(0.1)
    model.command(right=FinBeat(*P2))
    model.advance(0.09)  # t = 0.19 s, 10 ms before the turning point
    np.testing.assert_allclose(model.active_beats()[0, 0], P1)
    _, rate = model.fin_angles()
    assert rate[0, 0] > 0.5  # still sweeping with P1's power stroke
    model.advance(0.011)  # cross t = 0.2 s
    np.testing.assert_allclose(model.active_beats()[0, 0], P2)


def test_change_during_recovery_stroke():
    model = FullModel(1)
    model.reset(right=FinBeat(*P1))
    model.advance(0.5)  # recovery of P1 runs 0.2 .. 1.0 s
    model.command(right=FinBeat(*P2))
    dt = 1e-3
    t, ang, rate = _sample_model(model, dt, 2000)
    g, gd = ang[:, 0, 0], rate[:, 0, 0]
    _assert_continuous(g, gd, dt)
    before = t <= 1.0 + 1e-9
    np.testing.assert_allclose(g[before], eq21_vec(t[before], *P1), atol=1e-9)
    # at t = 1.0 the fin is at P1's front (70 deg); the next stroke is a power stroke of P2 to 105 deg in 0.2 s,
    # then P2 runs as eq. (21) shifted by 1.0 s from its recovery (first power stroke differs only in start angle)
    trans = (t > 1.0 + 1e-9) & (t <= 1.2)
    start, top = P1[0] - P1[1], P2[0] + P2[1]
    expect = 0.5 * (start + top) - 0.5 * (top - start) * np.cos(math.pi * (t[trans] - 1.0) / 0.2)
    np.testing.assert_allclose(g[trans], expect, atol=1e-9)
    after = t >= 1.2
    np.testing.assert_allclose(g[after], eq21_vec(t[after] - 1.0, *P2), atol=1e-9)


def test_fin_at_rest_latches_at_once():
    model = FullModel(1)
    model.reset()  # both fins at rest at 90 deg
    model.advance(1.37)
    ang, rate = model.fin_angles()
    assert ang[0, 0] == pytest.approx(math.pi / 2) and rate[0, 0] == 0.0
    t_cmd = model.time
    model.command(right=FinBeat(*P2))
    model.advance(1e-3)
    np.testing.assert_allclose(model.active_beats()[0, 0], P2)  # no waiting for a stroke end
    dt = 1e-3
    t, ang, rate = _sample_model(model, dt, 1500)
    g, gd = ang[:, 0, 0], rate[:, 0, 0]
    _assert_continuous(g, gd, dt)
    # first a power stroke from 90 deg to P2's top (105 deg) in 0.2 s, then eq. (21) of P2 from its recovery
    trans = t - t_cmd <= 0.2
    start, top = math.pi / 2, P2[0] + P2[1]
    expect = 0.5 * (start + top) - 0.5 * (top - start) * np.cos(math.pi * (t[trans] - t_cmd) / 0.2)
    np.testing.assert_allclose(g[trans], expect, atol=1e-9)
    after = ~trans
    np.testing.assert_allclose(g[after], eq21_vec(t[after] - t_cmd, *P2), atol=1e-9)
    # the left fin, never commanded to move, stays at rest
    np.testing.assert_allclose(ang[:, 0, 1], math.pi / 2, atol=0)


def test_stop_command_parks_fin_at_bias():
    model = FullModel(1)
    model.reset(right=FinBeat(*P1))
    model.advance(0.3)
    model.command(right=FinBeat.rest(math.radians(80)))
    model.advance(0.7)  # finish P1's recovery at t = 1.0 (fin at 70 deg)
    ang, _ = model.fin_angles()
    assert ang[0, 0] == pytest.approx(P1[0] - P1[1], abs=1e-9)
    model.advance(3.0)
    ang, rate = model.fin_angles()
    assert ang[0, 0] == pytest.approx(math.radians(80), abs=1e-12)
    assert rate[0, 0] == 0.0


def test_parked_fin_latches_new_pattern_at_once():
    # A fin parked by a rest command (stroke from == to) is at rest: a new pattern starts at once.
    model = FullModel(1)
    model.reset(right=FinBeat(*P1))
    model.advance(0.3)
    model.command(right=FinBeat.rest(math.radians(80)))
    # recovery ends at 1.0 s, the park move 70 -> 80 deg ends at 1.5 s; at 1.7 s the fin has been still for 0.2 s
    # (possibly inside a zero-amplitude half-stroke of the rest pattern, which must not delay the new command)
    model.advance(1.4)
    ang, rate = model.fin_angles()
    assert ang[0, 0] == pytest.approx(math.radians(80), abs=1e-12) and rate[0, 0] == 0.0
    t_cmd = model.time
    model.command(right=FinBeat(*P2))
    model.advance(1e-3)
    np.testing.assert_allclose(model.active_beats()[0, 0], P2)
    t, ang, _ = _sample_model(model, 1e-3, 1000)
    start, top = math.radians(80), P2[0] + P2[1]
    trans = t - t_cmd <= 0.2
    expect = 0.5 * (start + top) - 0.5 * (top - start) * np.cos(math.pi * (t[trans] - t_cmd) / 0.2)
    np.testing.assert_allclose(ang[trans, 0, 0], expect, atol=1e-9)
    np.testing.assert_allclose(ang[~trans, 0, 0], eq21_vec(t[~trans] - t_cmd, *P2), atol=1e-9)


def test_repeated_identical_command_does_not_disturb_motion():
    model = FullModel(1)
    model.reset(right=FinBeat(*P1))
    t, g = [], []
    for _ in range(300):
        model.command(right=FinBeat(*P1))
        model.advance(0.0101)
        t.append(model.time)
        g.append(model.fin_angles()[0][0, 0])
    np.testing.assert_allclose(g, eq21_vec(np.array(t), *P1), atol=1e-9)
