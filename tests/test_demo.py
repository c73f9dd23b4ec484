"""The end-to-end demo in quick mode, with a tiny budget."""

import json

from pectoral_gym.agents.studies.robot_stack import prepared_workers
from pectoral_gym.agents.training.demo import main


def test_quick_demo_writes_report_json_and_plot(tmp_path, capsys):
    out = tmp_path / "demo"
    # --jobs 1: the deploy's own process (its --jobs gives the same results for any J: tests/test_lockstep.py)
    assert main(["--quick", "--out", str(out), "--episodes", "3", "--no-progress", "--jobs", "1"]) == 0
    results = json.loads((out / "results.json").read_text())
    assert [e["env_id"] for e in results["evaluations"]] == ["PectoralFish-Averaged-v2", "PectoralFish-Full-v2"]
    assert all(e["n_episodes"] == 3 for e in results["evaluations"])
    assert results["timesteps"] >= 1024
    for evaluation in results["evaluations"]:
        success = evaluation["metrics"]["success"]
        assert 0.0 <= success["ci_low"] <= success["mean"] <= success["ci_high"] <= 1.0
    report = (out / "report.md").read_text()
    assert "| controller |" in report and "PectoralFish-Full-v2" in report and "trajectories.png" in report
    assert (out / "trajectories.png").read_bytes()[:4] == b"\x89PNG"
    assert (out / "run" / "model.zip").is_file()
    # the robot stack: 2 lockstep episodes on the emulated robot, their log and their line in the report
    robot = results["robot_stack"]
    assert robot["episodes"] == 2 and 0.0 <= robot["success"]["mean"] <= 1.0
    assert (out / "robot" / "steps.jsonl").is_file() and "emulated robot" in report
    # through the robot stack (hardware/studies/deployment.run_robot_stack), with the same figures and command
    assert set(robot) == {"episodes", "seed", "success", "safety_stops", "wall_time_s", "command"}
    assert robot["command"].startswith("python -m pectoral_gym.hardware.deploy --policy ")
    assert f"over 2 seeded episodes (seed {robot['seed']})" in report
    assert "demo finished" in capsys.readouterr().out
    # a second run into the same folder refuses to overwrite it
    assert main(["--quick", "--out", str(out), "--no-progress"]) == 2


def test_demo_refuses_a_bad_jobs_count(capsys):
    import pytest

    with pytest.raises(SystemExit) as exit_:
        main(["--quick", "--jobs", "0"])
    assert exit_.value.code == 2 and "--jobs must be >= 1" in capsys.readouterr().err


def test_a_failed_training_ends_the_robot_stacks_workers_started_before_it(tmp_path, monkeypatch):
    """The robot stack's workers start with the training (``--jobs 2``); a training error ends them."""
    import pytest

    from pectoral_gym.agents.training import demo, train

    pools = []

    def prepared(stack, jobs):
        context = prepared_workers(stack, jobs)
        pools.append(context)
        return context

    def failing_train(*args, **kwargs):
        assert pools and all(proc.is_alive() for proc in pools[0].procs)  # started, waiting for the policy
        raise RuntimeError("training failed")

    monkeypatch.setattr(demo, "prepared_workers", prepared)
    monkeypatch.setattr(train, "train", failing_train)
    with pytest.raises(RuntimeError, match="training failed"):
        demo.run_demo(tmp_path / "demo", quick=True, progress=False, robot_jobs=2)
    assert len(pools) == 1 and len(pools[0].procs) == 2
    assert all(proc.exitcode is not None for proc in pools[0].procs)  # ended and joined
