"""The calibration benchmark on robots whose fins differ: the truth drawn as documented, the asymmetry scored."""

from __future__ import annotations

import json
import math

from pectoral_gym.model.params import FishParams
from pectoral_gym.scaling.calibration.benchmark import main, summary
from pectoral_gym.scaling.calibration.identifiability import ASYMMETRY_FIELDS
from pectoral_gym.scaling.calibration.synth import asymmetric_params, perturbed_params


def test_the_asymmetry_is_drawn_within_its_spreads_and_seeded():
    base = FishParams()
    draws = [asymmetric_params(seed, base) for seed in range(40)]
    ratios = [p.fin_force_scale_left for p in draws]
    offsets = [p.fin_angle_offset_right for p in draws] + [p.fin_angle_offset_left for p in draws]
    assert 0.7 <= min(ratios) < 0.8 and 1.2 < max(ratios) <= 1.3  # U(0.7, 1.3): 40 draws reach both ends' tenths
    assert max(map(abs, offsets)) <= 0.1 and min(offsets) < -0.05 < 0.05 < max(offsets)
    assert asymmetric_params(7, base) == asymmetric_params(7, base)
    assert asymmetric_params(7, base).fin_force_scale_right == 1.0  # the right fin carries fin_force_coef


def test_an_asymmetric_robot_is_fitted_and_scored(tmp_path, capsys):
    assert main(["--seeds", "9002", "--asymmetric", "--held-out", "0", "--minutes", "0.5", "--out", str(tmp_path)]) == 0
    assert "the fins' asymmetry" in capsys.readouterr().out
    (report,) = json.loads((tmp_path / "benchmark.json").read_text())
    truth = asymmetric_params(9002, perturbed_params(9002))
    for name in ASYMMETRY_FIELDS:
        assert name in report["coverage"]["reported"]
    ratio = report["fields"]["fin_force_scale_left"]
    assert math.isclose(ratio["truth"], truth.fin_force_scale_left)
    assert abs(ratio["error_relative"]) < 0.05  # the target: the asymmetry within 5 %
    offset = report["fields"]["fin_angle_offset_left"]
    assert math.isclose(offset["truth"], truth.fin_angle_offset_left)
    assert math.isclose(offset["error_rad"], offset["value"] - truth.fin_angle_offset_left)
    figures = summary([report])
    assert figures["coverage_asymmetry"]["intervals"] == 3
