"""Sharing a run in rl_zoo3's Hub layout, offline: write it, lay it out as zoo's own download does, load it back."""

import filecmp
import importlib.util
import json
import os
import subprocess
import sys
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest
import yaml

from pectoral_gym.versions import LATEST_AVERAGED

pytest.importorskip("stable_baselines3")

from pectoral_gym.agents.training.hub import read_hub_folder, write_hub_folder  # noqa: E402
from pectoral_gym.agents.training.policy import load_policy  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _env():
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A real pectoral-train run (its --quick sizes)."""
    where = tmp_path_factory.mktemp("train")
    done = subprocess.run([str(Path(sys.executable).parent / "pectoral-train"), "--env", LATEST_AVERAGED, "--seed",
                           "0", "--out", "runs", "--run-name", "shared", "--quick", "--no-progress"], cwd=where,
                          env=_env(), capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    return where / "runs" / LATEST_AVERAGED / "shared"


def _same_actions(a, b):
    obs = np.random.default_rng(0).normal(size=(16, 27)).astype(np.float32) * 2
    return np.array_equal(load_policy(a).act_batch(obs), load_policy(b).act_batch(obs))


def test_round_trip_acts_as_the_run(run, tmp_path):
    hub = write_hub_folder(run, tmp_path / "hub")
    name = f"ppo-{LATEST_AVERAGED}"
    assert {p.name for p in hub.iterdir()} == {f"{name}.zip", "vec_normalize.pkl", "config.yml", "args.yml",
                                               "env_kwargs.yml", "train_eval_metrics.zip", "README.md"}
    assert filecmp.cmp(hub / f"{name}.zip", run / "model.zip", shallow=False)  # the model load_policy takes
    assert filecmp.cmp(hub / "vec_normalize.pkl", run / "vecnormalize_final.pkl", shallow=False)  # and its stats
    zoo_run = read_hub_folder(hub, tmp_path / "logs")
    assert zoo_run == tmp_path / "logs" / "ppo" / f"{LATEST_AVERAGED}_1"
    loaded, original = load_policy(zoo_run), load_policy(run)
    np.testing.assert_array_equal(loaded.obs_mean, original.obs_mean)
    assert _same_actions(zoo_run, run)
    assert read_hub_folder(hub, tmp_path / "logs").name == f"{LATEST_AVERAGED}_2"  # exp_id 0: the next free one
    with pytest.raises(ValueError, match="exists already"):
        read_hub_folder(hub, tmp_path / "logs", exp_id=1)
    with pytest.raises(ValueError, match="not empty"):
        write_hub_folder(run, hub)
    # zoo's own args.yml is an OrderedDict dumped by PyYAML (a python tag): the layout does not depend on reading it
    (hub / "args.yml").write_text(yaml.dump(OrderedDict([("algo", "ppo"), ("env", LATEST_AVERAGED)])))
    assert _same_actions(read_hub_folder(hub, tmp_path / "logs"), run)
    (hub / "config.yml").unlink()
    with pytest.raises(FileNotFoundError, match="config.yml"):
        read_hub_folder(hub, tmp_path / "other")
    with pytest.raises(FileNotFoundError, match="no config.yaml"):
        write_hub_folder(tmp_path, tmp_path / "again")


# rl_zoo3's own download_from_hub on the folder, its one network call (huggingface_sb3.load_from_hub) served from disk
_ZOO_DOWNLOAD = """
import sys
from pathlib import Path
from huggingface_sb3 import EnvironmentName
from requests.exceptions import HTTPError
import rl_zoo3.load_from_hub as zoo

hub, logs, algo, env_id = sys.argv[1:]

def from_disk(repo_id, filename):
    path = Path(hub) / filename
    if not path.is_file():
        raise HTTPError(f"404 {filename}")
    return str(path)

zoo.load_from_hub = from_disk
zoo.download_from_hub(algo=algo, env_name=EnvironmentName(env_id), exp_id=0, folder=logs, organization="offline")
"""


@pytest.mark.skipif(importlib.util.find_spec("rl_zoo3") is None or importlib.util.find_spec("huggingface_sb3") is None,
                    reason="rl_zoo3 and huggingface_sb3 not installed (dev extra)")
def test_zoo_download_lays_it_out_as_read_hub_folder_and_enjoy_runs(run, tmp_path):
    hub = write_hub_folder(run, tmp_path / "hub")
    done = subprocess.run([sys.executable, "-c", _ZOO_DOWNLOAD, str(hub), str(tmp_path / "zoo"), "ppo",
                           LATEST_AVERAGED], cwd=tmp_path, env=_env(), capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    by_zoo = tmp_path / "zoo" / "ppo" / f"{LATEST_AVERAGED}_1"
    ours = read_hub_folder(hub, tmp_path / "ours")
    files = sorted(p.relative_to(by_zoo) for p in by_zoo.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(ours) for p in ours.rglob("*") if p.is_file())
    assert all(filecmp.cmp(by_zoo / f, ours / f, shallow=False) for f in files)
    assert _same_actions(by_zoo, run)
    done = subprocess.run([sys.executable, "-m", "rl_zoo3.enjoy", "--algo", "ppo", "--env", LATEST_AVERAGED,
                           "--gym-packages", "pectoral_gym", "-f", "zoo", "--exp-id", "1", "--no-render", "-n", "20"],
                          cwd=tmp_path, env=_env(), capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Loading running average" in done.stdout  # zoo found the statistics and read config.yml's normalize


def test_command_line_writes_and_reads(run, tmp_path):
    module = [sys.executable, "-m", "pectoral_gym.agents.training.hub"]
    done = subprocess.run([*module, "write", str(run), "hub"], cwd=tmp_path, env=_env(), capture_output=True,
                          text=True)
    assert done.returncode == 0 and json.loads(done.stdout) == {"folder": "hub"}, done.stderr
    done = subprocess.run([*module, "read", "hub", "-f", "logs"], cwd=tmp_path, env=_env(), capture_output=True,
                          text=True)
    assert json.loads(done.stdout) == {"folder": f"logs/ppo/{LATEST_AVERAGED}_1"}, done.stderr
    done = subprocess.run([*module, "read", "nowhere"], cwd=tmp_path, env=_env(), capture_output=True, text=True)
    assert done.returncode == 2 and done.stderr.startswith("error: nowhere has 0 <algo>-<env>.zip"), done.stderr


def test_page_commands_run_as_written(run, tmp_path):
    # docs/guide/trainers.md's hub snippet on a pectoral-train run at the path it names (evaluation shortened)
    import shlex
    import shutil

    from doc_snippets import commands, snippet

    write_line, read_line, evaluate_line = commands(snippet("hub"))
    shutil.copytree(run, tmp_path / "runs" / LATEST_AVERAGED / "ppo_seed0")
    for line, extra in ((write_line, []), (read_line, []), (evaluate_line, ["--episodes", "2", "--out", "eval"])):
        argv = shlex.split(line)
        program = [sys.executable, "-m", argv[2]] if argv[0] == "python" else [
            str(Path(sys.executable).parent / argv[0])]
        done = subprocess.run([*program, *argv[(3 if argv[0] == "python" else 1):], *extra], cwd=tmp_path,
                              env=_env(), capture_output=True, text=True)
        assert done.returncode == 0, (line, done.stderr[-3000:])
    assert json.loads((tmp_path / "eval" / "metrics.json").read_text())["n_episodes"] == 2
