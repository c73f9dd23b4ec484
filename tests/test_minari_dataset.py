"""The Minari dataset command: a controller's seeded episodes written with their metadata, read back, replayed."""

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym.versions import LATEST_AVERAGED

minari = pytest.importorskip("minari")
pytest.importorskip("h5py")
pytest.importorskip("jax")

ROOT = Path(__file__).resolve().parents[1]


def _command(tmp_path, *args):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "pectoral_gym.agents.training.dataset", *args,
                           "--datasets-path", str(tmp_path / "datasets")], cwd=tmp_path, env=env,
                          capture_output=True, text=True)


def test_hand_controller_dataset_round_trip(tmp_path, monkeypatch):
    done = _command(tmp_path, "--controller", "hand", "--env", LATEST_AVERAGED, "--episodes", "3", "--seed", "7",
                    "--dataset-id", "pectoral/hand-test-v0", "--author", "pectoral-gym tests",
                    "--author-email", "tests@example.org")
    assert done.returncode == 0, done.stderr[-3000:]
    written = json.loads(done.stdout.strip().splitlines()[-1])
    assert written["episodes"] == 3 and written["path"] == str(tmp_path / "datasets" / "pectoral" / "hand-test-v0")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    dataset = minari.load_dataset("pectoral/hand-test-v0")
    assert dataset.total_episodes == 3 and dataset.total_steps == written["steps"]
    meta = dataset.storage.metadata
    assert meta["algorithm_name"] == "hand" and meta["author"] == {"pectoral-gym tests"}
    assert f"hand on {LATEST_AVERAGED}" in meta["description"] and "seeds 7..9" in meta["description"]
    assert f"success {written['success']:.2f}" in meta["description"]
    # the recorded episodes replay exactly in the env Minari recovers: same starts (seed 7 + k), observations,
    # rewards and infos for the recorded actions
    env = dataset.recover_environment()
    returns, successes = [], 0
    for k, episode in enumerate(dataset.iterate_episodes()):
        obs, info = env.reset(seed=7 + k)
        np.testing.assert_array_equal(obs, episode.observations[0])
        for t, action in enumerate(episode.actions):
            obs, reward, terminated, truncated, info = env.step(action)
            np.testing.assert_array_equal(obs, episode.observations[t + 1])
            assert reward == episode.rewards[t] and terminated == episode.terminations[t]
            assert info["distance"] == episode.infos["distance"][t + 1]
        assert terminated or truncated
        returns.append(float(np.sum(episode.rewards)))
        successes += bool(episode.infos["is_success"][-1])
    assert written["mean_return"] == pytest.approx(np.mean(returns)) and written["success"] == successes / 3
    assert env.spec.id == LATEST_AVERAGED


def test_policy_dataset_and_bad_input(tmp_path, monkeypatch, capsys):
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from pectoral_gym.agents.training.dataset import main

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        PPO("MlpPolicy", gym.make(LATEST_AVERAGED), n_steps=64, batch_size=64, seed=0, device="cpu").save(
            tmp_path / "model.zip")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    args = ["--policy", str(tmp_path / "model.zip"), "--env", LATEST_AVERAGED, "--episodes", "1",
            "--dataset-id", "pectoral/ppo-test-v0"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # Minari's advice to name an author
        assert main(args) == 0
        assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["episodes"] == 1
        assert minari.load_dataset("pectoral/ppo-test-v0").storage.metadata["algorithm_name"] == "ppo"
        assert main(args) == 2  # an existing id is refused
        assert "pectoral/ppo-test-v0" in capsys.readouterr().err
    assert main(["--controller", "hand", "--episodes", "0", "--dataset-id", "pectoral/x-v0"]) == 2
    assert "episodes must be >= 1" in capsys.readouterr().err


def test_page_commands_run_as_written(tmp_path, monkeypatch):
    # docs/guide/trainers.md's two commands, with one episode each (argparse keeps the last --episodes); the
    # policy's run folder holds an untrained PPO's model.zip
    pytest.importorskip("stable_baselines3")
    import shlex

    from doc_snippets import commands, snippet
    from stable_baselines3 import PPO

    from pectoral_gym.agents.training.dataset import main

    policy_line, hand_line = commands(snippet("minari-command"))
    run = tmp_path / "runs" / LATEST_AVERAGED / "ppo_seed0"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        PPO("MlpPolicy", gym.make(LATEST_AVERAGED), n_steps=64, batch_size=64, seed=0, device="cpu").save(
            run / "model.zip")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "home"))
    for line in (policy_line, hand_line):
        argv = shlex.split(line)
        assert argv[:3] == ["python", "-m", "pectoral_gym.agents.training.dataset"], line
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            assert main([*argv[3:], "--episodes", "1"]) == 0, line
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "home"))  # the second line's --datasets-path moved it
    assert minari.load_dataset("pectoral/full-ppo-v0").storage.metadata["author"] == {"your name"}
    assert (tmp_path / "datasets" / "pectoral" / "full-hand-v0").is_dir()  # the second line's --datasets-path
