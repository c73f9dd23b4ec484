"""A run folder keeps the robot files it trained with (``agents/training/run_files.py``)."""

import dataclasses
import json

import pytest
import yaml

from pectoral_gym.agents.training.evaluate import main as evaluate_main
from pectoral_gym.agents.training.policy import load_policy, read_config
from pectoral_gym.agents.training.run_files import keep_run_files, resolve_run_files
from pectoral_gym.agents.training.train import main as train_main
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import FishParams, load_params, save_params


def _robot_files(where):
    """A robot's params file and a K file labelled as identified for it (the shipped K, relabelled)."""
    robot = FishParams().replace(drag_coef=0.45, fin_span=0.07)
    save_params(robot, where / "robot.json")
    k = ScalingFunctions.load(None)
    k.metadata["model_parameters"] = dataclasses.asdict(robot)
    k.save(where / "k.json")
    return robot


def test_a_run_trained_with_robot_files_evaluates_from_anywhere(tmp_path, monkeypatch):
    train_dir, elsewhere = tmp_path / "train_here", tmp_path / "elsewhere"
    train_dir.mkdir()
    elsewhere.mkdir()
    robot = _robot_files(train_dir)
    monkeypatch.chdir(train_dir)
    kwargs = json.dumps({"params": "robot.json", "scaling": "k.json"})
    assert train_main(["--env", "PectoralFish-Averaged-v2", "--quick", "--no-progress", "--out", "runs",
                       "--run-name", "r", "--env-kwargs", kwargs]) == 0
    run_dir = train_dir / "runs" / "PectoralFish-Averaged-v2" / "r"
    recorded = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert recorded["env_kwargs"]["params"] == "params.json" and recorded["env_kwargs"]["scaling"] == \
        "scaling_coefficients.json"
    assert recorded["model_spec"]["scaling"] == "scaling_coefficients.json"
    assert load_params(run_dir / "params.json") == robot
    # the user's files change or go away: the run keeps what it trained with
    (train_dir / "robot.json").write_text(json.dumps({"drag_coef": 0.2}))
    (train_dir / "k.json").unlink()
    monkeypatch.chdir(elsewhere)
    config = read_config(run_dir)
    assert config["env_kwargs"]["params"] == str(run_dir / "params.json")
    assert load_policy(run_dir).trained_from == run_dir / "config.yaml"
    assert evaluate_main(["--policy", str(run_dir), "--env", "PectoralFish-Full-v2", "--quick",
                          "--out", str(elsewhere / "eval")]) == 0
    metrics = json.loads((elsewhere / "eval" / "metrics.json").read_text())
    assert load_params(metrics["env_kwargs"]["params"]) == robot


def test_only_files_are_kept_and_old_runs_read_as_before(tmp_path):
    (tmp_path / "run").mkdir()
    config = {"env_kwargs": {"params": {"drag_coef": 0.4}, "scaling": "identified", "task": "goal"},
              "eval_env_kwargs": {}}
    to_train, to_record = keep_run_files(config, tmp_path / "run")
    assert to_train == config == to_record and not any((tmp_path / "run").iterdir())
    # an old run folder recorded the path as typed: left as it is when the run has no such file
    assert resolve_run_files({"params": "robot.json"}, tmp_path / "run") == {"params": "robot.json"}
    assert resolve_run_files({"params": "params.json"}, tmp_path / "run") == {"params": "params.json"}


def test_two_files_for_one_argument_are_refused(tmp_path):
    _robot_files(tmp_path)
    save_params(FishParams(), tmp_path / "other.json")
    (tmp_path / "run").mkdir()
    config = {"env_kwargs": {"params": str(tmp_path / "robot.json")},
              "eval_env_kwargs": {"params": str(tmp_path / "other.json")}}
    with pytest.raises(ValueError, match="another file"):
        keep_run_files(config, tmp_path / "run")
