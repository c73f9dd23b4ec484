"""The hyperparameter files in rl-baselines3-zoo's format: zoo's rules, the Python-text parser, the project
section, the demo's hyperparameters reaching SB3 unchanged, and zoo's own train on the shipped file."""

import importlib.util
import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml
from doc_snippets import commands, snippet

from pectoral_gym.agents.training.config import algo_kwargs, resolve_config
from pectoral_gym.agents.training.zoo_format import (
    HYPERPARAMS_DIR,
    load_hyperparams,
    load_project_settings,
    parse_python_kwargs,
    zoo_problems,
)
from pectoral_gym.versions import ENV_VERSIONS, LATEST, LATEST_AVERAGED, LATEST_FULL, SIMULATION_IDS

ENV = "PectoralFish-Averaged-v0"
ROOT = Path(__file__).resolve().parents[1]


def _doc_argv(line):
    """A command of the docs as argv: this interpreter for ``python`` and its environment's console scripts, the
    repository's hyperparameter files."""
    argv = shlex.split(line)
    assert argv[0] == "python" or argv[0].startswith("pectoral-"), line
    program = [sys.executable] if argv[0] == "python" else [str(Path(sys.executable).parent / argv[0])]
    return [*program, *(str(ROOT / a) if a.startswith("agents/hyperparams/") else a for a in argv[1:])]


def _option(argv, name):
    """The value after ``name`` in ``argv``."""
    return argv[argv.index(name) + 1]


def write(tmp_path, table, name="ppo.yml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(table))
    return path


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_shipped_files_follow_zoo_rules(algo):
    assert zoo_problems(algo) == []
    table = yaml.safe_load((HYPERPARAMS_DIR / f"{algo}.yml").read_text())
    for env_id in ("PectoralFish-Averaged-v0", "PectoralFish-Full-v0"):
        entry = table[env_id]
        assert "eval_freq" not in entry and "eval_episodes" not in entry  # zoo would pass them to the algorithm
        assert isinstance(entry["policy_kwargs"], str)  # zoo evaluates the text; a dict would reach SB3 as is
        assert table["agents.train"][env_id]["eval_freq"] > 0


def test_zoo_problems_names_what_zoo_refuses(tmp_path):
    old = {ENV: {"n_timesteps": 100, "eval_freq": 10, "learning_rate": "lin_1e-3",
                 "policy_kwargs": {"net_arch": [8], "activation_fn": "tanh"}},
           "Other-v0": {"clip_range": "linear_0.2_x", "policy_kwargs": "dict(net_arch=[8], f=open('x'))"}}
    problems = "\n".join(zoo_problems("ppo", write(tmp_path, old)))
    assert "'eval_freq' is not a PPO argument" in problems
    assert "policy_kwargs.activation_fn is text in a dict" in problems
    assert "Other-v0: no n_timesteps" in problems
    assert "clip_range 'linear_0.2_x' is not a zoo schedule" in problems
    assert "cannot read \"open('x')\"" in problems
    assert "learning_rate" not in problems  # lin_1e-3 is a zoo schedule
    assert len(zoo_problems("ppo", write(tmp_path, old))) == 5


def test_parse_python_kwargs_reads_without_evaluating():
    assert parse_python_kwargs("dict(net_arch=dict(pi=[64, 64], vf=[64]), activation_fn=nn.Tanh, log_std_init=-0.5)") \
        == {"net_arch": {"pi": [64, 64], "vf": [64]}, "activation_fn": "nn.Tanh", "log_std_init": -0.5}
    assert parse_python_kwargs("{'norm_obs': True, 'clip_obs': 10.0, 'x': None}") == {
        "norm_obs": True, "clip_obs": 10.0, "x": None}
    assert parse_python_kwargs(" dict(optimizer_class=th.optim.Adam, net_arch=(8, 8)) ") == {
        "optimizer_class": "th.optim.Adam", "net_arch": [8, 8]}
    for text in ("__import__('os').system('true')", "dict(a=lambda: 1)", "dict(a=os.sep)", "dict(**x)",
                 "[1, 2]", "dict(a=", "dict(a=-'x')"):
        with pytest.raises(ValueError):
            parse_python_kwargs(text)


def test_demo_hyperparameters_reach_sb3_unchanged():
    # the demo's PPO (seed 0): the values of agents/hyperparams/ppo.yml, as SB3 must receive them
    config = resolve_config("ppo", ENV, 0, task="goal")
    assert {k: config[k] for k in ("n_envs", "n_timesteps", "policy", "normalize", "env_kwargs", "eval_freq",
                                   "eval_episodes")} == {
        "n_envs": 32, "n_timesteps": 1600000, "policy": "MlpPolicy",
        "normalize": {"norm_obs": True, "norm_reward": False, "clip_obs": 10.0},
        "env_kwargs": {"task": "goal", "transitions": True, "observe_fins": True},
        "eval_freq": 50000, "eval_episodes": 50}
    kwargs = algo_kwargs(config)
    schedule = kwargs.pop("learning_rate")
    assert [schedule(p) for p in (1.0, 0.5, 0.0)] == pytest.approx([1e-3, 5e-4, 0.0])
    assert kwargs == {"n_steps": 256, "batch_size": 512, "n_epochs": 5, "gamma": 0.995, "gae_lambda": 0.95,
                      "clip_range": 0.2, "ent_coef": 0.005, "max_grad_norm": 0.5,
                      "policy_kwargs": {"net_arch": {"pi": [64, 64], "vf": [64, 64]}, "activation_fn": torch.nn.Tanh,
                                        "log_std_init": -0.5}}
    sac = algo_kwargs(resolve_config("sac", "PectoralFish-Full-v0", 0))
    assert sac["policy_kwargs"] == {"net_arch": [128, 128]} and sac["learning_rate"] == 1e-3


def test_project_section_and_old_format(tmp_path):
    assert load_project_settings("ppo", ENV) == {"eval_freq": 50000, "eval_episodes": 50,
                                                 "eval_env": "PectoralFish-Full-v0",
                                                 "eval_env_kwargs": {"randomize": None}}
    assert load_project_settings("ppo", "PectoralFish-Full-v0") == {"eval_freq": 50000, "eval_episodes": 50}
    assert "agents.train" not in str(load_hyperparams("ppo", ENV))
    with pytest.raises(ValueError, match="no entry"):
        load_hyperparams("ppo", "agents.train")
    config = resolve_config("ppo", ENV, 0, hyperparams={"eval_freq": 0})
    assert config["eval_freq"] == 0 and config["eval_episodes"] == 50
    bad = write(tmp_path, {ENV: {"n_timesteps": 64}, "agents.train": {ENV: {"eval_freq": 8, "save_freq": 1}}})
    with pytest.raises(ValueError, match=r"unknown keys \['save_freq'\]"):
        resolve_config("ppo", ENV, 0, hyperparams_file=bad)
    # a file of the old format still trains with pectoral_gym.agents.training.train (zoo_problems names why zoo refuses
    # it)
    old = write(tmp_path, {ENV: {"n_timesteps": 64, "eval_freq": 8, "normalize": "dict(norm_obs=True)",
                                 "policy_kwargs": {"activation_fn": "relu", "optimizer_class": "th.optim.RMSprop"}}},
                "old.yml")
    config = resolve_config("ppo", ENV, 0, hyperparams_file=old)
    assert config["eval_freq"] == 8 and config["normalize"] == {"norm_obs": True}
    policy_kwargs = algo_kwargs(config)["policy_kwargs"]
    assert policy_kwargs == {"activation_fn": torch.nn.ReLU, "optimizer_class": torch.optim.RMSprop}
    with pytest.raises(ValueError, match="not a torch class"):
        algo_kwargs(resolve_config("ppo", ENV, 0, hyperparams={"policy_kwargs": {"activation_fn": "nn.NoSuch"}}))
    with pytest.raises(ValueError, match=r"zoo keys \['env_wrapper'\] are not supported"):
        resolve_config("ppo", ENV, 0, hyperparams={"env_wrapper": "gymnasium.wrappers.TimeAwareObservation"})


# Loading a zoo model unpickles rl_zoo3's schedule objects, and importing rl_zoo3 patches gymnasium's TimeLimit
# (an extra "TimeLimit.truncated" info key) for the whole process: the loading runs in a child process.
_LOAD = """
import json, sys
import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
import pectoral_gym

env_id, zip_path, stats_path = sys.argv[1:]
model = PPO.load(zip_path, device="cpu")
stats = VecNormalize.load(stats_path, DummyVecEnv([lambda: gym.make(env_id, observe_fins=True)]))
action, _ = model.predict(stats.normalize_obs(np.zeros((1, 27), dtype=np.float32)), deterministic=True)
extractor = model.policy.mlp_extractor
print(json.dumps({
    "num_timesteps": model.num_timesteps, "n_envs": model.n_envs, "n_steps": model.n_steps,
    "batch_size": model.batch_size, "gamma": model.gamma, "gae_lambda": model.gae_lambda,
    "ent_coef": model.ent_coef, "lr": [model.lr_schedule(1.0), model.lr_schedule(0.5)],
    "clip_range": model.clip_range(1.0), "activation": model.policy.activation_fn.__name__,
    "pi": [m.out_features for m in extractor.policy_net if isinstance(m, torch.nn.Linear)],
    "vf": [m.out_features for m in extractor.value_net if isinstance(m, torch.nn.Linear)],
    "norm_obs": stats.norm_obs, "norm_reward": stats.norm_reward, "clip_obs": stats.clip_obs,
    "stats_gamma": stats.gamma, "action_shape": list(action.shape), "action_max": float(np.abs(action).max()),
}))
"""


# pectoral_gym.agents.training.policy.load_policy on zoo's layout (<env>.zip, best_model.zip, <env>/vecnormalize.pkl),
# checked against the zip and the statistics loaded by SB3 itself.
_LOAD_POLICY = """
import json, sys
import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
import pectoral_gym
from pectoral_gym.agents.training.policy import load_policy

env_id, run_dir = sys.argv[1:]
stats = VecNormalize.load(f"{run_dir}/{env_id}/vecnormalize.pkl",
                          DummyVecEnv([lambda: gym.make(env_id, observe_fins=True)]))
obs = np.random.default_rng(0).normal(size=(6, 27)).astype(np.float32) * 3  # the shipped file observes the fins
out = {}
for name, target, zip_name in (("dir", run_dir, f"{env_id}.zip"), ("final", f"{run_dir}/{env_id}.zip", f"{env_id}.zip"),
                               ("best", f"{run_dir}/best_model.zip", "best_model.zip")):
    policy = load_policy(target)
    model = PPO.load(f"{run_dir}/{zip_name}", device="cpu")
    expected, _ = model.predict(stats.normalize_obs(obs), deterministic=True)
    unnormalized, _ = model.predict(obs, deterministic=True)
    out[name] = {"mean": bool(np.allclose(policy.obs_mean, stats.obs_rms.mean)), "name": policy.name,
                 "same": bool(np.allclose(policy.act_batch(obs), np.clip(expected, -1, 1), atol=1e-6)),
                 "differs_unnormalized": bool(not np.allclose(np.clip(unnormalized, -1, 1), np.clip(expected, -1, 1)))}
print(json.dumps(out))
"""


@pytest.mark.skipif(importlib.util.find_spec("rl_zoo3") is None, reason="rl_zoo3 not installed (dev extra)")
def test_zoo_trains_from_the_shipped_file(tmp_path):
    # the commands of docs/guide/trainers.md's zoo snippet, as written, with smaller sizes appended (zoo's argparse
    # keeps the last -n, --eval-freq, --eval-episodes and --hyperparams)
    train_cmd, enjoy_cmd, evaluate_cmd = [_doc_argv(line) for line in commands(snippet("zoo"))]
    assert train_cmd[:3] == [sys.executable, "-m", "rl_zoo3.train"] and "--conf-file" in train_cmd
    env_id = _option(train_cmd, "--env")
    assert env_id == LATEST_AVERAGED  # the recipe trains the latest id
    eval_id = _option(evaluate_cmd, "--env")
    command = [*train_cmd, "-n", "512", "--eval-freq", "256", "--eval-episodes", "2", "--hyperparams", "n_envs:2",
               "n_steps:64", "batch_size:64", "n_epochs:1"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "logs").is_dir()  # the snippet's -f logs
    run_dir = tmp_path / "logs" / "ppo" / f"{env_id}_1"
    assert (run_dir / "best_model.zip").is_file()  # zoo's evaluation, from its command line
    done = subprocess.run([sys.executable, "-c", _LOAD, env_id, str(run_dir / f"{env_id}.zip"),
                           str(run_dir / env_id / "vecnormalize.pkl")], cwd=tmp_path, env=env, capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    model = json.loads(done.stdout.strip().splitlines()[-1])
    # the file's values reached SB3 (the four overridden ones from zoo's --hyperparams)
    assert (model["num_timesteps"], model["n_envs"], model["n_steps"], model["batch_size"]) == (512, 2, 64, 64)
    assert (model["gamma"], model["gae_lambda"], model["ent_coef"], model["clip_range"]) == (0.995, 0.95, 0.005, 0.2)
    assert model["lr"] == pytest.approx([1e-3, 5e-4])
    assert model["activation"] == "Tanh" and model["pi"] == [64, 64] and model["vf"] == [64, 64]
    assert model["norm_obs"] and not model["norm_reward"] and model["clip_obs"] == 10.0
    assert model["stats_gamma"] == 0.995
    assert model["action_shape"] == [1, 8] and model["action_max"] <= 1.0
    done = subprocess.run([sys.executable, "-c", _LOAD_POLICY, env_id, str(run_dir)], cwd=tmp_path, env=env,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    loaded = json.loads(done.stdout.strip().splitlines()[-1])
    for case in ("dir", "final", "best"):  # the run folder (its final zip), the final zip, the best zip
        assert loaded[case]["mean"] and loaded[case]["same"] and loaded[case]["name"] == "ppo", (case, loaded)
        assert loaded[case]["differs_unnormalized"], case  # the statistics matter, so the check can fail
    saved = yaml.unsafe_load((run_dir / env_id / "config.yml").read_text())
    assert dict(saved)["policy_kwargs"] == load_hyperparams("ppo", env_id)["policy_kwargs"]
    done = subprocess.run([*enjoy_cmd, "-n", "50"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Loading running average" in done.stdout  # zoo found the statistics next to the model
    done = subprocess.run([*evaluate_cmd, "--episodes", "2", "--out", str(tmp_path / "eval")], cwd=tmp_path, env=env,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    metrics = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert metrics["env_id"] == eval_id == LATEST_FULL and metrics["n_episodes"] == 2, metrics.keys()
    assert "rl_zoo3" not in sys.modules  # this process stays unpatched


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_file_env_kwargs_agree_with_the_versions_table(algo):
    # one source of truth: an id's settings are ENV_VERSIONS'; an entry's env_kwargs may pick the task, and a -v0
    # (simulation-only) entry may take the latest version's observation and model options, nothing else
    table = yaml.safe_load((HYPERPARAMS_DIR / f"{algo}.yml").read_text())
    assert set(ENV_VERSIONS) <= set(table) and set(ENV_VERSIONS) <= set(table["agents.train"])
    simulation = set(SIMULATION_IDS.values())
    for env_id, version in ENV_VERSIONS.items():
        settings = version.settings()
        latest = ENV_VERSIONS[LATEST[settings["model"]]].settings()
        env_kwargs = dict(table[env_id].get("env_kwargs", {}))
        assert env_kwargs.pop("task", "goal") == "goal", env_id
        for key, value in env_kwargs.items():
            assert key in settings, (env_id, key)  # an EnvConfig setting the table names
            if env_id in simulation:
                assert value == latest[key], (env_id, key, value, latest[key])
            else:
                assert value == settings[key], (env_id, key, value, settings[key])  # no override of the id's own


# rl_zoo3's own train, up to its callbacks: the EvalCallback it builds from the snippet's command, then no training.
_ZOO_CALLBACKS = """
import json, sys
from stable_baselines3.common.callbacks import EvalCallback
import rl_zoo3.train
from rl_zoo3.exp_manager import ExperimentManager

def report(self, model):
    (evaluation,) = [c for c in self.callbacks if isinstance(c, EvalCallback)]
    print(json.dumps({"n_envs": model.n_envs, "eval_freq": evaluation.eval_freq,
                      "n_eval_episodes": evaluation.n_eval_episodes}))

ExperimentManager.learn = report
ExperimentManager.save_trained_model = lambda self, model: None
sys.argv = ["rl_zoo3.train", *sys.argv[1:]]
rl_zoo3.train.train()
"""


@pytest.mark.skipif(importlib.util.find_spec("rl_zoo3") is None, reason="rl_zoo3 not installed (dev extra)")
def test_zoo_snippet_evaluates_as_often_as_the_file_says(tmp_path):
    # zoo divides --eval-freq by n_envs (rl_zoo3/exp_manager.py, create_callbacks): the snippet's value must be the
    # file's eval_freq in env steps in all, not per env
    train_cmd = _doc_argv(commands(snippet("zoo"))[0])
    env_id = _option(train_cmd, "--env")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run([sys.executable, "-c", _ZOO_CALLBACKS, *train_cmd[3:]], cwd=tmp_path, env=env,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    built = json.loads(done.stdout.strip().splitlines()[-1])
    wanted = load_project_settings("ppo", env_id)
    assert built["n_envs"] == load_hyperparams("ppo", env_id)["n_envs"] == 32
    period = built["eval_freq"] * built["n_envs"]  # EvalCallback counts vector steps, each n_envs env steps
    assert wanted["eval_freq"] - built["n_envs"] < period <= wanted["eval_freq"], (period, wanted)
    assert built["n_eval_episodes"] == wanted["eval_episodes"]
