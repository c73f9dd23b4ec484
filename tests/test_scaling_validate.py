"""Tests of the averaged-model validation.

pectoral_gym.scaling.validation.validate and pectoral_gym.scaling.validation.plots.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from pectoral_gym.model.averaging import averaged_forcing
from pectoral_gym.model.dynamics import body_rhs
from pectoral_gym.model.kfunctions import FEATURES, ScalingFunctions
from pectoral_gym.model.params import FinBeat, FishParams, coefficient_vector
from pectoral_gym.model.steady import steady_state
from pectoral_gym.scaling.identification.grids import GRIDS, draw_off_grid
from pectoral_gym.scaling.validation import comparison as sc
from pectoral_gym.scaling.validation import pattern_sets as ps
from pectoral_gym.scaling.validation import validate as sv
from pectoral_gym.scaling.validation.plots import identification_points

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def constant_k(k_fx: float, k_fy: float, k_m: float, metadata: dict | None = None) -> ScalingFunctions:
    """Scaling functions that are constants."""
    return ScalingFunctions(np.zeros((3, 1, len(FEATURES))), np.array([[k_fx], [k_fy], [k_m]]), metadata or {})


def exact_k(beat: FinBeat, params: FishParams) -> tuple[float, float, float]:
    """K that makes the averaged model's equilibrium the full model's steady state (paper-notes, NMPC oracle).

    The averaged body dynamics are ``dv/dt = f(v) + M^-1 (K * forcing)``, so at the full model's
    cycle-averaged velocities ``v_ref``: ``K_i = -f_i(v_ref) / (M^-1 forcing)_i``.
    """
    ref = steady_state("full", right=beat, params=params)
    coef = coefficient_vector(params)
    drift = np.array(body_rhs(ref.vx, ref.vy, ref.omega, 0.0, 0.0, 0.0, coef))
    forcing = averaged_forcing(beat, params, side="right")
    unit_push = [np.array(body_rhs(ref.vx, ref.vy, ref.omega, *(forcing[j] if j == i else 0.0 for j in range(3)),
                                   coef))[i] - drift[i] for i in range(3)]
    return tuple(float(-drift[i] / unit_push[i]) for i in range(3))


def test_relative_error_and_summary_on_hand_made_numbers():
    err = sc.relative_error([1.1, 0.9, 2.0, np.nan, -3.0], [1.0, 1.0, 0.0, 1.0, -2.0])
    np.testing.assert_allclose(err[[0, 1, 4]], [0.1, 0.1, 0.5])
    assert np.isnan(err[2]) and np.isnan(err[3])  # exact 0 and missing values are undefined

    s = sc.summarize([0.01, 0.03, 0.02, np.nan, 0.10], ["a", "b", "c", "d", "e"])
    assert s["n"] == 4
    assert s["median"] == pytest.approx(0.025)  # mean of 0.02 and 0.03
    assert s["p90"] == pytest.approx(0.03 + 0.7 * (0.10 - 0.03))  # linear interpolation at rank 0.9 * 3 = 2.7
    assert s["worst"] == pytest.approx(0.10) and s["worst_pattern"] == "e"
    assert sc.summarize([np.nan], ["x"])["n"] == 0


def test_quick_cli_writes_report_json_and_plots(tmp_path, capsys):
    coefficients = tmp_path / "unit.json"
    ScalingFunctions.unit().save(coefficients)
    out = tmp_path / "val"
    assert sv.main(["--coefficients", str(coefficients), "--out", str(out), "--quick", "--no-progress"]) == 0

    results = json.loads((out / "validation.json").read_text())  # strict JSON: no NaN/Infinity
    for section in ("table4", "single_fin", "sweep", "two_fin", "targets", "timing_s"):
        assert section in results
    assert len(results["targets"]) == 9
    assert all(isinstance(t["met"], bool) for t in results["targets"])
    assert results["two_fin"]["position_m"]["n"] == len(results["two_fin"]["rows"]) > 0
    report = (out / "report.md").read_text()
    for heading in ("## Targets", "## 1. Table 4", "## 2. Random single-fin", "## 3. Forward swimming sweep",
                    "## 4. Random two-fin", "## Figures", "## Timing"):
        assert heading in report
    assert "amplitude < 5 deg or ratio < 1.25" in report  # the exclusion is stated
    assert len(results["plots"]) == 4
    for name in results["plots"]:
        data = (out / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000
        assert f"]({name})" in report
    printed = capsys.readouterr().out
    assert "MISSED" in printed and str(out / "report.md") in printed


def test_cli_rejects_bad_arguments(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    for argv in (["--coefficients", str(bad)], ["--n-single", "0"], ["--coefficients", str(tmp_path / "none.json")]):
        with pytest.raises(SystemExit) as exc:
            sv.main(argv + ["--out", str(tmp_path / "x"), "--quick"])
        assert exc.value.code == 2
    assert "not valid JSON" in capsys.readouterr().err


def test_unit_k_is_detected_as_bad():
    """With K = 1 the averaged model turns about twice as fast (paper-notes): Table 4 radii far off."""
    params = FishParams()
    table = ps.table4_section(ScalingFunctions.unit(), params, count=4)
    for row in table["rows"]:
        assert abs(row["averaged"]["omega"]) > 1.5 * abs(row["full"]["omega"])
        assert row["radius_error"] > 0.2
    assert table["radius"]["worst"] > sv.TARGETS["table4_radius_max"]


def test_exact_k_gives_vanishing_table4_error_on_the_mirrored_fin():
    """K from the right-fin steady state (algebraic oracle) reproduces the left-fin Table 4 pattern."""
    params = FishParams()
    k = exact_k(FinBeat.from_degrees(80, 22, 1.0, 4), params)  # not 90 deg: there the sway forcing vanishes
    assert 0 < k[2] < 1  # the moment must be scaled down (paper-notes)
    table = ps.table4_section(constant_k(*k), params, count=5)
    row = table["rows"][4]
    assert row["left"] == [80.0, 22.0, 1.0, 4.0] and row["right"][1] == 0
    assert row["radius_error"] < 1e-3
    assert row["period_error"] < 1e-3
    assert row["full"]["omega"] < 0  # the left fin turns the fish right
    # A constant K fitted to one pattern is not exact elsewhere: the metric does see differences.
    assert table["rows"][0]["radius_error"] > 1e-3


def test_left_and_right_fin_mirror_in_both_models():
    pattern = np.array([math.radians(72.5), math.radians(17.3), 0.83, 3.4])
    beats = np.array([[pattern, sc.REST], [sc.REST, pattern]])
    res = sc.steady_pair(beats, constant_k(0.9, 1.1, 0.6))
    for model in ("full", "averaged"):
        r = res[model]
        assert r["omega"][0] > 0 > r["omega"][1]
        assert r["omega"][1] == pytest.approx(-r["omega"][0], rel=1e-9)
        assert r["vy"][1] == pytest.approx(-r["vy"][0], rel=1e-9)
        assert r["radius"][1] == pytest.approx(r["radius"][0], rel=1e-9)
    np.testing.assert_allclose(res["radius_error"][0], res["radius_error"][1], rtol=1e-9)


def test_sampling_box_from_grid_metadata_and_draws_off_grid():
    grid = GRIDS["paper"]
    scaling = constant_k(1, 1, 1, {"grid": grid.to_dict()})
    low, high, rebuilt, _ = ps.sampling_box(scaling)
    np.testing.assert_allclose(np.degrees(low[:2]), [50, 10])
    np.testing.assert_allclose(np.degrees(high[:2]), [90, 30])
    np.testing.assert_allclose([low[2], high[2], low[3], high[3]], [0.5, 2.0, 2.0, 5.0])
    assert rebuilt is not None and len(rebuilt) == len(grid)
    draws = draw_off_grid(np.random.default_rng(1), 50, low, high, rebuilt)
    assert np.all(draws >= low) and np.all(draws <= high)
    assert not any(grid.contains(d, tol=1e-6) for d in draws)
    # No grid: the environment ranges with the forcing floor (amplitude >= 5 deg, ratio >= 1.25).
    low, high, rebuilt, _ = ps.sampling_box(ScalingFunctions.unit())
    assert rebuilt is None
    np.testing.assert_allclose(np.degrees([low[0], high[0], low[1], high[1]]), [45, 135, 5, 30])
    np.testing.assert_allclose([low[2], high[2], low[3], high[3]], [0.5, 2.0, 1.25, 5.0])


def test_simulate_xy_symmetric_fins_swim_straight_ahead():
    fin = np.array([math.radians(95), math.radians(15), 1.0, 4.0])
    model = sc.make_model("full", 1, FishParams(), ScalingFunctions.unit())
    path = sc.simulate_xy(model, np.array([[fin, fin]]), 20.0, step=1.0)
    assert path.shape == (1, 21, 2)
    assert np.all(path[0, 0] == 0)
    assert path[0, -1, 0] > 0.3  # about 5 cm/s once up to speed
    assert np.max(np.abs(path[0, :, 1])) < 1e-9


def test_identification_points_accepts_records_and_columns():
    records = [{"bias_deg": 90, "amplitude_deg": 20, "period_s": 1.0, "ratio": 2, "K_fx": 0.9, "K_fy": None,
                "K_m": 0.5}, {"bias_deg": 60, "amplitude_deg": 10, "period_s": 1.0, "ratio": 2, "K_fx": 1.0,
                              "K_fy": 1.2, "K_m": 0.6}]
    pts = identification_points({"data": records})
    np.testing.assert_allclose(pts["bias"], np.radians([90, 60]))
    assert np.isnan(pts["K_fy"][0]) and pts["K_m"][1] == 0.6
    columns = {"bias": [1.0], "amplitude": [0.2], "period": [1.0], "ratio": [2.0], "K_m": [0.4]}
    assert identification_points({"data": columns})["K_m"][0] == 0.4
    table = {"columns": ["bias_deg", "amplitude_deg", "period_s", "ratio", "K_fx", "K_fy", "K_m", "usable_K_fx",
                         "usable_K_fy", "usable_K_m"],
             "rows": [[90, 20, 1.0, 2, 0.98, 5e6, 0.2, 1.0, 0.0, 1.0], [60, 10, 1.0, 2, 1.0, 0.8, 0.3, 1.0, 1.0, 1.0]]}
    pts = identification_points({"data": table})
    np.testing.assert_allclose(pts["amplitude"], np.radians([20, 10]))
    assert np.isnan(pts["K_fy"][0]) and pts["K_fy"][1] == 0.8  # the unusable value is hidden
    assert identification_points({}) is None
    assert identification_points({"data": "garbage"}) is None


def test_report_says_when_k_was_identified_with_other_parameters():
    recorded = dataclasses.asdict(FishParams())
    assert sv._params_differ(recorded, FishParams()) == []
    assert sv._params_differ({**recorded, "fin_span": recorded["fin_span"] * 1.1}, FishParams()) == ["fin_span"]
    assert sv._params_differ(None, FishParams()) is None


def test_a_turn_in_the_other_direction_is_caught_although_the_radius_has_no_sign():
    # K_m = -1 reverses the right fin's averaged moment: the averaged fish circles right, the full one left.
    beats = np.array([[sc.fin_pattern(60, 20, 1.0, 3), sc.REST]])
    res = sc.steady_pair(beats, constant_k(1.0, 1.0, -1.0))
    assert res["full"]["omega"][0] > 0 > res["averaged"]["omega"][0]
    assert res["direction_flip"].tolist() == [True]
    flips = ps._flips(res, ["p"])
    assert flips == {"count": 1, "n": 1, "share": 1.0, "patterns": ["p"]}
    assert not sc.steady_pair(beats, constant_k(1.0, 1.0, 0.5))["direction_flip"][0]
