import json

import pytest

from pectoral_gym.agents.studies import benchmark
from pectoral_gym.agents.studies.benchmark import (
    ENVS,
    TASKS,
    BenchmarkSettings,
    run_benchmark,
    to_markdown,
    write_outputs,
)


def test_small_benchmark_writes_a_row_per_cell(tmp_path):
    settings = BenchmarkSettings(episodes=2, max_episode_steps=3, train_steps=0)
    report = run_benchmark(settings, controllers=("random", "hand"), envs=("averaged",), throughput=False)
    rows = {(c["controller"], c["env"], c["task"]) for c in report["cells"]}
    assert rows == {(name, "averaged", task) for name in ("random", "hand") for task in TASKS}
    write_outputs(report, tmp_path, plots=False)
    markdown = (tmp_path / "benchmark.md").read_text()
    for name in ("random", "hand"):
        assert markdown.count(f"| {name} | averaged | 2 |") == 2  # one row per task
    assert not (tmp_path / "benchmark.png").exists()


@pytest.mark.slow
def test_tiny_benchmark_has_every_row(tmp_path):
    settings = BenchmarkSettings(episodes=2, nmpc_episodes={"goal": 1, "track": 1}, max_episode_steps=3,
                                 nmpc={"horizon": 3, "blocks": (1, 1, 1), "substeps": 4}, train_steps=0)
    report = run_benchmark(settings, throughput=False)
    assert report["errors"] == {}
    rows = {(c["controller"], c["env"], c["task"]) for c in report["cells"]}
    expected = {(name, env, task) for name in ("random", "hand", "nmpc") for env in ENVS for task in TASKS}
    assert rows == expected
    for cell in report["cells"]:
        n = 1 if cell["controller"] == "nmpc" else 2
        assert cell["n_episodes"] == n
        assert cell["metrics"]["length"]["mean"] <= 3  # truncated after max_episode_steps
        if cell["controller"] == "nmpc":
            assert cell["solver"]["solves"] >= 1
        if cell["env"] == "full+rand":
            assert cell["env_kwargs"]["randomize"]
    paths = write_outputs(report, tmp_path)
    assert [p.name for p in paths] == ["benchmark.json", "benchmark.md", "benchmark.png"]
    assert json.loads((tmp_path / "benchmark.json").read_text())["cells"] == json.loads(json.dumps(report["cells"]))
    markdown = (tmp_path / "benchmark.md").read_text()
    table_rows = [line for line in markdown.splitlines() if line.startswith("| ") and not line.startswith("| con")]
    for name, env, task in expected:
        assert any(line.startswith(f"| {name} | {env} |") for line in table_rows), (name, env, task)
    assert "## Task `goal`" in markdown and "## Task `track`" in markdown
    assert "NMPC solve times" in markdown


def test_markdown_reports_throughput_and_errors():
    report = {
        "settings": {"episodes": 1, "nmpc_episodes": {"goal": 1}, "max_episode_steps": None, "seed": 0},
        "cells": [],
        "env_throughput": {"single_env": {"A": 1000.0}, "vector_env": {"A": 2e6}, "num_envs": {"A": 4096}},
        "training_throughput": {"env_id": "A", "n_envs": 32, "timesteps": 8192, "steps_per_s": 1234.5},
        "errors": {"nmpc/full/goal": "RuntimeError: boom"},
    }
    text = to_markdown(report)
    assert "| single env `A` | 1,000 steps/s |" in text
    assert "2,000,000 env-steps/s" in text
    assert "1,234 steps/s" in text or "1,235 steps/s" in text
    assert "RuntimeError: boom" in text


def test_cli_rejects_bad_sizes_and_unknown_names(tmp_path, capsys):
    assert benchmark.main(["--quick", "--episodes", "0", "--out", str(tmp_path)]) == 2
    assert "error" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        benchmark.main(["--controllers", "pid"])
    with pytest.raises(ValueError, match="unknown"):
        run_benchmark(BenchmarkSettings(), controllers=("pid",))


@pytest.mark.slow
def test_training_throughput_measures_a_short_ppo_run():
    result = benchmark.measure_training(steps=1)
    # PPO collects at least one full rollout (n_steps x n_envs) before it can stop
    assert result["timesteps"] >= result["n_envs"]
    assert result["steps_per_s"] > 0


def test_a_policy_is_benchmarked_on_the_model_settings_it_trained_with(tmp_path, monkeypatch):
    # A run folder trained with transitions and the fin block: its averaged cell keeps both, its full cells drop
    # the averaged-only transitions; the cell still decides task and randomisation.
    import pectoral_gym.agents.training.evaluate
    import pectoral_gym.agents.training.policy

    run = tmp_path / "run"
    run.mkdir()
    monkeypatch.setattr(pectoral_gym.agents.training.policy, "load_policy", lambda path: object())
    monkeypatch.setattr(pectoral_gym.agents.training.policy, "read_config", lambda path: {"env_kwargs": {
        "task": "track", "transitions": True, "observe_fins": True, "randomize": {"drag_coef": 0.3}}})
    seen = {}

    def fake_evaluate(controller, env_id, n_episodes, seed, env_kwargs):
        seen[(env_id, bool(env_kwargs.get("randomize")))] = dict(env_kwargs)
        raise RuntimeError("recorded")  # the benchmark keeps the error per cell and goes on

    monkeypatch.setattr(pectoral_gym.agents.training.evaluate, "evaluate", fake_evaluate)
    report = run_benchmark(BenchmarkSettings(episodes=1, train_steps=0), controllers=(), tasks=("goal",),
                           policies=[str(run)], throughput=False)
    assert len(report["errors"]) == 3
    assert seen[("PectoralFish-Averaged-v0", False)] == {"task": "goal", "transitions": True, "observe_fins": True}
    assert seen[("PectoralFish-Full-v0", False)] == {"task": "goal", "observe_fins": True}
    full_rand = seen[("PectoralFish-Full-v0", True)]
    assert full_rand["observe_fins"] and "transitions" not in full_rand and full_rand["task"] == "goal"
