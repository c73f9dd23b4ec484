"""Training smoke runs through the real CLI, run folders, config resolution, repeatability, load_policy."""

import contextlib
import shutil

import numpy as np
import pytest
import torch
import yaml

from pectoral_gym.agents.training.config import algo_kwargs, parse_overrides, resolve_config
from pectoral_gym.agents.training.evaluate import evaluate
from pectoral_gym.agents.training.policy import Controller, load_policy
from pectoral_gym.agents.training.train import main

ENV = "PectoralFish-Averaged-v0"
TINY = ["n_timesteps=256", "n_envs=4", "n_steps=32", "batch_size=64", "n_epochs=1", "eval_freq=128",
        "eval_episodes=2"]


def run(tmp_path, name, *extra, algo="ppo", hyperparams=TINY):
    argv = ["--env", ENV, "--algo", algo, "--seed", "3", "--out", str(tmp_path), "--run-name", name,
            "--no-progress", "--hyperparams", *hyperparams, *extra]
    assert main(argv) == 0
    return tmp_path / ENV / name


def test_ppo_smoke_run_fills_the_run_folder(tmp_path):
    run_dir = run(tmp_path, "a", "--task", "goal")
    for name in ("model.zip", "best_model.zip", "vecnormalize.pkl", "vecnormalize_final.pkl", "config.yaml",
                 "command.txt", "training.json"):
        assert (run_dir / name).is_file(), name
    assert any((run_dir / "tb").rglob("events.out.tfevents.*"))
    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert config["algo"] == "ppo" and config["env_id"] == ENV and config["seed"] == 3
    assert config["n_timesteps"] == 256 and config["algo_kwargs"]["n_steps"] == 32
    assert config["env_kwargs"]["task"] == "goal"
    assert "--seed 3" in (run_dir / "command.txt").read_text()

    policy = load_policy(run_dir)
    assert isinstance(policy, Controller)
    assert policy.obs_mean is not None  # normalisation statistics applied
    assert policy.obs_size == 27  # the shipped file observes the fins (observe_fins: true)
    obs = np.random.default_rng(0).normal(size=(5, policy.obs_size)).astype(np.float32)
    actions = policy.act_batch(obs)
    assert actions.shape == (5, 8) and actions.dtype == np.float32 and np.all(np.abs(actions) <= 1)
    np.testing.assert_allclose(policy.act(obs[0]), actions[0], atol=1e-6)
    np.testing.assert_array_equal(policy.act_batch(obs), actions)  # deterministic
    # the zip alone loads too (algorithm read from the zip), with the statistics next to it
    from_zip = load_policy(run_dir / "best_model.zip")
    np.testing.assert_allclose(from_zip.act_batch(obs), actions, atol=1e-6)
    result = evaluate(policy, ENV, n_episodes=3, seed=0)
    assert result.n_episodes == 3


def test_keep_checkpoints_keeps_every_evaluated_policy_with_its_statistics(tmp_path):
    import json

    run_dir = run(tmp_path, "k", "--keep-checkpoints")
    evaluations = json.loads((run_dir / "training.json").read_text())["evaluations"]
    names = [e["checkpoint"] for e in evaluations]
    assert len(names) == 2 and all((run_dir / n).is_file() for n in names)  # 256 steps, evaluated every 128
    for e in evaluations:
        assert (run_dir / f"rl_model_vecnormalize_{e['timesteps']}_steps.pkl").is_file()
    # The best one is the same policy as best_model.zip, statistics included (load_policy finds them by name).
    best = next(e for e in reversed(evaluations) if e["best"])
    obs = np.random.default_rng(2).normal(size=(6, 27)).astype(np.float32)
    kept = load_policy(run_dir / best["checkpoint"])
    np.testing.assert_array_equal(kept.obs_mean, load_policy(run_dir).obs_mean)
    np.testing.assert_allclose(kept.act_batch(obs), load_policy(run_dir).act_batch(obs), atol=1e-6)
    assert not list(run(tmp_path, "n").glob("rl_model_*"))  # off by default


def test_same_seed_repeats_the_run(tmp_path):
    a = load_policy(run(tmp_path, "a") / "model.zip")
    b = load_policy(run(tmp_path, "b") / "model.zip")
    obs = np.random.default_rng(1).normal(size=(8, a.obs_size)).astype(np.float32)
    for pa, pb in zip(a.model.policy.parameters(), b.model.policy.parameters(), strict=True):
        assert np.array_equal(pa.detach().numpy(), pb.detach().numpy())
    np.testing.assert_array_equal(a.act_batch(obs), b.act_batch(obs))


def test_training_without_distribution_checks_learns_the_same_and_restores_them(tmp_path, monkeypatch):
    # the checks only raise on invalid parameters: with them on (as a caller may want), the run is the same
    from torch.distributions import Distribution

    import pectoral_gym.agents.training.train as train_module

    before = Distribution._validate_args  # importing torchrl (another test, same worker) turns them off
    try:
        Distribution.set_default_validate_args(True)
        a = load_policy(run(tmp_path, "a") / "model.zip")
        assert Distribution._validate_args is True  # the caller's setting, restored after the run
        monkeypatch.setattr(train_module, "_distribution_checks_off", contextlib.nullcontext)
        b = load_policy(run(tmp_path, "b") / "model.zip")
        for pa, pb in zip(a.model.policy.parameters(), b.model.policy.parameters(), strict=True):
            assert np.array_equal(pa.detach().numpy(), pb.detach().numpy())
        Distribution.set_default_validate_args(False)
        run(tmp_path, "c")
        assert Distribution._validate_args is False
    finally:
        Distribution.set_default_validate_args(before)


def test_sac_smoke_run(tmp_path):
    run_dir = run(tmp_path, "s", "--eval-freq", "0", algo="sac",
                  hyperparams=["n_timesteps=200", "n_envs=2", "learning_starts=50", "normalize=false"])
    assert (run_dir / "model.zip").is_file() and not (run_dir / "vecnormalize.pkl").exists()
    # --eval-freq 0 overrides the file's pectoral_gym.agents.training.train section
    assert not (run_dir / "best_model.zip").exists()
    assert yaml.safe_load((run_dir / "config.yaml").read_text())["eval_freq"] == 0
    policy = load_policy(run_dir)
    assert policy.obs_mean is None
    shutil.move(run_dir / "model.zip", tmp_path / "lonely.zip")
    assert load_policy(tmp_path / "lonely.zip").name == "sac"


def test_cli_errors(tmp_path, capsys):
    base = ["--out", str(tmp_path), "--no-progress"]
    assert main([*base, "--algo", "dqn"]) == 2
    assert "unknown algorithm" in capsys.readouterr().err
    assert main([*base, "--hyperparams", "not_an_arg=1"]) == 2
    assert "unknown PPO arguments" in capsys.readouterr().err
    assert main([*base, "--env-kwargs", '{"goal_radius": -1}']) == 2
    assert "goal_radius" in capsys.readouterr().err
    assert main([*base, "--env", "PectoralFish-Nothing-v0"]) == 2
    assert not any(tmp_path.iterdir())  # nothing written on bad input


def test_overrides_and_resolution():
    assert parse_overrides(["a=1", "b.c=[32, 32]", "lr=3e-4", "n=1e5", "s=tanh", "f=false"]) == {
        "a": 1, "b": {"c": [32, 32]}, "lr": 3e-4, "n": 100000, "s": "tanh", "f": False}
    with pytest.raises(ValueError, match="key=value"):
        parse_overrides(["novalue"])
    config = resolve_config("ppo", ENV, 0, task="track", hyperparams={"policy_kwargs": {"net_arch": [8]}},
                            env_kwargs={"goal_radius": 0.1})
    assert config["env_kwargs"] == {"task": "track", "transitions": True, "observe_fins": True, "goal_radius": 0.1}
    # nested override replaces one key and keeps the file's others
    assert config["algo_kwargs"]["policy_kwargs"]["net_arch"] == [8]
    assert config["algo_kwargs"]["policy_kwargs"]["activation_fn"] == "nn.Tanh"
    kwargs = algo_kwargs(config)
    assert kwargs["policy_kwargs"]["activation_fn"] is torch.nn.Tanh
    assert kwargs["learning_rate"](1.0) == pytest.approx(1e-3) and kwargs["learning_rate"](0.5) == pytest.approx(5e-4)
    with pytest.raises(ValueError, match="no entry"):
        resolve_config("ppo", "Nope-v0", 0)


def test_on_evaluation_sees_every_evaluation_and_can_stop_the_run(tmp_path):
    from pectoral_gym.agents.training.config import resolve_config as resolve
    from pectoral_gym.agents.training.train import train

    config = resolve("ppo", ENV, seed=3, hyperparams=parse_overrides(TINY + ["n_timesteps=1024"]))
    seen = []

    def stop_after_two(record):
        seen.append(record)
        return len(seen) < 2

    run_dir = train(config, tmp_path / "run", progress=False, on_evaluation=stop_after_two)
    assert len(seen) == 2  # the second report stopped training: no further evaluation
    assert [r["timesteps"] for r in seen] == sorted(r["timesteps"] for r in seen)
    assert seen[-1]["timesteps"] < 1024
    assert all(r["elapsed_s"] > 0 and 0.0 <= r["success"] <= 1.0 for r in seen)
    import json
    stats = json.loads((run_dir / "training.json").read_text())
    assert stats["timesteps"] < 1024 and len(stats["evaluations"]) == 2
    assert (run_dir / "model.zip").is_file()


def test_evaluation_env_resolution():
    from pectoral_gym.agents.training.config import evaluation_env

    shipped = resolve_config("ppo", ENV, 0)  # the shipped file validates on the full model, nominal parameters
    assert evaluation_env(shipped) == ("PectoralFish-Full-v0", {"task": "goal", "observe_fins": True})
    config = resolve_config("ppo", ENV, 0, hyperparams={"env_kwargs": {"randomize": {"body_mass": 0.1},
                                                                       "scaling": "none"},
                                                        "eval_env": None})
    assert config["eval_env"] == ENV  # null: the training env, its arguments but the file's randomize: null
    assert evaluation_env(config) == (ENV, {"task": "goal", "transitions": True, "observe_fins": True,
                                            "scaling": "none"})
    config["eval_env_kwargs"] = {"randomize": {"drag_coef": 0.2}}
    assert evaluation_env(config) == (ENV, {"task": "goal", "randomize": {"drag_coef": 0.2}, "scaling": "none",
                                            "transitions": True, "observe_fins": True})
    config["eval_env"], config["eval_env_kwargs"] = "PectoralFish-Full-v0", {"randomize": None, "wall_penalty": 5}
    # null drops a training argument; the averaged model's own arguments do not reach the full model
    assert evaluation_env(config) == ("PectoralFish-Full-v0", {"task": "goal", "observe_fins": True, "wall_penalty": 5})
    config["eval_env"] = "CartPole-v1"
    with pytest.raises(ValueError, match="eval_env must be one of"):
        evaluation_env(config)
    with pytest.raises(ValueError, match="eval_env_kwargs must be a mapping"):
        resolve_config("ppo", ENV, 0, hyperparams={"eval_env_kwargs": "full"})


def test_best_model_is_selected_on_the_evaluation_env(tmp_path):
    """The kept model's record is what evaluate() gives on the full model (the validation env), episodes seed + 1e6."""
    import json

    from pectoral_gym.agents.training.train import EVAL_SEED_OFFSET, train

    full = "PectoralFish-Full-v0"
    config = resolve_config("ppo", ENV, seed=3, hyperparams=parse_overrides(
        TINY + ["eval_episodes=3", f"eval_env={full}", "eval_env_kwargs={randomize: null}",
                "env_kwargs.randomize={body_mass: 0.1}"]))
    run_dir = train(config, tmp_path / "run", progress=False)
    records = json.loads((run_dir / "training.json").read_text())["evaluations"]
    best = [r for r in records if r["best"]][-1]
    policy = load_policy(run_dir)  # best_model.zip with its statistics
    kwargs = {"task": "goal"}
    on_full = evaluate(policy, full, n_episodes=3, seed=3 + EVAL_SEED_OFFSET, env_kwargs=kwargs)
    assert on_full.metrics["return"].mean == pytest.approx(best["mean_return"], rel=1e-9)
    on_averaged = evaluate(policy, ENV, n_episodes=3, seed=3 + EVAL_SEED_OFFSET, env_kwargs=kwargs)
    assert on_averaged.metrics["return"].mean != pytest.approx(best["mean_return"], rel=1e-6)
