"""Your own robot: parameters files, K files that record their parameters, the check, and the walk-through."""

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym import FishParams
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import (
    PER_FIN_DEFAULTS,
    as_params,
    load_params,
    params_dict,
    params_from_dict,
    save_params,
)

ROOT = Path(__file__).resolve().parents[1]
ENV = "PectoralFish-Averaged-v0"


def _k_file(tmp_path: Path, params: FishParams | None, name: str = "k.json") -> Path:
    """The shipped K with ``model_parameters`` set to ``params`` (``None``: removed), saved to a file."""
    k = ScalingFunctions.load()
    meta = dict(k.metadata)
    meta.pop("model_parameters", None)
    if params is not None:
        meta["model_parameters"] = dataclasses.asdict(params)
    path = tmp_path / name
    dataclasses.replace(k, metadata=meta).save(path)
    return path


def test_a_parameters_file_holds_only_what_differs_from_table_1(tmp_path):
    (tmp_path / "robot.json").write_text('{"fin_span": 0.07, "body_mass": 1}')
    params = load_params(tmp_path / "robot.json")
    assert params == FishParams().replace(fin_span=0.07, body_mass=1.0)
    pytest.importorskip("yaml")
    (tmp_path / "robot.yaml").write_text("fin_span: 0.07\nbody_mass: 1.0\n")
    assert load_params(tmp_path / "robot.yaml") == params
    save_params(params, tmp_path / "all.json")
    assert json.loads((tmp_path / "all.json").read_text()) == params_dict(params)
    assert load_params(tmp_path / "all.json") == params
    (tmp_path / "empty.yaml").write_text("")
    assert load_params(tmp_path / "empty.yaml") == FishParams()


@pytest.mark.parametrize(("text", "match"), [
    ('{"fin_spam": 0.07}', r"unknown FishParams fields \['fin_spam'\]"),
    ('{"fin_span": -1}', "fin_span must be > 0"),
    ('{"fin_span": "wide"}', "fin_span must be a number"),
    ('{"fin_span": true}', "fin_span must be a number"),
    ('[0.07]', "expected a mapping"),
    ('{"fin_span": 0.07', "not valid JSON"),
])
def test_bad_parameters_files_say_what_is_wrong(tmp_path, text, match):
    path = tmp_path / "robot.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_params(path)


def test_as_params_takes_every_form():
    p = FishParams(fin_span=0.05)
    assert as_params(None) == FishParams() and as_params(p) is p
    assert as_params({"fin_span": 0.05}) == p == params_from_dict(params_dict(p))
    with pytest.raises(ValueError, match="params must be"):
        as_params(3.0)
    with pytest.raises(FileNotFoundError):
        as_params("no/such/robot.json")


def test_params_mismatch_names_the_fields_that_differ(tmp_path):
    k = ScalingFunctions.load()
    # the shipped file: Table 1, recorded before the per-fin fields existed (its fish is the symmetric one)
    assert k.identified_params == {name: value for name, value in dataclasses.asdict(FishParams()).items()
                                   if name not in PER_FIN_DEFAULTS}
    assert k.params_mismatch(FishParams()) == {}
    assert k.params_mismatch(FishParams(fin_span=0.07, fin_chord=0.05)) == {
        "fin_span": (0.061, 0.07), "fin_chord": (0.041, 0.05)}
    unrecorded = ScalingFunctions.load(_k_file(tmp_path, None))
    assert unrecorded.identified_params is None and unrecorded.params_mismatch(FishParams(fin_span=0.07)) == {}
    assert ScalingFunctions.unit().params_mismatch(FishParams(fin_span=0.07)) == {}


def test_averaged_env_refuses_k_identified_for_another_robot_unless_told(tmp_path):
    robot = FishParams(fin_span=0.07)
    with pytest.raises(ValueError, match=r"fin_span: identified 0.061, given 0.07"):
        gym.make(ENV, params=robot)
    with pytest.raises(ValueError, match="fin_span"):
        gym.make_vec(ENV, num_envs=2, vectorization_mode="vector_entry_point", params=robot)
    env = gym.make(ENV, params=robot, check_scaling_params=False)  # the explicit opt-out
    assert env.unwrapped.config.params == robot
    gym.make(ENV, params=robot, scaling="none")  # K = 1 records no robot
    gym.make("PectoralFish-Full-v0", params=robot)  # the full model has no K
    # domain randomisation around the identified parameters is not checked per episode
    env = gym.make(ENV, randomize={"fin_span": 0.2})
    env.reset(seed=0)
    assert env.unwrapped.fish_params.fin_span != 0.061


def test_env_takes_params_and_k_files_identified_for_them(tmp_path):
    robot = FishParams(fin_span=0.07)
    params_file = tmp_path / "robot.json"
    save_params(robot, params_file)
    k_file = _k_file(tmp_path, robot)
    env = gym.make(ENV, params=str(params_file), scaling=str(k_file))
    assert env.unwrapped.config.params == robot
    assert env.unwrapped.model.scaling.identified_params == dataclasses.asdict(robot)
    env.reset(seed=0)
    env.step(np.zeros(8, np.float32))
    with pytest.raises(ValueError, match="coefficients file"):
        gym.make(ENV, scaling=k_file)  # Table 1 params, K for the other robot
    with pytest.raises(ValueError, match="no coefficients file"):
        gym.make(ENV, scaling=str(tmp_path / "missing.json"))


def _run(*args, cwd):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=600)


def test_cli_steady_takes_params_and_checks_the_k_file(tmp_path):
    (tmp_path / "robot.json").write_text('{"fin_span": 0.07}')
    common = ["-m", "pectoral_gym", "steady", "--right", "90,20,1,3", "--json"]
    bad = _run(*common, "--model", "averaged", "--params", "robot.json", cwd=tmp_path)
    assert bad.returncode == 2 and "fin_span: identified 0.061, given 0.07" in bad.stderr
    ok = _run(*common, "--model", "averaged", "--params", "robot.json", "--no-params-check", cwd=tmp_path)
    assert ok.returncode == 0, ok.stderr
    full = [json.loads(_run(*common, *extra, cwd=tmp_path).stdout) for extra in ([], ["--params", "robot.json"])]
    # a longer fin at the same beat pushes harder: the paper robot and this one do not swim alike
    assert full[1]["speed"] > full[0]["speed"]


def test_cli_validate_takes_params_and_reports_a_k_file_for_another_robot(tmp_path):
    (tmp_path / "robot.json").write_text('{"fin_span": 0.07}')
    run = _run("-m", "pectoral_gym.scaling", "validate", "--params", "robot.json", "--out", "val", "--quick",
               "--no-plots", "--no-progress", cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    report = json.loads((tmp_path / "val" / "validation.json").read_text())
    assert report["params_differ"] == ["fin_span"]  # the shipped K was identified for fin_span 0.061
    assert report["source"] == "the shipped coefficients file"  # a report names no path of the machine it ran on
    bad = _run("-m", "pectoral_gym.scaling", "validate", "--params", "missing.json", cwd=tmp_path)
    assert bad.returncode == 2 and "missing.json" in bad.stderr
