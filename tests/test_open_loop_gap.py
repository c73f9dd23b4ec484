"""The open-loop study: a deploy's actions replayed in simulation from its logged starts, and where the poses part."""

import json

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.studies import open_loop_gap

ENV = "PectoralFish-Full-v2"


def _deploy(folder, episodes, nudge=None):
    """A deploy folder logged from simulated hand-law episodes; ``nudge=(episode, step)`` moves that pose by 1 cm."""
    env = gym.make(ENV)
    hand = make_baseline("hand", env.unwrapped.config)
    folder.mkdir()
    summary = []
    with (folder / "steps.jsonl").open("w") as log:
        for k in range(episodes):
            obs, _ = env.reset(seed=200 + k)
            hand.reset(k)
            start = [float(v) for v in env.unwrapped.fish_state[:3]]
            log.write(json.dumps({"episode": k, "step": 0, "event": "reset", "pose": start,
                                  "target": list(env.unwrapped.target), "true_pose": start}) + "\n")
            steps, done = 0, False
            while not done and steps < 12:
                action = hand.act(obs)
                obs, _, terminated, truncated, info = env.step(action)
                steps, done = steps + 1, terminated or truncated
                pose = [float(v) for v in env.unwrapped.fish_state[:3]]
                if nudge == (k, steps):
                    pose[0] += 0.01
                log.write(json.dumps({"episode": k, "step": steps, "action": np.asarray(action).tolist(),
                                      "pose": pose, "true_pose": pose}) + "\n")
            summary.append({"episode": k, "success": bool(info["is_success"]), "safety_stop": "", "steps": steps})
    (folder / "summary.json").write_text(json.dumps({"episodes": summary}))


def test_the_model_replayed_open_loop_does_not_part_from_itself(tmp_path):
    # A deploy logged from the simulation itself: its actions, replayed from its starts, give its poses again.
    _deploy(tmp_path / "deploy", 2)
    partings = open_loop_gap.replay_open_loop(tmp_path / "deploy", ENV)
    assert [p.parted_at for p in partings] == [None, None]
    assert all(p.steps == 12 and p.final_position_mm < 1e-3 for p in partings)


def test_a_pose_off_by_a_centimetre_parts_at_its_step(tmp_path):
    _deploy(tmp_path / "deploy", 2, nudge=(1, 4))
    partings = open_loop_gap.replay_open_loop(tmp_path / "deploy", ENV, part_mm=5.0, part_deg=3.0)
    assert partings[0].parted_at is None
    assert partings[1].parted_at == 4 and partings[1].position_mm == pytest.approx(10.0, abs=0.01)
    assert partings[1].final_position_mm < 1e-3  # only that one logged pose was moved


def test_the_command_line_writes_its_report(tmp_path, capsys):
    _deploy(tmp_path / "deploy", 1, nudge=(0, 2))
    assert open_loop_gap.main(["--deploy", str(tmp_path / "deploy"), "--out", str(tmp_path / "gap")]) == 0
    result = json.loads((tmp_path / "gap" / "open_loop_gap.json").read_text())
    assert result["episodes"] == 1 and result["parted"] == 1 and result["per_episode"][0]["parted_at"] == 2
    assert "at step 2 of 12" in capsys.readouterr().out


def test_bad_step_records_and_thresholds_name_what_is_wrong(tmp_path, capsys):
    (tmp_path / "steps.jsonl").write_text('{"episode": 0, "step": 1, "action": [0, 1], "pose": [1, 0.5, 0]}\n')
    with pytest.raises(ValueError, match=r"steps.jsonl:1: the step's action \(8\) and pose \(3\) must be finite"):
        open_loop_gap.read_steps(tmp_path)
    (tmp_path / "steps.jsonl").write_text('{"episode": 0, "step": 1, "action": [0, 0, 0, 0, 0, 0, 0, 0]}\n')
    with pytest.raises(ValueError, match="steps.jsonl:1: a step record needs"):
        open_loop_gap.read_steps(tmp_path)
    with pytest.raises(ValueError, match="thresholds must be > 0"):
        open_loop_gap.replay_open_loop(tmp_path, ENV, part_mm=0.0)
    assert open_loop_gap.main(["--deploy", str(tmp_path / "missing")]) == 2
    assert "steps.jsonl: not found" in capsys.readouterr().err
