"""Calibrating a fish whose fins differ: the left fin's force relative to the right one's and the servo offsets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pectoral_gym.model.params import FishParams
from pectoral_gym.runlog import read_run_log
from pectoral_gym.scaling.calibration.benchmark import interval_scores
from pectoral_gym.scaling.calibration.fit import CalibrationSettings, calibrate
from pectoral_gym.scaling.calibration.identifiability import ASYMMETRY_FIELDS
from pectoral_gym.scaling.calibration.report import markdown, report_dict
from pectoral_gym.scaling.calibration.synth import write_synthetic_log

# Force coefficients unknown, added masses known (the fields of test_calibration), and a weak left fin whose
# servo horns are both off.
TRUTH = FishParams().replace(drag_coef=0.3870 * 1.2, moment_coef=8.5e-3 * 0.8, fin_force_coef=4.1464 * 1.15,
                             fin_force_scale_left=0.75, fin_angle_offset_right=0.06, fin_angle_offset_left=-0.04)
FIELDS = ("drag_coef", "moment_coef", "fin_force_coef", *ASYMMETRY_FIELDS)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    path = tmp_path_factory.mktemp("asym") / "fit.jsonl"
    write_synthetic_log(path, TRUTH, 5, duration=60.0)
    return calibrate([read_run_log(path)], settings=CalibrationSettings(fields=FIELDS))


def test_the_asymmetry_is_recovered_within_its_standard_errors(fitted):
    cal, ident = fitted, fitted.identifiability
    ratio = cal.params.fin_force_scale_left / cal.params.fin_force_scale_right
    assert ratio == pytest.approx(0.75, rel=0.05)  # the target: within 5 %
    for name in FIELDS:
        got, true = getattr(cal.params, name), getattr(TRUTH, name)
        error = got - true if name.startswith("fin_angle_offset") else math.log(got / true)
        assert abs(error) <= 4.0 * ident.std_error[name] + 0.005, f"{name}: {got} against {true}"
    assert ident.identified["fin_force_scale_left"]


def test_the_report_gives_offsets_in_rad_and_the_benchmark_scores_them(fitted):
    report = report_dict(fitted, truth=TRUTH)
    offset = report["fields"]["fin_angle_offset_right"]
    assert "std_error_rad" in offset and "std_error_relative" not in offset
    assert offset["error_rad"] == pytest.approx(fitted.params.fin_angle_offset_right - 0.06, abs=1e-15)
    assert "deg |" in markdown(report)
    scores = interval_scores(report)["reported"]
    assert scores["fin_angle_offset_right"] == pytest.approx(offset["error_rad"] / offset["std_error_rad"])


def test_a_field_off_the_common_scale_keeps_its_standard_error():
    """Information ``[[3, 1, 0], [1, 3, 0], [0, 0, 4]]``, scale ``(1, 1, 0)/sqrt 2`` unfixed: the third field's
    standard error is ``1/sqrt(4)`` by hand, the two that move the scale are unfixed."""
    from pectoral_gym.scaling.calibration.identifiability import _standard_errors

    info = np.array([[3.0, 1.0, 0.0], [1.0, 3.0, 0.0], [0.0, 0.0, 4.0]])
    scale = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
    data_se = _standard_errors(info, 0.3, np.zeros((0, 3)), scale)[1]
    assert np.isinf(data_se[:2]).all()
    assert data_se[2] == pytest.approx(0.5, rel=1e-12)
