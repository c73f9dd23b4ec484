"""Time to solve.

The probe's logic with a scripted evaluation, and its place in pectoral_gym.agents.training.train.train.
"""

import json
import types

import numpy as np
import pytest

import pectoral_gym.agents.training.evaluate
from pectoral_gym.agents.studies.solve_time import PROBE_SEED, REPORT_SEED, SolveProbe
from pectoral_gym.agents.training.config import parse_overrides, resolve_config
from pectoral_gym.agents.training.metrics import MetricSummary
from pectoral_gym.agents.training.policy import load_policy
from pectoral_gym.agents.training.train import train

ENV = "PectoralFish-Averaged-v0"
TINY = ["n_timesteps=1024", "n_envs=4", "n_steps=32", "batch_size=64", "n_epochs=1", "eval_freq=256",
        "eval_episodes=2"]


class _Scripted:
    """Stands in for pectoral_gym.agents.training.evaluate.evaluate.

    The next success rate of a script, and a log of the calls.
    """

    def __init__(self, successes):
        self.successes = list(successes)
        self.calls = []

    def __call__(self, controller, env_id, n_episodes, seed, env_kwargs):
        self.calls.append({"env_id": env_id, "n_episodes": n_episodes, "seed": seed, "env_kwargs": env_kwargs})
        value = self.successes.pop(0)
        return types.SimpleNamespace(metrics={"success": MetricSummary(value, value, value, n_episodes)})


def _record(k):
    return {"timesteps": 1000 * k, "elapsed_s": 10.0 * k, "success": 0.0, "mean_return": 0.0, "best": False}


def test_first_probe_at_the_threshold_solves_and_is_confirmed_on_other_episodes(monkeypatch):
    script = _Scripted([0.90, 0.94, 0.95, 0.91])  # the 4th is the confirmation of the 3rd
    monkeypatch.setattr(pectoral_gym.agents.training.evaluate, "evaluate", script)
    probe = SolveProbe(episodes=20, confirm_episodes=30, stop_on_solve=True, env_kwargs={"task": "goal",
                                                                                          "randomize": {"a": 1}})
    for k in range(1, 6):
        result = probe(object(), _record(k))
        if k <= 3:
            assert result is not None and result["timesteps"] == 1000 * k
        else:
            assert result is None  # solved: no more probes
        assert probe.on_evaluation(_record(k)) == (k < 3)
    summary = probe.summary()
    assert summary["solved"] and summary["time_to_solve_s"] == 30.0 and summary["steps_to_solve"] == 3000
    assert summary["probe_success"] == 0.95 and summary["confirm_success"] == 0.91
    assert summary["best_probe_success"] == 0.95 and len(summary["probes"]) == 3
    assert [c["seed"] for c in script.calls] == [PROBE_SEED] * 3 + [REPORT_SEED]
    assert [c["n_episodes"] for c in script.calls] == [20, 20, 20, 30]
    assert all(c["env_id"] == "PectoralFish-Full-v2" and "randomize" not in c["env_kwargs"] for c in script.calls)


def test_keep_probing_after_the_solve_keeps_the_first_solve(monkeypatch):
    script = _Scripted([0.96, 0.93, 0.5, 0.97])  # the 2nd is the confirmation of the 1st
    monkeypatch.setattr(pectoral_gym.agents.training.evaluate, "evaluate", script)
    probe = SolveProbe(keep_probing=True)
    assert all(probe(object(), _record(k)) is not None for k in (1, 2, 3))
    summary = probe.summary()
    assert summary["steps_to_solve"] == 1000 and summary["confirm_success"] == 0.93
    assert [p["success"] for p in summary["probes"]] == [0.96, 0.5, 0.97] and summary["best_probe_success"] == 0.97
    assert len(script.calls) == 4  # one confirmation only


def test_probe_every_kth_evaluation_and_never_solved(monkeypatch):
    script = _Scripted([0.5, 0.6, 0.7])
    monkeypatch.setattr(pectoral_gym.agents.training.evaluate, "evaluate", script)
    probe = SolveProbe(every=2, episodes=5)
    returned = [probe(object(), _record(k)) for k in range(1, 7)]
    assert [r is not None for r in returned] == [True, False, True, False, True, False]
    summary = probe.summary()
    assert not summary["solved"] and summary["time_to_solve_s"] is None and summary["best_probe_success"] == 0.7
    assert probe.on_evaluation(_record(7)) is True  # not solved: never stops training


def test_probe_arguments_are_checked():
    with pytest.raises(ValueError, match="threshold"):
        SolveProbe(threshold=0.0)
    with pytest.raises(ValueError, match="every"):
        SolveProbe(every=0)
    with pytest.raises(ValueError, match="goal task"):
        SolveProbe(env_kwargs={"task": "track"})


def test_a_probe_neither_changes_training_nor_counts_in_its_elapsed_time(tmp_path, monkeypatch):
    config = resolve_config("ppo", ENV, seed=4, hyperparams=parse_overrides(TINY))
    plain = train(config, tmp_path / "plain", progress=False)

    clock = {"t": 0.0}

    def perf_counter():
        clock["t"] += 1.0  # every reading of the training clock moves it by one
        return clock["t"]

    monkeypatch.setattr("pectoral_gym.agents.training.train.time", types.SimpleNamespace(perf_counter=perf_counter))
    seen = []

    def probe(controller, record):
        clock["t"] += 1e6  # the probe "takes" a million clock units
        actions = controller.act_batch(np.zeros((2, controller.obs_size), dtype=np.float32))
        seen.append(actions.shape)
        return {"k": len(seen)}

    probed = train(config, tmp_path / "probed", progress=False, probe=probe)
    stats = json.loads((probed / "training.json").read_text())
    assert len(seen) == len(stats["evaluations"]) >= 3 and seen[0] == (2, 8)
    assert [e["probe"]["k"] for e in stats["evaluations"]] == list(range(1, len(seen) + 1))
    assert all(e["elapsed_s"] < 1e6 for e in stats["evaluations"])  # the probes' time is left out
    assert stats["probe_time_s"] >= 1e6 * len(seen)
    a, b = load_policy(plain / "model.zip"), load_policy(probed / "model.zip")
    for pa, pb in zip(a.model.policy.parameters(), b.model.policy.parameters(), strict=True):
        assert np.array_equal(pa.detach().numpy(), pb.detach().numpy())  # the probe changed nothing in training


def test_benchmark_time_to_solve_trains_probes_and_reports(tmp_path, monkeypatch):
    import pectoral_gym.agents.studies.solve_time
    from pectoral_gym.agents.studies.benchmark import BenchmarkSettings, run_benchmark, to_markdown

    measure = pectoral_gym.agents.studies.solve_time.measure_time_to_solve
    small = {"n_envs": 4, "n_steps": 64, "batch_size": 128, "n_epochs": 1, "eval_freq": 256, "eval_episodes": 2}
    monkeypatch.setattr(pectoral_gym.agents.studies.solve_time, "measure_time_to_solve",
                        lambda *args, **kwargs: measure(*args, **kwargs, hyperparams=small))  # a smaller network run

    settings = BenchmarkSettings(episodes=1, max_episode_steps=2, train_steps=0, solve_seeds=(2,),
                                 solve_timesteps=1024, solve_episodes=2)
    report = run_benchmark(settings, controllers=("random",), envs=("averaged",), tasks=("goal",),
                           throughput=False, solve_out=tmp_path / "solve")
    assert report["errors"] == {}
    solve = report["time_to_solve"]
    assert solve["settings"]["seeds"] == [2] and solve["settings"]["probe_episodes"] == 2
    (run,) = solve["runs"]
    assert run["seed"] == 2 and 1 <= len(run["probes"]) <= 4  # one probe per periodic evaluation until solved
    assert run["solved"] == (run["time_to_solve_s"] is not None)
    assert list((tmp_path / "solve").glob("*/seed2/model.zip"))
    assert "## Time to solve" in to_markdown(report) and "| 2 |" in to_markdown(report)


def test_time_to_solve_markdown_by_hand():
    from pectoral_gym.agents.studies.benchmark_report import to_markdown

    settings = {"n_timesteps": 800000, "every": 1, "eval_freq": 50000, "probe_episodes": 100, "probe_seed": 20000,
                "threshold": 0.95, "confirm_episodes": 100, "confirm_seed": 10000, "jobs": 1}
    runs = [{"seed": 0, "solved": True, "time_to_solve_s": 30.0, "steps_to_solve": 400000, "probe_success": 0.96,
             "confirm_success": 0.93, "best_probe_success": 0.96},
            {"seed": 1, "solved": False, "time_to_solve_s": None, "steps_to_solve": None, "probe_success": None,
             "confirm_success": None, "best_probe_success": 0.9},
            {"seed": 2, "solved": True, "time_to_solve_s": 50.0, "steps_to_solve": 650000, "probe_success": 0.95,
             "confirm_success": 0.97, "best_probe_success": 0.95}]
    report = {"settings": {"episodes": 1, "nmpc_episodes": {}, "max_episode_steps": None, "seed": 0}, "cells": [],
              "time_to_solve": {"settings": settings, "runs": runs}}
    text = to_markdown(report)
    assert "| 0 | yes | 30 | 400000 | 0.96 | 0.93 | 0.96 |" in text
    assert "| 1 | no | - | - | - | - | 0.90 |" in text
    assert "Solved: 2 of 3 seeds within the budget; median time of the solved runs 40 s." in text
