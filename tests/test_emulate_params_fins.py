"""``--emulate-params``/``--params`` with per-fin fields: the emulated robot takes them; implausible ones fail."""

from __future__ import annotations

import argparse
import json

import pytest

from pectoral_gym.hardware.deploy_cli import fish_params
from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.model.params import COEF_NAMES


def test_the_emulated_robot_runs_the_fins_of_its_params_file(tmp_path):
    path = tmp_path / "robot_true.json"
    path.write_text(json.dumps({"fin_force_scale_left": 0.75, "fin_angle_offset_right": 0.087}))
    params = fish_params(str(path))
    assert (params.fin_force_scale_left, params.fin_angle_offset_right) == (0.75, 0.087)
    robot = EmulatedRobot(params=params, seed=0)
    row = dict(zip(COEF_NAMES, robot.model.coef[0], strict=True))
    assert row["fin_force_scale_left"] == 0.75 and row["fin_angle_offset_right"] == 0.087
    assert row["fin_force_scale_right"] == 1.0 and row["fin_angle_scale_left"] == 1.0


@pytest.mark.parametrize("fields, named", [({"fin_angle_offset_left": 0.5}, "fin_angle_offset_left"),
                                           ({"fin_force_scale_right": 0.01}, "fin_force_scale_right"),
                                           ({"fin_angle_scale_right": -1.0}, "fin_angle_scale_right")])
def test_an_implausible_fin_is_refused_in_one_line(tmp_path, fields, named):
    path = tmp_path / "robot.json"
    path.write_text(json.dumps(fields))
    with pytest.raises(argparse.ArgumentTypeError, match=named) as error:
        fish_params(str(path))
    assert "\n" not in str(error.value)
