import dataclasses
import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from pectoral_gym.agents.studies import benchmark
from pectoral_gym.agents.studies.benchmark import (
    ALL_ENVS,
    ENVS,
    PRESETS,
    TASKS,
    BenchmarkSettings,
    run_benchmark,
    to_markdown,
    write_outputs,
)
from pectoral_gym.hardware.studies.deployment import (
    DEGRADED,
    ROBOT_CONDITIONS,
    conditions_argv,
    robot_cell,
    run_robot_stack,
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
    report = run_benchmark(settings, envs=tuple(ENVS), throughput=False)
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
    with pytest.raises(SystemExit) as stop:
        benchmark.main(["--quick", "--episodes", "0", "--out", str(tmp_path)])
    assert stop.value.code == 2 and "error: --episodes" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        benchmark.main(["--controller", "pid"])
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
    report = run_benchmark(BenchmarkSettings(episodes=1, train_steps=0, version="v0"), controllers=(), tasks=("goal",),
                           policies=[str(run)], envs=tuple(ENVS), throughput=False)
    assert len(report["errors"]) == 3
    assert seen[("PectoralFish-Averaged-v0", False)] == {"task": "goal", "transitions": True, "observe_fins": True}
    assert seen[("PectoralFish-Full-v0", False)] == {"task": "goal", "observe_fins": True}
    full_rand = seen[("PectoralFish-Full-v0", True)]
    assert full_rand["observe_fins"] and "transitions" not in full_rand and full_rand["task"] == "goal"


def test_the_simulated_columns_run_on_the_version_asked_for_v1_by_default(tmp_path, monkeypatch):
    import pectoral_gym.agents.training.evaluate

    seen = []

    def fake_evaluate(controller, env_id, n_episodes, seed, env_kwargs):
        seen.append(env_id)
        raise RuntimeError("recorded")

    monkeypatch.setattr(pectoral_gym.agents.training.evaluate, "evaluate", fake_evaluate)
    for version, expected in (("v2", {"PectoralFish-Averaged-v2", "PectoralFish-Full-v2"}),
                              ("v1", {"PectoralFish-Averaged-v1", "PectoralFish-Full-v1"}),
                              ("v0", {"PectoralFish-Averaged-v0", "PectoralFish-Full-v0"})):
        seen.clear()
        settings = BenchmarkSettings(episodes=1, train_steps=0) if version == "v2" else BenchmarkSettings(
            episodes=1, train_steps=0, version=version)
        run_benchmark(settings, controllers=("random",), tasks=("goal",), envs=tuple(ENVS), throughput=False)
        assert set(seen) == expected and len(seen) == 3
    assert benchmark._parse_args([]).version == "v2"
    assert benchmark._parse_args(["--env-version", "v0"]).version == "v0"
    with pytest.raises(SystemExit):
        benchmark._parse_args(["--env-version", "v3"])


def test_robot_cells_come_from_the_deploy_summary(tmp_path):
    # hand through the whole robot stack in lockstep, ideal and degraded: 2 short episodes per cell; no random row
    from pectoral_gym.hardware.safety.supervisor import PRIORITY

    settings = BenchmarkSettings(episodes=1, train_steps=0, robot_episodes={"goal": 2, "track": 0}, robot_max_steps=12)
    report = run_benchmark(settings, controllers=("random", "hand"), envs=("robot", "robot+degraded"),
                           tasks=("goal",), throughput=False, robot_out=tmp_path / "robot")
    assert report["errors"] == {}
    assert [(c["controller"], c["env"], c["task"]) for c in report["cells"]] == [
        ("hand", "robot", "goal"), ("hand", "robot+degraded", "goal")]
    for cell in report["cells"]:
        summary = json.loads((Path(cell["robot"]["out"]) / "summary.json").read_text())
        episodes = summary["episodes"]
        assert cell["n_episodes"] == len(episodes) == 2
        stops = [e["safety_stop"] for e in episodes if e["safety_stop"]]
        assert cell["robot"]["safety_stops"] == dict(Counter(stops)) and set(stops) <= set(PRIORITY)
        assert sum(cell["robot"]["safety_stops"].values()) <= cell["n_episodes"]
        m = cell["metrics"]
        assert m["success"]["mean"] == pytest.approx(np.mean([e["success"] for e in episodes]))
        assert m["length"]["mean"] == pytest.approx(np.mean([e["steps"] for e in episodes]))
        assert m["length"]["mean"] <= 12
        assert m["return"]["mean"] == pytest.approx(np.mean([e["return"] for e in episodes]))
        assert m["time_to_goal"]["n"] == sum(e["success"] for e in episodes)
        assert 0 <= cell["robot"]["wall_contacts"] <= cell["n_episodes"]
        # the conditions reached the deploy: its summary records the column's
        expected = ROBOT_CONDITIONS[cell["env"]]
        recorded = summary["emulation"]["conditions"]
        assert summary["emulation"]["lockstep"] and cell["robot"]["conditions"] == recorded
        assert recorded == json.loads(json.dumps(dataclasses.asdict(expected)))
    assert report["cells"][1]["robot"]["conditions"]["radio_loss"] == DEGRADED.radio_loss == 0.1
    markdown = to_markdown(report)
    assert "## Robot stack" in markdown and "| hand | robot+degraded | goal | 2 |" in markdown
    assert "radio latency 100 ms, radio loss 10 %, frame drops 10 %, pose noise 5 mm / 2 deg" in markdown


def _fake_deploy(calls, episodes, poses):
    """A stand-in for ``hardware.library.run_deployment`` that returns the given episodes and step records."""
    from pectoral_gym.hardware.library import Deployment

    def deploy(request, notify=None, workers=None):
        calls.append(request)
        assert workers is None  # the benchmark's runs start their own
        summary = {"settings": {"task": "goal", "control_period": 0.5}, "episodes": episodes, "wall_time": 2.0,
                   "emulation": {"conditions": {"radio_loss": 0.1}}}
        lines = [{"episode": k, "step": i, "true_pose": pose, "target": [1.0, 0.5]}
                 for k, path in enumerate(poses) for i, pose in enumerate(path)]
        return Deployment(episodes, lines, [], {"sent": 0, "acked": 0, "retries": 0, "crc_errors": 0}, None, 2.0,
                          "", summary["settings"], summary)
    return deploy


def test_robot_cell_counts_stops_contacts_and_time_to_goal(tmp_path, monkeypatch):
    from pectoral_gym.hardware.studies import deployment

    episodes = [{"episode": 0, "return": 1.0, "steps": 20, "safety_stop": "", "success": True, "final_distance": 0.05},
                {"episode": 1, "return": -1.0, "steps": 4, "safety_stop": "geofence", "success": False,
                 "final_distance": 0.5},
                {"episode": 2, "return": 0.0, "steps": 3, "safety_stop": "tracking_lost", "success": False,
                 "final_distance": 0.4}]
    inside = [1.0, 0.5, 0.0]
    poses = [[inside, inside], [inside, [0.02, 0.5, 0.0]], [inside, [1.0, 0.5, 0.0]]]  # episode 1: nose past X = 0
    calls = []
    monkeypatch.setattr(deployment, "run_deployment", _fake_deploy(calls, episodes, poses))
    run = run_robot_stack(tmp_path / "d", 3, seed=7, controller="hand", conditions=DEGRADED, max_steps=20,
                          capture=True)
    request = calls[0]
    assert request.conditions == DEGRADED and request.rig == "lockstep" and request.max_episode_steps == 20
    assert request.controller == "hand" and request.policy is None and (request.episodes, request.seed) == (3, 7)
    argv = run["command"].split()
    for flag, value in (("--radio-loss", 0.1), ("--radio-latency", 0.1), ("--camera-drop", 0.1),
                        ("--pose-noise-mm", 5.0), ("--pose-noise-deg", 2.0)):
        assert float(argv[argv.index(flag) + 1]) == pytest.approx(value)
    assert "--radio-jitter" not in argv and argv[argv.index("--controller") + 1] == "hand"
    assert run["safety_stops"] == {"geofence": 1, "tracking_lost": 1} and run["wall_contacts"] == 1
    cell = robot_cell(run, "hand", "robot+degraded")
    m = cell["metrics"]
    assert m["success"]["mean"] == pytest.approx(1 / 3)
    assert m["time_to_goal"]["mean"] == pytest.approx(10.0) and m["time_to_goal"]["n"] == 1  # 20 steps x 0.5 s
    assert m["min_clearance"]["n"] == 3 and cell["robot"]["wall_ms_per_step"] == pytest.approx(2e3 / 27)
    assert cell["robot"]["conditions"] == {"radio_loss": 0.1}
    # a refused setting (the deploy's exit status 2) is an error of the cell, not of the whole process
    monkeypatch.setattr(deployment, "run_deployment",
                        lambda request, notify=None, workers=None: (_ for _ in ()).throw(ValueError("refused")))
    with pytest.raises(RuntimeError, match="status 2"):
        run_robot_stack(tmp_path / "e", 1, seed=0, controller="hand")
    assert conditions_argv(ROBOT_CONDITIONS["robot"]) == []


def test_a_policy_gets_robot_cells_on_its_own_task_only(tmp_path, monkeypatch):
    import types

    import pectoral_gym.agents.training.policy
    from pectoral_gym.hardware.studies import deployment

    monkeypatch.setattr(pectoral_gym.agents.training.policy, "load_policy",
                        lambda path: types.SimpleNamespace(trained={"task": "track"}))
    seen = []

    def fake_run(out, episodes, seed, **kwargs):
        seen.append((episodes, seed, kwargs))
        raise RuntimeError("recorded")

    monkeypatch.setattr(deployment, "run_robot_stack", fake_run)
    settings = BenchmarkSettings(episodes=1, train_steps=0, robot_episodes={"goal": 3, "track": 1}, seed=5)
    report = run_benchmark(settings, controllers=("random",), policies=[str(tmp_path / "run")], envs=("robot",),
                           throughput=False)
    assert list(report["errors"]) == ["run/robot/track"]
    assert len(seen) == 1
    episodes, seed, kwargs = seen[0]
    assert (episodes, seed, kwargs["controller"], kwargs["task"]) == (1, 5, "policy", "track")
    assert kwargs["policy"] == str(tmp_path / "run") and kwargs["conditions"] == deployment.NOMINAL


def test_cli_offers_the_robot_columns(tmp_path, capsys):
    parser_args = benchmark._parse_args(["--env", "robot", "robot+degraded", "--robot-episodes", "1", "0"])
    assert parser_args.envs == ["robot", "robot+degraded"] and parser_args.robot_episodes == [1, 0]
    assert set(benchmark._parse_args([]).envs) == set(ALL_ENVS) == {*ENVS, "robot", "robot+degraded"}
    with pytest.raises(SystemExit) as stop:
        benchmark.main(["--robot-episodes", "-1", "0", "--out", str(tmp_path)])
    assert stop.value.code == 2 and "--robot-episodes" in capsys.readouterr().err
    quick = PRESETS["quick"]
    assert sum(quick.robot_episodes.values()) <= 3 and quick.robot_max_steps <= 60
