import json
import math
import subprocess
import sys

import numpy as np
import pytest

from pectoral_gym.model.dynamics import linearised_rate
from pectoral_gym.model.kfunctions import FEATURES, ScalingFunctions
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.params import FishParams, body_coefficients
from pectoral_gym.model.steady import steady_state_batch
from pectoral_gym.scaling.identification.grids import GRIDS, Grid, GridError, load_grid
from pectoral_gym.scaling.identification.identify import holdout_patterns, identify
from pectoral_gym.scaling.identification.nmpc import (
    RK4_STEP_RATE,
    IdentificationNmpcSettings,
    ScalingNmpc,
    algebraic_scaling,
    auto_substeps,
    unscaled_forcing,
)
from pectoral_gym.scaling.identification.reference import reference_runs, velocities_from_turning
from pectoral_gym.scaling.identification.regression import feature_matrix, fit_polynomial, fit_spline, select_model
from pectoral_gym.scaling.identification.response import predicted_turning

PARAMS = FishParams()
FAST = IdentificationNmpcSettings(horizon=3.0, sampling=1.0)  # the paper's weights, a shorter horizon for speed


@pytest.fixture(scope="module")
def small():
    grid = Grid.product("small", bias_deg=(60, 90), amplitude_deg=(15, 25), period_s=(1.0,), ratio=(3,))
    ref = reference_runs(grid.patterns, PARAMS, progress=False)
    return grid, ref


def test_presets_have_the_documented_sizes_and_ranges():
    assert len(GRIDS["paper"]) == 7 * 5 * 4 * 4 == 560
    low, high = GRIDS["env"].bounds()
    # The env grid covers the environments' default action ranges (bias 45-135 deg, amplitude <= 30 deg, period 0.5-2 s)
    assert low[0] <= math.radians(45) and high[0] >= math.radians(135)
    assert high[1] >= math.radians(30) and low[2] <= 0.5 and high[2] >= 2.0 and high[3] >= 5


def test_grid_file_errors_are_clear(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(GridError, match="cannot read grid file"):
        load_grid(bad)
    bad.write_text(json.dumps({"bias_deg": [90], "amplitude_deg": [10]}))
    with pytest.raises(GridError, match="missing keys"):
        load_grid(bad)
    bad.write_text(json.dumps({"patterns": [[10, 20, 1.0, 3]]}))  # bias - amplitude < 0
    with pytest.raises(GridError, match="pattern 0"):
        load_grid(bad)
    with pytest.raises(GridError, match="not a preset"):
        load_grid("no-such-grid")
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"patterns": [[90, 22, 1.0, 4]]}))
    assert load_grid(good).contains((math.radians(90), math.radians(22), 1.0, 4.0))


def test_eq29_velocities_round_trip():
    v = velocities_from_turning(radius=0.4, turn_period=50.0, drift_angle=-0.2, turn_sign=1.0)
    omega = 2 * math.pi / 50.0
    assert v[2] == pytest.approx(omega)
    assert math.hypot(v[0], v[1]) / omega == pytest.approx(0.4)
    assert math.atan(v[1] / v[0]) == pytest.approx(-0.2)


def test_nmpc_equals_algebraic_solution(small):
    grid, ref = small
    forcing = unscaled_forcing(grid.patterns, PARAMS, sway="base")
    oracle = algebraic_scaling(ref.velocities, forcing, PARAMS)
    nmpc = ScalingNmpc(PARAMS, FAST, ref.velocities)
    for i in range(len(grid)):
        r = nmpc.solve(ref.velocities[i], forcing[i])
        assert r.success
        # With the "base" sway term every K is identifiable, also at 90 deg bias.
        np.testing.assert_allclose(r.k, oracle[i], rtol=1e-3)


def test_base_sway_forcing_is_the_force_magnitude():
    # Closed form (paper-notes): fx = base sin(bias), fy = base cos(bias); "base" replaces fy by base itself.
    patterns = np.radians([[60.0, 20.0, 0.0, 0.0], [90.0, 25.0, 0.0, 0.0]]) + [0, 0, 1.3, 3.0]
    paper = unscaled_forcing(patterns, PARAMS)
    base = unscaled_forcing(patterns, PARAMS, sway="base")
    np.testing.assert_allclose(base[:, 1], np.hypot(paper[:, 0], paper[:, 1]), rtol=1e-12)
    np.testing.assert_allclose(base[:, [0, 2]], paper[:, [0, 2]], rtol=0)
    with pytest.raises(ValueError, match="sway"):
        unscaled_forcing(patterns, PARAMS, sway="cos")


def test_identified_k_makes_the_averaged_model_reproduce_the_full_model(small):
    # The point of the identification: with a pattern's own K, the averaged model's steady state
    # is the full model's (to the steady-state tolerance), which K = 1 misses by about 2x in omega.
    grid, ref = small
    forcing = unscaled_forcing(grid.patterns, PARAMS, sway="base")
    oracle = algebraic_scaling(ref.velocities, forcing, PARAMS)
    for i in (0, 2):  # bias 60 deg and 90 deg (the paper's K_fy would be infinite there)
        k = ScalingFunctions(np.zeros((3, 1, len(FEATURES))), oracle[i].reshape(3, 1), {}, sway="base")
        beats = np.array([[grid.patterns[i], [math.pi / 2, 0.0, 1.0, 1.0]]])
        averaged = steady_state_batch(AveragedModel(1, PARAMS, scaling=k), beats)[0]
        np.testing.assert_allclose([averaged.vx, averaged.vy, averaged.omega], ref.velocities[i], rtol=1e-4)
        unit = steady_state_batch(AveragedModel(1, PARAMS, scaling="none"), beats)[0]
        assert unit.omega > 1.5 * ref.velocities[i, 2]


def test_k_does_not_depend_on_the_period(small):
    # Time-scale symmetry of eqs. (9)-(20): fin forces ~ 1/T^2 and drag ~ v^2, so v ~ 1/T and K is T-free.
    grid, _ = small
    patterns = np.array([grid.patterns[0], grid.patterns[0] * [1, 1, 2.5, 1]])
    ref = reference_runs(patterns, PARAMS, progress=False)
    k = algebraic_scaling(ref.velocities, unscaled_forcing(patterns, PARAMS), PARAMS)
    np.testing.assert_allclose(ref.velocities[1], ref.velocities[0] / 2.5, rtol=1e-5)
    np.testing.assert_allclose(k[1], k[0], rtol=1e-4)


def test_regression_recovers_a_known_polynomial():
    rng = np.random.default_rng(3)
    patterns = np.column_stack([rng.uniform(0.8, 2.3, 200), rng.uniform(0.05, 0.5, 200),
                                rng.uniform(0.5, 2.0, 200), rng.uniform(1.2, 5.0, 200)])
    b, a, _, z = patterns.T
    values = 0.5 + 0.3 * b - 2.0 * a * a + 0.1 * z * b
    fit, candidates = select_model(patterns, values, max_degree=4, target=1e-9)
    assert fit.degree == 2 and fit.features == "bias, amplitude, ratio"
    assert fit.cv_rmse < 1e-10 and fit.r2 == pytest.approx(1.0)
    assert np.allclose(fit.predict(patterns), values, atol=1e-10)
    assert len(candidates) > 3
    # Degree 1 cannot fit it: the choice is not the simplest candidate by accident.
    assert fit_polynomial(patterns, values, degree=1).cv_rmse > 1e-3
    assert feature_matrix(patterns)[:, 4] == pytest.approx(1 / patterns[:, 2])


def test_pipeline_flags_degenerate_and_failed_patterns_and_round_trips(tmp_path):
    # Amplitude 0: no forcing at all, every K unidentifiable; the sway K is identifiable at 90 deg.
    grid = Grid.product("degenerate", bias_deg=(60, 90), amplitude_deg=(0, 15, 25), period_s=(1.0,), ratio=(3,))
    result = identify(grid, PARAMS, FAST, max_degree=1, folds=2, jobs=1, progress=False, holdout=0,
                      yaw_damping="paper")  # 3 amplitudes: too few nodes for the yaw-oscillation spline
    assert not result.scaling.has_oscillation
    still = [i for i, p in enumerate(grid.patterns) if p[1] == 0]
    assert len(still) == 2
    for j, name in enumerate(("K_fx", "K_fy", "K_m")):
        reasons = {f["pattern"]: f["reason"] for f in result.flags if f["K"] == name}
        assert set(reasons) == set(still) and all("no forcing" in r for r in reasons.values())
        assert result.usable[[i for i in range(len(grid)) if i not in still], j].all()
    assert result.chosen == "polynomial" and "unavailable" in result.scaling.metadata["regression"]["spline"]
    path = tmp_path / "k.json"
    result.scaling.save(path)
    loaded = ScalingFunctions.load(path)
    np.testing.assert_array_equal(loaded.coefs, result.scaling.coefs[:, : loaded.coefs.shape[1]])
    p = grid.patterns[0]
    assert loaded.evaluate(*p) == pytest.approx(result.scaling.evaluate(*p))
    assert loaded.metadata["grid"]["size"] == len(grid)


def test_auto_substeps_keep_rk4_stable_and_the_solution_does_not_depend_on_them(small):
    grid, ref = small
    b = body_coefficients(PARAMS)
    rate = max(linearised_rate(math.hypot(vx, vy), abs(w), 0.0, b.m1, b.m2, b.J3, b.c1, b.c2, b.c4)
               for vx, vy, w in ref.velocities)
    substeps = auto_substeps(ref.velocities, PARAMS, FAST.sampling)
    step = FAST.sampling / substeps
    assert step * rate <= RK4_STEP_RATE < 2.785  # inside RK4's real stability interval
    assert substeps == 4 or (FAST.sampling / (substeps - 1)) * rate > RK4_STEP_RATE  # the fewest that do
    # The optimum (constant K making v_ref an equilibrium) is an equilibrium of any RK4 step: three times
    # the substeps give the same K, and both the algebraic solution.
    forcing = unscaled_forcing(grid.patterns, PARAMS, sway="base")
    oracle = algebraic_scaling(ref.velocities, forcing, PARAMS)
    fine = ScalingNmpc(PARAMS, IdentificationNmpcSettings(horizon=3.0, substeps=3 * substeps), ref.velocities)
    coarse = ScalingNmpc(PARAMS, FAST, ref.velocities)
    assert coarse.substeps == substeps
    for i in range(len(grid)):
        k_coarse, k_fine = coarse.solve(ref.velocities[i], forcing[i]).k, fine.solve(ref.velocities[i], forcing[i]).k
        np.testing.assert_allclose(k_coarse, oracle[i], rtol=1e-9)
        np.testing.assert_allclose(k_fine, oracle[i], rtol=1e-9)


def test_solver_failure_is_recorded_not_raised(small):
    grid, ref = small
    forcing = unscaled_forcing(grid.patterns, PARAMS)
    nmpc = ScalingNmpc(PARAMS, IdentificationNmpcSettings(horizon=3.0, max_iter=1), ref.velocities)
    r = nmpc.solve(ref.velocities[0], forcing[0], guess=np.array([5.0, -3.0, 9.0]))
    assert not r.success and r.status


def test_cli_identify_small_grid(tmp_path):
    grid = tmp_path / "grid.json"
    grid.write_text(json.dumps({"bias_deg": [60, 75], "amplitude_deg": [15, 25], "period_s": [1.0],
                                "ratio": [2, 4]}))
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "pectoral_gym.scaling", "identify", "--grid", str(grid),
                          "--out", str(out), "--horizon", "3", "--jobs", "1", "--folds", "2", "--max-degree", "1",
                          "--no-progress", "--yaw-damping", "paper"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "stage times" in run.stdout
    k = ScalingFunctions.load(out / "scaling_coefficients.json")
    assert k.metadata["status"] == "identified" and len(k.metadata["data"]["rows"]) == 8
    bad = subprocess.run([sys.executable, "-m", "pectoral_gym.scaling", "identify", "--grid", "nope"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "unknown grid" in bad.stderr


# --------------------------------------------------------------------------- splines and the held-out choice


def _tensor_patterns(bias_deg, amplitude_deg, ratios, periods=(1.0,)):
    b, a, t, z = np.meshgrid(np.radians(bias_deg), np.radians(amplitude_deg), periods, ratios, indexing="ij")
    return np.column_stack([b.ravel(), a.ravel(), t.ravel(), z.ravel()])


def _cubic(p):
    # a cubic polynomial in (bias, amplitude, 1/ratio): a not-a-knot cubic spline reproduces it exactly
    b, a, r = p[:, 0], p[:, 1], 1.0 / p[:, 3]
    return 0.7 + 0.2 * b**3 - 1.5 * b * a**2 + 0.8 * r**3 * a - 0.3 * b * a * r


def test_spline_reproduces_a_cubic_off_the_nodes_and_averages_periods():
    grid = _tensor_patterns((45, 60, 80, 100, 135), (5, 10, 20, 30), (1.25, 2, 3, 5), periods=(0.5, 2.0))
    values = _cubic(grid)
    values[grid[:, 2] == 2.0] += 1e-3  # the two periods disagree by 1e-3: averaged, and reported
    fit = fit_spline(grid, values)
    rng = np.random.default_rng(0)
    off = np.column_stack([rng.uniform(np.radians(45), np.radians(135), 40), rng.uniform(np.radians(5),
                           np.radians(30), 40), np.ones(40), rng.uniform(1.25, 5, 40)])
    np.testing.assert_allclose(fit.predict(off), _cubic(off) + 5e-4, atol=1e-10)
    assert fit.period_spread == pytest.approx(1e-3) and fit.filled == 0
    assert fit.summary()["nodes"] == [5, 4, 4]


def test_spline_fit_errors_and_fill():
    grid = _tensor_patterns((45, 60, 80, 100), (5, 10, 20, 30), (1.25, 2, 3, 5))
    with pytest.raises(ValueError, match=">= 4 distinct"):
        fit_spline(grid[grid[:, 0] < 1.6], _cubic(grid[grid[:, 0] < 1.6]))
    with pytest.raises(ValueError, match="not a full tensor product"):
        fit_spline(grid[1:], _cubic(grid[1:]))
    usable = np.ones(len(grid), dtype=bool)
    usable[5] = False
    with pytest.raises(ValueError, match="no usable value"):
        fit_spline(grid, _cubic(grid), usable)
    fit = fit_spline(grid, _cubic(grid), usable, fill=_cubic)  # the filled node takes the fill's value
    assert fit.filled == 1
    np.testing.assert_allclose(fit.predict(grid), _cubic(grid), atol=1e-10)


def test_predicted_turning_with_the_exact_k_is_the_full_models_turn(small):
    # The oracle K makes the full model's mean velocities an equilibrium of the averaged model (eq. 20),
    # so the root solve must return the full model's radius and period (eq. 29).
    grid, ref = small
    forcing = unscaled_forcing(grid.patterns, PARAMS, sway="base")
    k = algebraic_scaling(ref.velocities, forcing, PARAMS)
    turn = predicted_turning(ref.velocities, forcing, k, PARAMS)
    np.testing.assert_allclose(turn, np.column_stack([ref.radius, ref.turn_period]), rtol=1e-6)
    off = predicted_turning(ref.velocities, forcing, k * [1.0, 1.0, 1.1], PARAMS)  # 10 % more yaw moment
    assert np.all(off[:, 0] < ref.radius)


def test_holdout_patterns_are_seeded_inside_the_box_and_off_the_grid():
    grid = GRIDS["paper"]
    a, b = holdout_patterns(grid, 20, seed=3), holdout_patterns(grid, 20, seed=3)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, holdout_patterns(grid, 20, seed=4))
    low, high = grid.bounds()
    assert np.all(a >= low - 1e-12) and np.all(a <= high + 1e-12)
    assert not any(grid.contains(p, tol=1e-6) for p in a)
    assert set(np.unique(a[:, 2])) <= set(np.unique(grid.patterns[:, 2]))


def test_pipeline_chooses_the_spline_when_polynomials_miss_the_turning_target(tmp_path):
    grid = Grid.product("tensor", bias_deg=(50, 70, 90, 110), amplitude_deg=(10, 17, 24, 30), period_s=(1.0,),
                        ratio=(1.5, 2.5, 3.5, 5))
    result = identify(grid, PARAMS, FAST, max_degree=1, folds=2, jobs=1, progress=False, holdout=12)
    comparison = result.comparison
    assert set(comparison) == {"polynomial", "spline"}
    assert comparison["spline"]["radius_worst"] < comparison["polynomial"]["radius_worst"]
    assert result.chosen == "spline" and result.scaling.has_spline and result.scaling.sway == "base"
    path = tmp_path / "k.json"
    result.scaling.save(path)
    loaded = ScalingFunctions.load(path)
    for p in grid.patterns[::7]:  # the spline interpolates the NMPC values at the nodes
        i = int(np.flatnonzero(np.all(grid.patterns == p, axis=1))[0])
        np.testing.assert_allclose(loaded.evaluate(*p), result.k_nmpc[i], rtol=1e-8, atol=1e-10)
    # The averaged model's oscillation-averaged yaw damping: the file interpolates each node's measured
    # yaw oscillation (amplitude and phase of the full model's steady in-beat yaw rate).
    assert loaded.has_oscillation and result.scaling.metadata["yaw_damping"].startswith("oscillation")
    ref = result.reference
    for i in range(0, len(grid), 5):
        amplitude, phase = loaded.yaw_oscillation(*grid.patterns[i])
        assert amplitude == pytest.approx(ref.yaw_oscillation[i], rel=1e-8)
        assert phase == pytest.approx(ref.yaw_phase[i], abs=1e-8)


def test_oscillation_damping_needs_a_tensor_grid_and_a_known_mode():
    grid = Grid.product("tiny", bias_deg=(60, 90), amplitude_deg=(15, 25), period_s=(1.0,), ratio=(3,))
    with pytest.raises(ValueError, match="needs a tensor grid.*--yaw-damping paper"):
        identify(grid, PARAMS, FAST, jobs=1, progress=False, holdout=0)
    with pytest.raises(ValueError, match="yaw_damping"):
        identify(grid, PARAMS, FAST, jobs=1, progress=False, holdout=0, yaw_damping="linear")
