"""``pectoral-train --params FILE``: the fish's parameters file, the same as ``--env-kwargs '{"params": FILE}'``."""

from __future__ import annotations

import json

import yaml

from pectoral_gym.agents.training.train import main


def test_params_reach_the_run_and_are_given_once(tmp_path, capsys):
    robot = tmp_path / "robot.json"
    robot.write_text(json.dumps({"fin_force_scale_left": 0.75}))
    assert main(["--quick", "--params", str(robot), "--env-kwargs", json.dumps({"params": str(robot)}),
                 "--out", str(tmp_path / "runs")]) == 2
    assert "--params" in capsys.readouterr().err
    assert main(["--quick", "--no-progress", "--params", str(robot), "--out", str(tmp_path / "runs"),
                 "--run-name", "weak"]) == 0
    run = next((tmp_path / "runs").glob("*/weak"))
    config = yaml.safe_load((run / "config.yaml").read_text())
    kept = json.loads((run / config["env_kwargs"]["params"]).read_text())
    assert kept["fin_force_scale_left"] == 0.75
