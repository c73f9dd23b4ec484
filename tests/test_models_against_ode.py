"""FullModel and AveragedModel against an independent solution of their ODEs, and the averaged model against the full.

The reference (``tests/model_reference.py``): eqs. (19)-(21) typed in and solved by ``scipy.integrate.solve_ivp``
(DOP853, tight tolerances, restarted at every stroke boundary), the averaged forcing in closed form. Checked: the
full model's reference and fast integration presets, high-order convergence, huge steps, a moving start; the
averaged model with and without K; the averaged model's switch of pattern at the turning point, its turn rate
with K = 1, the shipped K as its default and the Taylor forcing option.
"""


import numpy as np
import pytest
from model_reference import (
    FORWARD,
    TURN,
    closed_form_average,
    cycle_average,
    eq19,
    reference_averaged,
    reference_full,
    run,
)
from scipy.integrate import solve_ivp

from pectoral_gym import AveragedModel, FinBeat, FullModel, ScalingFunctions
from pectoral_gym.model.kfunctions import FEATURES, FORMAT

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
