"""FullModel and AveragedModel: turning directions, symmetry, batching, dissipation, and the ODE itself.

References are independent of the package's integrators:

* eq. (19)-(20) typed in here and solved with ``scipy.integrate.solve_ivp``
  (DOP853, tight tolerances, restarted at every stroke boundary), with the fin
  forcing from eq. (21) and the closed-form blade-element force;
* the closed-form coast-down with fins at rest: ``m1 dvx/dt = -c1 vx^2`` gives
  ``vx = v0 / (1 + c1 v0 t / m1)`` and ``s = (m1/c1) ln(1 + c1 v0 t / m1)``;
* the energy balance ``dE/dt = -c1 |V|^3 - C_M |omega|^3`` for
  ``E = (m1 vx^2 + m2 vy^2 + J3 omega^2) / 2`` with fins at rest (the Coriolis
  terms of eq. 20 and the lift terms do no work).

Sign reasoning for a turn (x forward, y left, omega > 0 = left turn): the right
fin pivots at ``y = -C_p``; its mean thrust ``f_x > 0`` gives the moment
``tau = (r x f)_z = -(-C_p) f_x > 0``, so the right fin alone turns the fish left.
With bias 90 deg its mean side force is zero, and the sway equation at steady
state, ``0 = -m1 vx omega - (c1 + c2 ...) |V| vy``, forces ``vy`` to the sign of
``-vx omega``: the body skids outward, ``vy < 0``.
"""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.special import j1

from pectoral_gym import AveragedModel, FinBeat, FishParams, FullModel, ScalingFunctions
from pectoral_gym.model.kfunctions import FEATURES, FORMAT

P = FishParams()
M1, M2, J3 = 0.795 + 0.095, 0.795 + 0.1794, 4.26e-4 + 2.7e-5
C1 = 0.5 * 1000 * 0.0325 * 0.3870
C2 = 0.5 * 1000 * 0.0325 * 0.0808
CM = 8.5e-3
CP = 0.03
K_DRAG = 4.1464 * 1000 * 0.041 * 0.061**3 / 6
K_INERTIA = 0.008 * 0.061 / 2

TURN = FinBeat.from_degrees(90, 20, 1.0, 4.0)
FORWARD = FinBeat.from_degrees(100, 12, 0.8, 5.0)


# --------------------------------------------------------------------------- independent reference


def eq21(t, beat):
    g0, ga, tp, zeta = beat
    t = t % tp
    t1 = tp / (zeta + 1.0)
    if t <= t1:
        w = math.pi / t1
        return g0 - ga * math.cos(w * t), ga * w * math.sin(w * t), ga * w * w * math.cos(w * t)
    w = math.pi / (tp - t1)
    s = t - t1
    return g0 + ga * math.cos(w * s), -ga * w * math.sin(w * s), -ga * w * w * math.cos(w * s)


def right_fin_force(g, gd, gdd):
    m = np.array([math.cos(g), -math.sin(g)])
    n = np.array([-math.sin(g), -math.cos(g)])
    return -K_DRAG * gd * abs(gd) * n - K_INERTIA * (gdd * n - gd * gd * m)


def forcing(t, right, left):
    fr = right_fin_force(*eq21(t, right)) if right is not None else np.zeros(2)
    fl = right_fin_force(*eq21(t, left)) if left is not None else np.zeros(2)
    fl = fl * np.array([1.0, -1.0])  # mirror image
    return fr[0] + fl[0], fr[1] + fl[1], CP * fr[0] - CP * fl[0]


def eq19(state, f):
    _, _, psi, vx, vy, om = state
    fx, fy, tau = f
    speed = math.hypot(vx, vy)
    alpha = math.atan(vy / vx) if vx != 0 else 0.0
    return [
        vx * math.cos(psi) - vy * math.sin(psi),
        vx * math.sin(psi) + vy * math.cos(psi),
        om,
        M2 / M1 * vy * om - C1 / M1 * vx * speed + C2 / M1 * vy * speed * alpha + fx / M1,
        -M1 / M2 * vx * om - C1 / M2 * vy * speed - C2 / M2 * vx * speed * alpha + fy / M2,
        (M1 - M2) / J3 * vx * vy - CM / J3 * om * abs(om) + tau / J3,
    ]


def boundaries(beat, t_end):
    if beat is None:
        return []
    g0, ga, tp, zeta = beat
    t1 = tp / (zeta + 1.0)
    out, k = [], 0
    while k * tp < t_end:
        out += [k * tp + t1, (k + 1) * tp]
        k += 1
    return out


def reference_full(right, left, t_end, y0=None):
    """solve_ivp of eq. (19) with eq. (21) forcing, restarted at every stroke boundary."""
    r = None if right is None else tuple(right.as_array())
    lf = None if left is None else tuple(left.as_array())
    cuts = sorted({0.0, t_end, *[b for b in boundaries(r, t_end) + boundaries(lf, t_end) if b < t_end]})
    y = np.zeros(6) if y0 is None else np.asarray(y0, float)
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        sol = solve_ivp(lambda t, s: eq19(s, forcing(t, r, lf)), (a, b), y, method="DOP853", rtol=1e-11, atol=1e-13)
        y = sol.y[:, -1]
    return y


def closed_form_average(beat, side):
    g0, ga, tp, zeta = beat.as_array()
    base = K_DRAG * math.pi**2 * (zeta**2 - 1) / (zeta * tp**2) * ga * j1(ga)
    fx, fy = base * math.sin(g0), base * math.cos(g0)
    return np.array([fx, side * fy, side * CP * fx])


def reference_averaged(right, left, t_end, y0=None):
    f = closed_form_average(right, 1.0) + closed_form_average(left, -1.0)
    sol = solve_ivp(lambda t, s: eq19(s, f), (0, t_end), np.zeros(6) if y0 is None else y0, method="DOP853",
                    rtol=1e-11, atol=1e-13)
    return sol.y[:, -1]


def run(model, duration, **reset):
    model.reset(**reset)
    model.advance(duration)
    return model.state.copy()


def cycle_average(model, window):
    before = model.integral.copy()
    model.advance(window)
    return (model.integral - before) / window


# --------------------------------------------------------------------------- the ODE itself


@pytest.mark.parametrize("right,left", [(TURN, None), (FORWARD, FinBeat.from_degrees(70, 25, 0.7, 2.0))])
def test_full_model_matches_independent_ode_solution(right, left):
    t_end = 3.0
    ref = reference_full(right, left, t_end)
    fine = run(FullModel(1, dt_max=0.00125, min_substeps=128), t_end, right=right, left=left)[0]
    np.testing.assert_allclose(fine, ref, rtol=0, atol=5e-8)
    default = run(FullModel(1), t_end, right=right, left=left)[0]
    np.testing.assert_allclose(default, ref, rtol=0, atol=5e-4)  # |omega| swings up to ~0.7 rad/s here


@pytest.mark.parametrize("right,left", [(TURN, None), (FORWARD, FinBeat.from_degrees(70, 25, 0.7, 2.0))])
def test_full_model_converges_at_high_order(right, left):
    # RK4 with substeps landing on every stroke boundary: quartering the step divides the error by ~4^4;
    # require more than 4^3.3 = 100 (a boundary-straddling step would drop this to first/second order).
    ref = reference_full(right, left, 3.0)
    errors = [np.abs(run(FullModel(1, dt_max=dt, min_substeps=ms), 3.0, right=right, left=left)[0] - ref).max()
              for dt, ms in ((0.01, 16), (0.0025, 64))]
    assert errors[0] / errors[1] > 100


VIOLENT = (FinBeat.from_degrees(60, 30, 0.5, 5), FinBeat.from_degrees(120, 30, 0.5, 5))  # fastest default strokes


@pytest.mark.parametrize("right,left", [(TURN, None), (FORWARD, FinBeat.from_degrees(70, 25, 0.7, 2.0)), VIOLENT])
def test_full_model_fast_preset_stays_close_to_independent_ode_solution(right, left):
    # 8 substeps per half-stroke, at most 0.05 s: about 1e-4 of the state after 3 s (the reference preset ~1e-5)
    got = run(FullModel(1, integration="fast"), 3.0, right=right, left=left)[0]
    np.testing.assert_allclose(got, reference_full(right, left, 3.0), rtol=0, atol=2e-3)


@pytest.mark.parametrize("right,left", [(TURN, None), (FORWARD, FinBeat.from_degrees(70, 25, 0.7, 2.0)), VIOLENT])
def test_full_model_huge_steps_stay_stable(right, left):
    # One substep per half-stroke and dt_max 1 s: without the stiffness bound on the step
    # (stepping._full_stable_step) RK4 diverges to NaN on all three; with it the error stays ~2 mm.
    got = run(FullModel(1, dt_max=1.0, min_substeps=1), 3.0, right=right, left=left)[0]
    np.testing.assert_allclose(got, reference_full(right, left, 3.0), rtol=0, atol=5e-3)


def test_full_model_fast_preset_holds_far_outside_the_action_ranges():
    # strokes up to 85 deg, periods 0.2-5 s, ratios 0.2-10, and a change at 4 s: the stiffness bound keeps
    # every fish finite and near the reference steps (measured ~0.4 % of the distance at p90, 1.6 % worst)
    rng = np.random.default_rng(3)
    amp = np.radians(rng.uniform(0, 85, (64, 2)))
    bias = np.pi / 2 + rng.uniform(-1, 1, (64, 2)) * (np.pi / 2 - amp)
    beats = np.stack([bias, amp, rng.uniform(0.2, 5, (64, 2)), rng.uniform(0.2, 10, (64, 2))], axis=-1)
    end = {}
    for name in ("reference", "fast"):
        model = FullModel(64, integration=name)
        model.reset()
        model.command_array(beats)
        model.advance(4.0)
        model.command_array(np.ascontiguousarray(beats[:, ::-1]))
        end[name] = model.advance(4.0)[:, :2].copy()
    assert np.all(np.isfinite(end["fast"]))
    distance = np.maximum(np.linalg.norm(end["reference"], axis=1), 0.05)
    assert np.max(np.linalg.norm(end["fast"] - end["reference"], axis=1) / distance) < 0.05


def test_full_model_from_moving_initial_state_matches_ode():
    y0 = np.array([0.2, -0.1, 0.4, 0.05, -0.01, 0.3])
    ref = reference_full(TURN, FORWARD, 2.0, y0)
    got = run(FullModel(1, dt_max=0.00125, min_substeps=128), 2.0, state=y0, right=TURN, left=FORWARD)[0]
    np.testing.assert_allclose(got, ref, rtol=0, atol=5e-8)


@pytest.mark.parametrize("right,left", [(TURN, FinBeat.rest()), (FORWARD, FinBeat.from_degrees(70, 25, 0.7, 2.0))])
def test_averaged_model_matches_independent_ode_solution(right, left):
    ref = reference_averaged(right, left, 5.0)
    got = run(AveragedModel(1, scaling=None, dt_max=0.005, ripple_offsets=False), 5.0, right=right, left=left)[0]
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)


def test_averaged_model_with_scaling_scales_forcing():
    k = {"K_fx": 0.8, "K_fy": 1.3, "K_m": 0.45}
    s = ScalingFunctions.from_dict({"format": FORMAT, "features": list(FEATURES[:5]),
                                    "functions": {n: [{"coef": v, "powers": [0] * 5}] for n, v in k.items()}})
    f = (closed_form_average(FORWARD, 1.0) * np.array([k["K_fx"], k["K_fy"], k["K_m"]]))
    ref = solve_ivp(lambda t, y: eq19(y, f), (0, 4.0), np.zeros(6), method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
    got = run(AveragedModel(1, scaling=s, dt_max=0.005, ripple_offsets=False), 4.0, right=FORWARD)[0]
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- turning directions, symmetry

MODELS = [lambda n=1: FullModel(n), lambda n=1: AveragedModel(n, scaling=None)]
MODEL_IDS = ["full", "averaged"]


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_right_fin_alone_turns_left(make):
    m = make()
    m.reset(right=TURN)
    m.advance(40.0)
    vx, vy, om = cycle_average(m, 1.0)[0]
    assert om > 0.02
    assert vx > 0.01
    assert vy < -0.001  # outward skid, see module docstring
    assert m.state[0, 2] > 2.0  # heading has turned counter-clockwise


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_left_fin_alone_turns_right(make):
    m = make()
    m.reset(left=TURN)
    m.advance(40.0)
    vx, vy, om = cycle_average(m, 1.0)[0]
    assert om < -0.02
    assert vx > 0.01
    assert vy > 0.001
    assert m.state[0, 2] < -2.0


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
@pytest.mark.parametrize("beat", [TURN, FORWARD, FinBeat.from_degrees(60, 30, 0.5, 0.5)])
def test_equal_patterns_swim_straight(make, beat):
    m = make()
    m.reset(right=beat, left=beat)
    for _ in range(30):
        m.advance(0.37)
        assert abs(m.state[0, 4]) < 1e-12  # vy
        assert abs(m.state[0, 5]) < 1e-12  # omega
        assert abs(m.state[0, 1]) < 1e-12 and abs(m.state[0, 2]) < 1e-12  # Y, psi
    assert abs(m.state[0, 3]) > 1e-3


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
@pytest.mark.parametrize("beat", [TURN, FORWARD, FinBeat.from_degrees(130, 40, 2.0, 3.0)])
def test_mirror_symmetry(make, beat):
    right = run(make(), 17.3, right=beat)[0]
    left = run(make(), 17.3, left=beat)[0]
    mirror = np.array([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])  # X, Y, psi, vx, vy, omega
    np.testing.assert_allclose(left, mirror * right, rtol=1e-12, atol=1e-15)
    assert abs(right[5]) > 1e-3


def test_mirror_symmetry_two_fins_swapped():
    other = FinBeat.from_degrees(70, 25, 0.7, 2.0)
    a = run(FullModel(1), 9.1, right=FORWARD, left=other)[0]
    b = run(FullModel(1), 9.1, right=other, left=FORWARD)[0]
    np.testing.assert_allclose(b, a * np.array([1, -1, -1, 1, -1, -1]), rtol=1e-12, atol=1e-15)


# --------------------------------------------------------------------------- batching

BATCH = [
    (TURN, None),
    (None, FORWARD),
    (FORWARD, FORWARD),
    (FinBeat.from_degrees(130, 40, 2.0, 3.0), FinBeat.from_degrees(60, 30, 0.5, 0.5)),
    (FinBeat.from_degrees(95, 12, 0.66, 5.0), TURN),
]


def _beats_array(pairs):
    rest = FinBeat.rest().as_array()
    return (np.array([(r or FinBeat.rest()).as_array() for r, _ in pairs]),
            np.array([(lf.as_array() if lf else rest) for _, lf in pairs]))


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_batch_equals_each_fish_alone(make):
    right, left = _beats_array(BATCH)
    batch = make(len(BATCH))
    batch.reset(right=right, left=left)
    for _ in range(4):
        batch.advance(1.3)
    for i, (r, lf) in enumerate(BATCH):
        one = make()
        one.reset(right=r, left=lf)
        for _ in range(4):
            one.advance(1.3)
        np.testing.assert_array_equal(batch.state[i], one.state[0])
        np.testing.assert_array_equal(batch.integral[i], one.integral[0])


def test_large_batch_parallel_path_equals_each_alone():
    n = 70  # above the parallel threshold
    rng = np.random.default_rng(3)
    bias = rng.uniform(math.radians(60), math.radians(120), (n, 2))
    amp = rng.uniform(0.0, math.radians(25), (n, 2))
    period = rng.choice([0.5, 0.8, 1.0], (n, 2))
    ratio = rng.choice([0.5, 2.0, 4.0], (n, 2))
    beats = np.stack([bias, amp, period, ratio], axis=-1)
    batch = FullModel(n)
    batch.reset(right=beats[:, 0], left=beats[:, 1])
    batch.advance(2.0)
    for i in (0, 17, 69):
        one = FullModel(1)
        one.reset(right=beats[i, 0], left=beats[i, 1])
        one.advance(2.0)
        np.testing.assert_allclose(batch.state[i], one.state[0], rtol=1e-13, atol=1e-16)


def test_batch_with_per_fish_params():
    heavy = P.replace(body_mass=1.5, drag_coef=0.6)
    batch = FullModel(2, params=[P, heavy])
    batch.reset(right=TURN, left=FORWARD)
    batch.advance(3.0)
    alone = FullModel(1, params=heavy)
    alone.reset(right=TURN, left=FORWARD)
    alone.advance(3.0)
    np.testing.assert_array_equal(batch.state[1], alone.state[0])
    assert not np.allclose(batch.state[0], batch.state[1])


def test_reset_index_only_resets_selected_fish():
    m = FullModel(3)
    m.reset(right=TURN, left=TURN)
    m.advance(2.0)
    before = m.state.copy()
    m.reset(right=TURN, left=TURN, index=np.array([1]))
    np.testing.assert_array_equal(m.state[[0, 2]], before[[0, 2]])
    np.testing.assert_array_equal(m.state[1], 0.0)


# --------------------------------------------------------------------------- dissipation and kinematics


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_coast_down_straight_closed_form(make):
    v0, psi0 = 0.12, 0.7
    m = make()
    m.dt_max = 0.005  # fine steps, so the closed form is matched to 1e-7
    m.reset(state=np.array([0.3, -0.2, psi0, v0, 0.0, 0.0]))
    for t in np.arange(1, 21) * 0.5:
        m.advance(0.5)
        x, y, psi, vx, vy, om = m.state[0]
        assert vx == pytest.approx(v0 / (1 + C1 * v0 * t / M1), rel=1e-7)
        dist = M1 / C1 * math.log(1 + C1 * v0 * t / M1)
        assert x == pytest.approx(0.3 + dist * math.cos(psi0), rel=1e-7)
        assert y == pytest.approx(-0.2 + dist * math.sin(psi0), rel=1e-7)
        assert psi == psi0 and vy == 0.0 and om == 0.0


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_speed_and_energy_decay_with_fins_at_rest(make):
    m = make()
    m.reset(state=np.array([0.0, 0.0, 0.0, 0.1, -0.04, 0.8]))
    dt = 0.002
    energy, dissipation = [], []
    for _ in range(1500):
        _, _, _, vx, vy, om = m.state[0]
        energy.append(0.5 * (M1 * vx**2 + M2 * vy**2 + J3 * om**2))
        dissipation.append(C1 * math.hypot(vx, vy) ** 3 + CM * abs(om) ** 3)
        m.advance(dt)
    energy, dissipation = np.array(energy), np.array(dissipation)
    assert np.all(np.diff(energy) < 0)
    # energy balance: E(t) - E(0) = -integral of the dissipation (trapezoid, O(dt^2))
    lost = np.concatenate([[0.0], np.cumsum(0.5 * (dissipation[1:] + dissipation[:-1]) * dt)])
    np.testing.assert_allclose(energy[0] - energy, lost, rtol=0, atol=1e-4 * energy[0])
    assert energy[-1] < 0.3 * energy[0]


def test_speed_decays_monotonically_straight():
    m = FullModel(1)
    m.reset(state=np.array([0, 0, 0, 0.2, 0, 0]))
    speeds = []
    for _ in range(200):
        m.advance(0.05)
        speeds.append(math.hypot(m.state[0, 3], m.state[0, 4]))
    assert np.all(np.diff(speeds) < 0) and speeds[-1] > 0


def test_position_integrates_body_velocity_in_heading_direction():
    # omega = 0, no fin forcing, vx only: the fish moves along its heading by the integral of vx.
    m = AveragedModel(1, scaling=None)
    psi0 = -2.0
    m.reset(state=np.array([0.0, 0.0, psi0, 0.08, 0.0, 0.0]))
    m.advance(6.0)
    travelled = m.integral[0, 0]  # integral of vx
    np.testing.assert_allclose(m.state[0, :2], travelled * np.array([math.cos(psi0), math.sin(psi0)]), rtol=1e-9)


# --------------------------------------------------------------------------- averaged vs full


@pytest.mark.parametrize("beat", [TURN, FinBeat.from_degrees(80, 22, 1.0, 3.0)])
def test_averaged_with_unit_k_turns_about_twice_as_fast(beat):
    # Notes: the yaw dynamics are fast against the fin beat, so plain averaging (K = 1) overpredicts the turn
    # rate, roughly by a factor two.
    full, avg = FullModel(1), AveragedModel(1, scaling=None)
    full.reset(right=beat)
    avg.reset(right=beat)
    full.advance(45.0)
    avg.advance(45.0)
    om_full = cycle_average(full, beat.period)[0, 2]
    om_avg = cycle_average(avg, beat.period)[0, 2]
    assert om_full > 0 and om_avg > 0
    assert 1.5 < om_avg / om_full < 3.0


def test_averaged_and_full_share_parameter_change_schedule():
    p1, p2 = TURN, FORWARD
    full, avg = FullModel(1), AveragedModel(1, scaling=None)
    for m in (full, avg):
        m.reset(right=p1, left=p1)
        m.advance(0.1)
        m.command(right=p2, left=p1)
    for _ in range(40):
        full.advance(0.031)
        avg.advance(0.031)
        np.testing.assert_array_equal(full.active_beats(), avg.active_beats())
        np.testing.assert_array_equal(full.fin_angles()[0], avg.fin_angles()[0])


def test_averaged_forcing_switches_at_turning_point():
    # Averaged model from rest: until the right fin's turning point at 0.2 s it is driven by P1's average,
    # then by P2's. Compare with the reference ODE driven by piecewise-constant closed-form forcing.
    # (Without the transitional-stroke forcing and the ripple offset, which tests/test_fidelity.py and
    # tests/test_ripple_offset.py check against the full model.)
    p1, p2 = TURN, FORWARD
    m = AveragedModel(1, scaling=None, dt_max=0.002, transitions=False, ripple_offsets=False)
    m.reset(right=p1)
    m.advance(0.1)
    m.command(right=p2)
    m.advance(1.9)
    f1, f2 = closed_form_average(p1, 1.0), closed_form_average(p2, 1.0)
    y = solve_ivp(lambda t, s: eq19(s, f1), (0, 0.2), np.zeros(6), method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
    y = solve_ivp(lambda t, s: eq19(s, f2), (0.2, 2.0), y, method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
    np.testing.assert_allclose(m.state[0], y, rtol=0, atol=1e-9)


def test_averaged_default_scaling_is_the_shipped_file():
    m = AveragedModel(1)
    assert not m.scaling.is_unit
    a = run(m, 5.0, right=TURN)
    b = run(AveragedModel(1, scaling=ScalingFunctions.load()), 5.0, right=TURN)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, run(AveragedModel(1, scaling="none"), 5.0, right=TURN))


def test_taylor_forcing_option_changes_side_force():
    beat = FinBeat.from_degrees(90, 20, 1.0, 4.0)
    exact = run(AveragedModel(1, scaling=None, forcing="exact"), 5.0, right=beat, left=beat)[0]
    taylor = run(AveragedModel(1, scaling=None, forcing="taylor"), 5.0, right=beat, left=beat)[0]
    assert abs(exact[3] - taylor[3]) > 1e-4  # the Taylor forms are far off at 90 deg bias


# --------------------------------------------------------------------------- argument validation


@pytest.mark.parametrize("kwargs,match", [({"n": 0}, "n"), ({"dt_max": 0.0}, "dt_max"), ({"dt_max": -1.0}, "dt_max"),
                                          ({"min_substeps": 0}, "min_substeps"),
                                          ({"integration": "rk45"}, "integration")])
def test_full_model_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        FullModel(**kwargs)


@pytest.mark.parametrize("kwargs,match", [({"forcing": "fourier"}, "forcing"), ({"scaling": "paper"}, "scaling")])
def test_averaged_model_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        AveragedModel(**kwargs)


def test_negative_duration_rejected():
    with pytest.raises(ValueError, match="duration"):
        FullModel().advance(-0.1)


@pytest.mark.parametrize("beat,field", [((1.0, -0.1, 1.0, 4.0), "amplitude"), ((1.0, 0.1, 0.0, 4.0), "period"),
                                        ((1.0, 0.1, 1.0, -4.0), "ratio"), ((0.1, 0.3, 1.0, 4.0), "bias"),
                                        ((math.nan, 0.1, 1.0, 4.0), "bias"), ((1.0, 0.1, math.inf, 4.0), "period")])
def test_command_validates_patterns(beat, field):
    m = FullModel(2)
    with pytest.raises(ValueError, match=field):
        m.command(right=np.array([TURN.as_array(), beat]))
    with pytest.raises(ValueError, match=field):
        m.reset(left=np.array(beat))


def test_command_array_shape_checked():
    with pytest.raises(ValueError, match="shape"):
        FullModel(2).command_array(np.zeros((1, 2, 4)))


def test_params_count_must_match_fish():
    with pytest.raises(ValueError, match="FishParams"):
        FullModel(3, params=[P, P])
