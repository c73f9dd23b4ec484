"""pectoral_gym.agents.studies.sweep.

Parameter spaces, each trial's config, the numba warm-up, two tiny trials on embedded Ray.
"""

import csv
import importlib.util
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from pectoral_gym.agents.studies.sweep_space import grid_points, load_param_space, parse_grid, trial_config
from pectoral_gym.agents.training.config import resolve_config
from pectoral_gym.agents.training.evaluate import DEFAULT_RANDOMIZATION

ENV = "PectoralFish-Averaged-v0"
ROOT = Path(__file__).resolve().parents[1]
# 4 envs x 32 steps: PPO runs to 512 steps; evaluations at 100, ..., 400, then 500 and 512 (after learning), both
# held back to the one report after the model is saved
TINY = ["n_timesteps=500", "n_envs=4", "n_steps=32", "batch_size=64", "n_epochs=1", "eval_freq=100",
        "eval_episodes=2"]
needs_ray = pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="ray[tune] not installed (sweep extra)")


@pytest.fixture(autouse=True)
def _restore_signal_handlers():
    """Ray and Tune install SIGINT/SIGTERM handlers in the calling process and leave them: restore them, so the
    hardware tests' signal checks that later run in the same pytest worker see the default handlers."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


def test_grid_values_split_outside_brackets_and_read_as_yaml():
    space = parse_grid(["seed=0,1,2", "learning_rate=1e-3,3e-4", "policy_kwargs.net_arch=[64, 64],[32]",
                        "env_kwargs.randomize={drag_coef: 0.2, lift_coef: 0.1},null", "task=goal,'a,b'"])
    assert space["seed"] == ("grid", [0, 1, 2])
    assert space["learning_rate"] == ("grid", [1e-3, 3e-4])  # YAML reads 1e-3 as text; taken as a number
    assert space["policy_kwargs.net_arch"] == ("grid", [[64, 64], [32]])
    assert space["env_kwargs.randomize"] == ("grid", [{"drag_coef": 0.2, "lift_coef": 0.1}, None])
    assert space["task"] == ("grid", ["goal", "a,b"])
    for bad in ("seed", "seed=", "=1,2"):
        with pytest.raises(ValueError, match="key=value1,value2"):
            parse_grid([bad])


def test_param_space_file_kinds(tmp_path):
    path = tmp_path / "space.yml"
    path.write_text("seed: [0, 1]\nent_coef: {grid: [0.0, 0.01, 0.02]}\nlearning_rate: {loguniform: [1.0e-4, 1.0e-3]}\n"
                    "n_steps: {choice: [64, 128]}\nn_timesteps: 4096\npolicy_kwargs.net_arch: {value: [16, 16]}\n"
                    "env_kwargs.randomize: {drag_coef: 0.1}\n")
    space = load_param_space(path)
    assert space == {"seed": ("grid", [0, 1]), "ent_coef": ("grid", [0.0, 0.01, 0.02]),
                     "learning_rate": ("loguniform", [1e-4, 1e-3]), "n_steps": ("choice", [64, 128]),
                     "n_timesteps": ("value", 4096), "policy_kwargs.net_arch": ("value", [16, 16]),
                     "env_kwargs.randomize": ("value", {"drag_coef": 0.1})}
    points = grid_points(space)
    assert len(points) == 2 * 3
    assert {(p["seed"], p["ent_coef"]) for p in points} == {(s, e) for s in (0, 1) for e in (0.0, 0.01, 0.02)}
    assert all(p["learning_rate"] == 1e-4 and p["n_steps"] == 64 and p["n_timesteps"] == 4096 for p in points)
    json_path = tmp_path / "space.json"
    json_path.write_text(json.dumps({"seed": [3], "gamma": {"uniform": [0.9, 0.99]}}))
    assert load_param_space(json_path) == {"seed": ("grid", [3]), "gamma": ("uniform", [0.9, 0.99])}


@pytest.mark.parametrize(("text", "match"), [
    ("seed: []", "empty list"),
    ("gamma: {uniform: [0.99, 0.9]}", "low < high"),
    ("learning_rate: {loguniform: [0, 1.0e-3]}", "0 < low"),
    ("gamma: {uniform: [0.9]}", r"\[low, high\] numbers"),
    ("gamma: {normal: [0.9, 0.1]}", "unknown kind 'normal'"),
    ("- seed", "must map keys"),
    ("seed: [0", "not valid YAML"),
])
def test_param_space_errors(tmp_path, text, match):
    path = tmp_path / "space.yml"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_param_space(path)


def test_trial_config_reaches_the_resolved_config():
    config = trial_config("ppo", ENV, {"seed": 7, "ent_coef": 0.02, "policy_kwargs.net_arch": [16],
                                       "env_kwargs.randomize.drag_coef": 0.3, "env_kwargs.time_penalty": 0.5,
                                       "task": "track"}, hyperparams={"n_timesteps": 1000, "ent_coef": 0.1})
    assert config["seed"] == 7 and config["n_timesteps"] == 1000
    assert config["algo_kwargs"]["ent_coef"] == 0.02  # the trial's value over the sweep-wide one
    # the file's policy_kwargs text is read into a dict, and the trial's net_arch replaces its net_arch only
    assert config["algo_kwargs"]["policy_kwargs"]["net_arch"] == [16]
    assert config["algo_kwargs"]["policy_kwargs"]["activation_fn"] == "nn.Tanh"
    assert config["env_kwargs"] == {"task": "track", "randomize": {"drag_coef": 0.3}, "time_penalty": 0.5,
                                    "transitions": True, "observe_fins": True}  # the last two: the file's
    plain = resolve_config("ppo", ENV, 0)
    assert trial_config("ppo", ENV, {}) == plain  # an empty point is the file's config


def test_randomize_scale_scales_the_default_ranges():
    half = trial_config("ppo", ENV, {"randomize_scale": 0.5})["env_kwargs"]["randomize"]
    assert half.keys() == DEFAULT_RANDOMIZATION.keys()
    assert all(half[k] == pytest.approx(DEFAULT_RANDOMIZATION[k] / 2) for k in half)
    assert trial_config("ppo", ENV, {"randomize_scale": 0})["env_kwargs"]["randomize"] is None
    for bad in (-1, 5, "x", True):
        with pytest.raises(ValueError, match="randomize_scale"):
            trial_config("ppo", ENV, {"randomize_scale": bad})
    with pytest.raises(ValueError, match="unknown PPO arguments"):
        trial_config("ppo", ENV, {"not_an_argument": 1})
    with pytest.raises(ValueError, match="seed must be an integer"):
        trial_config("ppo", ENV, {"seed": 0.5})


def test_cli_refuses_bad_spaces_before_starting_ray(tmp_path, capsys):
    from pectoral_gym.agents.studies.sweep import main

    base = ["--out", str(tmp_path), "--hyperparams", *TINY]
    assert main([*base, "--grid", "not_an_argument=1,2"]) == 2
    assert "unknown PPO arguments ['not_an_argument']" in capsys.readouterr().err
    assert main([*base, "--grid", "env_kwargs.randomize.no_such_field=0.1"]) == 2
    assert "unknown FishParams fields ['no_such_field']" in capsys.readouterr().err
    assert main([*base, "eval_freq=0"]) == 2
    assert "eval_freq must be in [1, n_timesteps]" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


@needs_ray
def test_tune_space_maps_kinds():
    from ray import tune

    from pectoral_gym.agents.studies.sweep import tune_space

    space = tune_space({"seed": ("grid", [0, 1]), "lr": ("loguniform", [1e-4, 1e-3]), "n": ("choice", [1, 2]),
                        "k": ("randint", [1, 5]), "g": ("uniform", [0.9, 0.99]), "fixed": ("value", [1, 2])})
    assert space["seed"] == tune.grid_search([0, 1]) and space["fixed"] == [1, 2]
    assert isinstance(space["lr"], tune.search.sample.Float) and space["lr"].lower == 1e-4
    assert isinstance(space["n"], tune.search.sample.Categorical) and space["n"].categories == [1, 2]
    assert isinstance(space["k"], tune.search.sample.Integer) and (space["k"].lower, space["k"].upper) == (1, 5)


_WARM_THEN_TRAIN = """
import json, sys, time
from pathlib import Path
from pectoral_gym.agents.studies.sweep_space import trial_config
tiny = dict(n_timesteps=256, n_envs=4, n_steps=32, batch_size=64, n_epochs=1, eval_freq=128, eval_episodes=3)
config = trial_config("ppo", "PectoralFish-Averaged-v0", {}, hyperparams=tiny)
if sys.argv[1] == "warm":
    from pectoral_gym.agents.studies.sweep import warm_up
    print(json.dumps({"seconds": warm_up(config)}))
else:
    from pectoral_gym.agents.training.train import train
    start = time.perf_counter()
    train(config, Path(sys.argv[2]), progress=False)
    print(json.dumps({"seconds": time.perf_counter() - start}))
"""


def _cache_files(folder):
    return sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*") if p.suffix in (".nbi", ".nbc"))


@pytest.mark.slow
def test_warm_up_compiles_every_kernel_a_training_run_uses(tmp_path):
    cache = tmp_path / "numba"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}

    def run(*args):
        done = subprocess.run([sys.executable, "-c", _WARM_THEN_TRAIN, *args], env=env, capture_output=True,
                              text=True, cwd=tmp_path)
        assert done.returncode == 0, done.stderr[-3000:]
        return json.loads(done.stdout.strip().splitlines()[-1])

    run("warm")
    warmed = _cache_files(cache)
    assert warmed  # the warm-up wrote the cache there
    run("train", str(tmp_path / "run"))
    assert _cache_files(cache) == warmed  # the training run compiled nothing new: it loaded every kernel


@needs_ray
def test_two_tiny_trials_on_an_embedded_ray_and_asha_stops_the_worse(tmp_path, capsys):
    import ray

    from pectoral_gym.agents.studies.sweep import main

    # Two trials, one at a time: the second pays 10 per step (time_penalty), so its mean return at the first
    # rung (100 steps) is far below the first trial's, and ASHA (keep the best half) stops it there.
    argv = ["--grid", "env_kwargs.time_penalty=0.01,10", "--hyperparams", *TINY, "--scheduler", "asha",
            "--reduction-factor", "2", "--max-concurrent", "1", "--num-cpus", "2", "--out", str(tmp_path),
            "--name", "s", "--verbose", "0", "--final-env", "PectoralFish-Full-v0", "--final-episodes", "2"]
    assert main(argv) == 0
    assert not ray.is_initialized()  # the command shut its Ray down
    folder = tmp_path / "s"
    with open(folder / "results.csv") as f:
        rows = {float(r["env_kwargs.time_penalty"]): r for r in csv.DictReader(f)}
    assert rows.keys() == {0.01, 10.0}
    good, bad = rows[0.01], rows[10.0]
    assert good["status"] == "done" and int(good["timesteps"]) == 512 and int(good["evaluations"]) == 5
    assert bad["status"] == "stopped" and int(bad["timesteps"]) == 100 and int(bad["evaluations"]) == 1
    # 10 per step: two steps of it outweigh the goal bonus (10), so the gap is large whatever the policy does
    assert float(bad["mean_return"]) < float(good["mean_return"]) - 10
    for row in (good, bad):
        assert float(row["env_ready_s"]) > 0
        run = Path(row["path"]) / "run"
        assert (run / "config.yaml").is_file() and (run / "best_model.zip").is_file()
    assert (Path(good["path"]) / "run" / "model.zip").is_file()
    # the trial that ran out was evaluated on the full model at the end; the stopped one was not
    from pectoral_gym.agents.studies.sweep import FINAL_SEED
    from pectoral_gym.agents.training.evaluate import evaluate
    from pectoral_gym.agents.training.policy import load_policy

    again = evaluate(load_policy(Path(good["path"]) / "run"), "PectoralFish-Full-v0", n_episodes=2, seed=FINAL_SEED,
                     env_kwargs={"task": "goal", "time_penalty": 0.01})
    assert float(good["final_mean_return"]) == pytest.approx(again.metrics["return"].mean, rel=1e-9)
    assert float(good["final_success"]) == pytest.approx(again.metrics["success"].mean)
    assert bad["final_success"] == ""
    assert json.loads((Path(good["path"]) / "run" / "training.json").read_text())["timesteps"] == 512
    assert (folder / "results.png").stat().st_size > 0
    assert "| stopped |" in (folder / "results.md").read_text()
    assert "results.md" not in capsys.readouterr().err


def test_help_names_the_defaults(capsys):
    from pectoral_gym.agents.studies.sweep import main

    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    for option in ("--param-space", "--grid", "--scheduler", "--address", "--num-cpus", "--numba-cache-dir",
                   "--metric", "mean_return"):
        assert option in text


@needs_ray
def test_result_rows_status_and_tables(tmp_path):
    import math
    from types import SimpleNamespace

    import pandas as pd

    from pectoral_gym.agents.studies.sweep_results import format_markdown, plot_results, result_rows, write_tables

    def result(trial, history, error=None, seed=0):
        return SimpleNamespace(metrics={"trial_id": trial} if history else {}, config={"seed": seed},
                               metrics_dataframe=pd.DataFrame(history), error=error, path=str(tmp_path / trial))

    evals = [{"timesteps": 100, "n_timesteps": 300, "success": 0.2, "mean_return": -5.0, "elapsed_s": 1.0},
             {"timesteps": 200, "n_timesteps": 300, "success": 0.6, "mean_return": -1.0, "elapsed_s": 2.0},
             {"timesteps": 300, "n_timesteps": 300, "success": 0.4, "mean_return": -2.0, "elapsed_s": 3.0,
              "final_success": 0.5}]
    rows = result_rows([result("a", evals), result("b", evals[:1], seed=1), result("c", [], error=RuntimeError("x"))],
                       ["seed"], "success")
    a, b, c = rows
    assert (a["status"], b["status"], c["status"]) == ("done", "stopped", "error")
    assert (a["success"], a["best_success"], a["best_mean_return"], a["evaluations"]) == (0.4, 0.6, -1.0, 3)
    assert a["final_success"] == 0.5 and "final_success" not in b
    assert a["curve"] == [(100, 0.2), (200, 0.6), (300, 0.4)]
    assert math.isnan(c["success"]) and c["evaluations"] == 0
    text = format_markdown(rows)
    assert text.splitlines()[0].split(" | ")[-1] == "final_success |"  # the union of the rows' columns
    assert text.count("\n") == 2 + 3
    write_tables(rows, tmp_path)
    plot_results(rows, tmp_path / "results.png", "success")
    with open(tmp_path / "results.csv") as f:
        table = list(csv.DictReader(f))
    assert [r["status"] for r in table] == ["done", "stopped", "error"] and table[0]["final_success"] == "0.5"
    assert table[1]["final_success"] == "" and (tmp_path / "results.png").stat().st_size > 0
