"""reset(options=...) pins an episode's start and goal; the stack-gap study replays deploy episodes from them."""

import json
import math

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.studies import stack_gap
from pectoral_gym.model import tank

ENV = "PectoralFish-Full-v2"


def _pose(env):
    return tuple(float(v) for v in env.unwrapped.fish_state[:3]), tuple(env.unwrapped.target)


def test_options_pin_the_start_and_goal_and_leave_the_generator_as_it_was():
    env = gym.make(ENV)
    obs, info = env.reset(seed=7, options={"start": (1.0, 0.5, 0.3), "goal": (1.5, 0.8)})
    (start, goal) = _pose(env)
    assert start == (1.0, 0.5, 0.3) and goal == (1.5, 0.8)
    assert obs[0] == pytest.approx(1.0) and obs[1] == pytest.approx(0.5)
    assert obs[2] == pytest.approx(math.cos(0.3)) and obs[3] == pytest.approx(math.sin(0.3))
    assert info["distance"] == pytest.approx(math.hypot(0.5, 0.3))
    assert np.all(env.unwrapped.fish_state[3:] == 0.0)  # at rest, as every start
    # The generator moved as in a plain reset: the next episodes are those after reset(seed=7).
    plain = gym.make(ENV)
    plain.reset(seed=7)
    for _ in range(3):
        assert np.array_equal(env.reset()[0], plain.reset()[0])
    # Pinning one of them keeps the other's draw.
    plain.reset(seed=11)
    drawn_start, drawn_goal = _pose(plain)
    env.reset(seed=11, options={"goal": (0.9, 0.6)})
    assert _pose(env) == (drawn_start, (0.9, 0.6))
    env.reset(seed=11, options={"start": (0.7, 0.4, -1.0)})
    assert _pose(env) == ((0.7, 0.4, -1.0), drawn_goal)


@pytest.mark.parametrize("options, match", [
    ({"start": (1.0, 0.5, 0.3), "heading": 1.0}, "unknown keys"),
    ({"start": (1.0, 0.5)}, "3 numbers"),
    ({"goal": (tank.TANK_LENGTH + 0.1, 0.5)}, "inside the"),
    ({"goal": (1.0, math.nan)}, "finite"),
    ({"start": "centre"}, "3 numbers"),
])
def test_bad_options_name_what_is_wrong(options, match):
    env = gym.make(ENV)
    with pytest.raises(ValueError, match=match):
        env.reset(seed=0, options=options)
    with pytest.raises(ValueError, match="goal task"):
        gym.make(ENV, task="track").reset(seed=0, options={"goal": (1.0, 0.5)})
    with pytest.raises(ValueError, match="unknown keys"):  # the vector env does not pin: it says so
        gym.make_vec(ENV, num_envs=2, vectorization_mode="vector_entry_point").reset(seed=0, options=options)


def _simulated_deploy(folder, episodes, fail_on_stack=()):
    """A deploy folder written from simulated hand-law episodes (drawn starts), with chosen stack failures."""
    env = gym.make(ENV)
    hand = make_baseline("hand", env.unwrapped.config)
    folder.mkdir()
    truth, summary = [], []
    with (folder / "steps.jsonl").open("w") as log:
        for k in range(episodes):
            obs, _ = env.reset(seed=100 + k)
            hand.reset(k)
            start, goal = _pose(env)
            log.write(json.dumps({"episode": k, "step": 0, "event": "reset", "pose": [0, 0, 0],
                                  "target": list(goal), "true_pose": list(start)}) + "\n")
            steps, done = 0, False
            while not done:
                obs, _, terminated, truncated, info = env.step(hand.act(obs))
                steps, done = steps + 1, terminated or truncated
            truth.append((bool(info["is_success"]), steps))
            failed = k in fail_on_stack
            summary.append({"episode": k, "success": truth[-1][0] and not failed,
                            "safety_stop": "geofence" if failed else "", "steps": 5 if failed else steps})
    (folder / "summary.json").write_text(json.dumps({"episodes": summary}))
    return truth


def test_replaying_a_deploy_reproduces_its_simulated_episodes_and_counts_the_stacks_losses(tmp_path):
    truth = _simulated_deploy(tmp_path / "deploy", 3, fail_on_stack=(1,))
    assert truth[1][0], "the episode marked lost on the stack must be one the hand law reaches"
    episodes = stack_gap.read_deploy(tmp_path / "deploy")
    hand = make_baseline("hand", gym.make(ENV).unwrapped.config)
    replayed = stack_gap.replay(hand, episodes, ENV)
    # From the logged starts and goals the simulation runs the very same episodes (outcome and length).
    assert [(r.sim_success, r.sim_steps) for r in replayed] == truth
    result = stack_gap.report(replayed)
    assert result["sim_only"] == 1 and result["both"] == sum(s for s, _ in truth) - 1
    assert [row["episode"] for row in result["lost_on_the_stack"]] == [1]
    assert result["lost_on_the_stack"][0]["stop"] == "geofence"


def test_the_command_line_writes_its_report(tmp_path, capsys):
    _simulated_deploy(tmp_path / "deploy", 2, fail_on_stack=(0,))
    assert stack_gap.main(["--controller", "hand", "--deploy", str(tmp_path / "deploy"),
                           "--out", str(tmp_path / "gap")]) == 0
    result = json.loads((tmp_path / "gap" / "stack_gap.json").read_text())
    assert result["episodes"] == 2 and len(result["per_episode"]) == 2
    assert "in simulation only" in capsys.readouterr().out


def test_bearing_of_the_goal_off_the_heading():
    ahead = stack_gap.DeployedEpisode(0, (1.0, 0.5, 0.0), (1.5, 0.5), True, "", 10)
    behind_left = stack_gap.DeployedEpisode(1, (1.0, 0.5, -math.pi / 2), (0.5, 0.5), True, "", 10)
    assert ahead.bearing == pytest.approx(0.0)
    assert behind_left.bearing == pytest.approx(-90.0)  # heading -Y, goal at -X: 90 deg to the right


def test_bad_deploy_folders_name_the_file_and_line(tmp_path):
    with pytest.raises(ValueError, match="summary.json: not found"):
        stack_gap.read_deploy(tmp_path)
    (tmp_path / "summary.json").write_text(json.dumps({"episodes": [{"episode": 0, "success": True}]}))
    reset = '{"episode": %d, "event": "reset", "pose": [1, %s, 0], "target": [1.2, 0.5]}\n'
    (tmp_path / "steps.jsonl").write_text(reset % (0, "0.5") + "not json\n")
    with pytest.raises(ValueError, match="steps.jsonl:2: not JSON"):
        stack_gap.read_deploy(tmp_path)
    (tmp_path / "steps.jsonl").write_text(reset % (3, "0.5"))
    with pytest.raises(ValueError, match="episode 0 of the summary has no reset record"):
        stack_gap.read_deploy(tmp_path)
    (tmp_path / "steps.jsonl").write_text(reset % (0, '"x"'))
    with pytest.raises(ValueError, match="steps.jsonl:1"):
        stack_gap.read_deploy(tmp_path)
