"""The deployment as a library call: settings refused before anything runs, episodes in memory, files on request."""

import json
import multiprocessing
import os

import numpy as np
import pytest

from pectoral_gym.agents.studies.robot_stack import RobotStackNotFoundError, robot_stack
from pectoral_gym.hardware.emurig import RigConditions
from pectoral_gym.hardware.library import DeployError, DeployRequest, run_deployment


class _Forward:
    """A fixed controller (no torch): both fins row forward."""

    def reset(self, seed=None):
        self.seed = seed

    def act(self, obs):
        return np.array([0.5, 0.5, 0.0, 0.5] * 2, dtype=np.float32)


@pytest.mark.parametrize(("settings", "words"), [
    ({"rig": "tank"}, "rig must be one of"),
    ({"controller": "random"}, "controller must be one of"),
    ({"controller": object()}, "needs reset(seed) and act(obs)"),
    ({"controller": "policy"}, "policy is needed"),
    ({"controller": "hand", "policy": "run"}, "policy is needed"),
    ({"controller": _Forward(), "jobs": 2}, "jobs must be 1"),
    ({"port": "/dev/ttyUSB0"}, "the emulated rigs bring their own"),
    ({"rig": "robot", "port": "/dev/ttyUSB0"}, "needs port and camera"),
    ({"rig": "emulated", "jobs": 2}, "jobs: not with rig 'emulated'"),
    ({"speed": 2.0}, "speed: not with rig 'lockstep'"),
    ({"rig": "robot", "port": "p", "camera": "0", "conditions": RigConditions(radio_loss=0.1)}, "conditions"),
    ({"episodes": 0}, "episodes must be >= 1"),
    ({"seed": -1}, "seed must be >= 0"),
    ({"solve_fraction": 0.0}, "solve_fraction"),
    ({"control_period": 10.0}, "control_period must be in"),
    ({"firmware": "rust"}, "firmware must be one of"),
])
def test_a_bad_request_is_one_line_naming_the_setting(settings, words):
    with pytest.raises(ValueError, match=None) as error:
        DeployRequest(**settings)
    assert words in str(error.value) and "\n" not in str(error.value)


def test_settings_found_wrong_by_the_checks_leave_no_folder(tmp_path):
    out = tmp_path / "a" / "b"
    with pytest.raises(ValueError, match="--calibration: cannot load"):
        run_deployment(DeployRequest(calibration=str(tmp_path / "missing.json"), out=out))
    assert not (tmp_path / "a").exists()


def test_episodes_in_memory_match_the_files_of_the_same_run(tmp_path, monkeypatch):
    # the same seeded lockstep run twice: without a folder nothing is written, and what it returns is what the
    # run with a folder writes (steps.jsonl, run.jsonl, summary.json, apart from the wall time)
    monkeypatch.chdir(tmp_path)
    request = DeployRequest(controller="hand", episodes=2, seed=3, max_episode_steps=3)
    memory = run_deployment(request)
    assert os.listdir(tmp_path) == []
    files = run_deployment(DeployRequest(controller="hand", episodes=2, seed=3, max_episode_steps=3,
                                         out=tmp_path / "out"))
    out = tmp_path / "out"
    assert sorted(os.listdir(out)) == ["run.jsonl", "steps.jsonl", "summary.json", "trajectory.png"]
    lines = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
    assert memory.steps == lines and len(lines) == 2 * (1 + 3)  # a reset record and 3 steps per episode
    assert [r["episode"] for r in lines if r.get("event") == "reset"] == [0, 1]
    assert memory.run_log == [json.loads(line) for line in (out / "run.jsonl").read_text().splitlines()]
    assert memory.run_log[0]["type"] == "header" and memory.run_log[0]["source"] == "emulator"
    summary = json.loads((out / "summary.json").read_text())
    expected = json.loads(json.dumps(memory.summary))  # as JSON holds it: lists for tuples
    assert summary.pop("wall_time") >= 0 and expected.pop("wall_time") >= 0
    assert summary == expected
    assert summary["controller"] == "hand" and summary["emulation"]["lockstep"] and summary["ended"] == "done"
    assert [e["steps"] for e in memory.episodes] == [3, 3] and memory.ended == "" and memory.solver is None
    assert memory.link["sent"] == files.link["sent"] > 0


def test_workers_started_before_the_checks_are_ended_when_the_checks_refuse_the_run(tmp_path):
    # with jobs > 1 the workers start before the checks (their start-up beside this process's); a refused run
    # ends them
    with pytest.raises(ValueError, match="--calibration: cannot load"):
        run_deployment(DeployRequest(calibration=str(tmp_path / "missing.json"), episodes=2, jobs=2))
    assert multiprocessing.active_children() == []


def test_a_run_with_workers_started_before_its_checks_gives_the_records_of_one_process():
    one = run_deployment(DeployRequest(controller="hand", episodes=2, seed=5, max_episode_steps=3))
    two = run_deployment(DeployRequest(controller="hand", episodes=2, seed=5, max_episode_steps=3, jobs=2))
    assert two.steps == one.steps and two.run_log == one.run_log and len(one.steps) == 2 * (1 + 3)
    assert multiprocessing.active_children() == []


def test_a_controller_object_runs_in_this_process():
    controller = _Forward()
    run = run_deployment(DeployRequest(controller=controller, task="goal", episodes=1, seed=5, max_episode_steps=2))
    assert controller.seed == 5  # reset with the episode's seed
    assert run.summary["controller"] == "object" and run.summary["policy"] is None
    assert [r["action"] for r in run.steps[1:]] == [[0.5, 0.5, 0.0, 0.5] * 2] * 2


def test_a_failing_episode_is_a_deploy_error(monkeypatch):
    from pectoral_gym.hardware import lockstep_episode

    def no_fish(*args, **kwargs):
        raise RuntimeError("no fish seen for 5.0 s at reset")

    monkeypatch.setattr(lockstep_episode, "run_episode", no_fish)
    with pytest.raises(DeployError, match="episode 0: no fish seen"):
        run_deployment(DeployRequest(controller="hand", max_episode_steps=2))


def test_agents_find_the_robot_stack_through_its_entry_point():
    from pectoral_gym.hardware.studies import deployment

    assert robot_stack() is deployment and robot_stack("emulated").ROBOT_CONTROLLERS == ("hand", "nmpc")
    with pytest.raises(RobotStackNotFoundError, match="no robot stack 'tank' is installed"):
        robot_stack("tank")


def test_a_robot_stack_without_workers_to_prepare_gets_none():
    """The emulated stack prepares its workers ahead; a stack that cannot is still usable (``workers`` is ``None``)."""
    import types

    from pectoral_gym.agents.studies.robot_stack import PreparingRobotStack, prepared_workers
    from pectoral_gym.hardware.studies import deployment

    assert isinstance(deployment, PreparingRobotStack)
    bare = types.SimpleNamespace(ROBOT_CONTROLLERS=(), run_robot_stack=lambda *args, **kwargs: {},
                                 robot_cells=lambda *args, **kwargs: [])
    with prepared_workers(bare, 2) as workers:
        assert workers is None


def test_workers_started_ahead_serve_lockstep_runs_only():
    with pytest.raises(ValueError, match="workers serve lockstep runs only, not rig='emulated'"):
        run_deployment(DeployRequest(controller="hand", rig="emulated", episodes=1), workers=object())
