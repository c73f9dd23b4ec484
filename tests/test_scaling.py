import json
import math
import subprocess
import sys

import numpy as np
import pytest

from pectoral_gym.kfunctions import FEATURES, ScalingFunctions
from pectoral_gym.models import AveragedModel
from pectoral_gym.params import FishParams
from pectoral_gym.steady import steady_state_batch
from scaling.grids import GRIDS, Grid, GridError, load_grid
from scaling.identify import identify
from scaling.nmpc import NmpcSettings, ScalingNmpc, algebraic_scaling, unscaled_forcing
from scaling.reference import reference_runs, velocities_from_turning
from scaling.regression import feature_matrix, fit_polynomial, select_model

PARAMS = FishParams()
FAST = NmpcSettings(horizon=3.0, sampling=1.0)  # the paper's weights, a shorter horizon for speed


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
    forcing = unscaled_forcing(grid.patterns, PARAMS)
    oracle = algebraic_scaling(ref.velocities, forcing, PARAMS)
    nmpc = ScalingNmpc(PARAMS, FAST, ref.velocities)
    for i in range(len(grid)):
        r = nmpc.solve(ref.velocities[i], forcing[i])
        assert r.success
        for j in range(3):
            if abs(forcing[i, j]) > 1e-3 * abs(forcing[i, 0]):  # the sway forcing vanishes at 90 deg bias
                assert r.k[j] == pytest.approx(oracle[i, j], rel=1e-3)


def test_identified_k_makes_the_averaged_model_reproduce_the_full_model(small):
    # The point of the identification: with a pattern's own K, the averaged model's steady state
    # is the full model's (to the steady-state tolerance), which K = 1 misses by about 2x in omega.
    grid, ref = small
    forcing = unscaled_forcing(grid.patterns, PARAMS)
    oracle = algebraic_scaling(ref.velocities, forcing, PARAMS)
    i = 0  # bias 60 deg: every forcing term is identifiable
    k = ScalingFunctions(np.zeros((3, 1, len(FEATURES))), oracle[i].reshape(3, 1), {})
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


def test_pipeline_flags_degenerate_and_failed_patterns_and_round_trips(small, tmp_path):
    grid, _ = small
    result = identify(grid, PARAMS, FAST, max_degree=1, folds=2, jobs=1, progress=False)
    at_90 = [i for i, p in enumerate(grid.patterns) if abs(p[0] - math.pi / 2) < 1e-12]
    sway = {f["pattern"]: f["reason"] for f in result.flags if f["K"] == "K_fy"}
    assert set(sway) == set(at_90) and all("sway forcing" in r for r in sway.values())
    assert result.usable[:, 0].all() and result.usable[:, 2].all()
    path = tmp_path / "k.json"
    result.scaling.save(path)
    loaded = ScalingFunctions.load(path)
    np.testing.assert_array_equal(loaded.coefs, result.scaling.coefs[:, : loaded.coefs.shape[1]])
    p = grid.patterns[0]
    assert loaded.evaluate(*p) == pytest.approx(result.scaling.evaluate(*p))
    assert loaded.metadata["grid"]["size"] == len(grid)


def test_solver_failure_is_recorded_not_raised(small):
    grid, ref = small
    forcing = unscaled_forcing(grid.patterns, PARAMS)
    nmpc = ScalingNmpc(PARAMS, NmpcSettings(horizon=3.0, max_iter=1), ref.velocities)
    r = nmpc.solve(ref.velocities[0], forcing[0], guess=np.array([5.0, -3.0, 9.0]))
    assert not r.success and r.status


def test_cli_identify_small_grid(tmp_path):
    grid = tmp_path / "grid.json"
    grid.write_text(json.dumps({"bias_deg": [60, 75], "amplitude_deg": [15, 25], "period_s": [1.0],
                                "ratio": [2, 4]}))
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "scaling", "identify", "--grid", str(grid), "--out", str(out),
                          "--horizon", "3", "--jobs", "1", "--folds", "2", "--max-degree", "1", "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "stage times" in run.stdout
    k = ScalingFunctions.load(out / "scaling_coefficients.json")
    assert k.metadata["status"] == "identified" and len(k.metadata["data"]["rows"]) == 8
    bad = subprocess.run([sys.executable, "-m", "scaling", "identify", "--grid", "nope"], capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 2 and "unknown grid" in bad.stderr
