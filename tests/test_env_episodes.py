"""Episodes of the single-fish Gymnasium environments: how they end (a wall contact with its penalty, the goal
reached, truncation after ``max_episode_steps``), where they start (the start and goal draws of ``goal``, the
reference of ``track`` moving at ``ref_speed``), and ``set_fish_state`` refusing a bad state.

The envs' API, seeding, rewards and settings: ``tests/test_envs.py``.
"""

import math

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym import FishParams
from pectoral_gym.envs import PectoralFishEnv
from pectoral_gym.model.params import TANK_LENGTH as TANK_X
from pectoral_gym.model.params import TANK_WIDTH as TANK_Y
from pectoral_gym.registration import registered_settings

IDS = ["PectoralFish-Averaged-v0", "PectoralFish-Full-v0"]


@pytest.mark.parametrize("env_id", IDS)
def test_wall_contact_terminates_with_the_penalty(env_id):
    env = gym.make(env_id, wall_penalty=7.0)
    env.reset(seed=0)
    half = 0.5 * FishParams().body_length
    env.unwrapped.set_fish_state([TANK_X - half - 0.005, 0.5, 0.0, 0.1, 0.0, 0.0])  # nose 5 mm from the wall, 0.1 m/s
    _, reward, terminated, truncated, info = env.step(np.zeros(8, np.float32))
    assert terminated and not truncated
    assert info["reward_wall"] == -7.0
    assert isinstance(info["is_success"], np.bool_) and not info["is_success"]
    assert reward == pytest.approx(-7.0 + info["reward_progress"] + info["reward_energy"] + info["reward_time"])


def test_goal_reached_terminates_with_success():
    env = gym.make("PectoralFish-Full-v0", goal_bonus=3.0)
    env.reset(seed=0)
    x, y = env.unwrapped.fish_state[:2]
    env.unwrapped.set_target(x + 0.02, y)  # goal 2 cm ahead
    _, reward, terminated, _, info = env.step(np.zeros(8, np.float32))
    assert terminated and isinstance(info["is_success"], np.bool_) and info["is_success"]
    assert info["reward_goal"] == 3.0 and info["reward_wall"] == 0.0
    assert info["distance"] < 0.08


@pytest.mark.parametrize("state", [[1.0, 0.5, 0.0], [1.0, 0.5, 0.0, 0.1, 0.0, np.nan]])
def test_set_fish_state_refuses_bad_states(state):
    env = PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0"))
    env.reset(seed=0)
    before = env.fish_state
    with pytest.raises(ValueError, match="6 finite numbers"):
        env.set_fish_state(state)
    np.testing.assert_array_equal(env.fish_state, before)


def test_goal_task_start_and_goal_geometry():
    env = PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0"))
    for seed in range(40):
        obs, _ = env.reset(seed=seed)
        x, y = obs[0], obs[1]
        assert 0.3 <= x <= TANK_X - 0.3 and 0.3 <= y <= TANK_Y - 0.3
        assert np.all(obs[4:7] == 0) and np.all(obs[9:11] == 0)
        gx, gy = env.target
        assert 0.2 <= gx <= TANK_X - 0.2 and 0.2 <= gy <= TANK_Y - 0.2
        assert 0.3 <= math.hypot(gx - x, gy - y) <= 1.0
        assert math.hypot(obs[7], obs[8]) == pytest.approx(math.hypot(gx - x, gy - y), rel=1e-5)
        angles, _ = env.model.fin_angles()
        np.testing.assert_allclose(angles, math.pi / 2)


def test_track_task_reference_moves_at_ref_speed():
    env = PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0", dict(task="track", ref_speed=0.05)))
    for seed in range(20):
        obs, _ = env.reset(seed=seed)
        assert math.hypot(obs[7], obs[8]) <= 0.1 + 1e-6
        assert math.hypot(obs[9], obs[10]) == pytest.approx(0.05, rel=1e-5)
        ellipse = env.reference
        assert 0.5 <= ellipse.a <= 0.8 and 0.25 <= ellipse.b <= 0.4
        tx, ty = env.target
        velocity = env.target_velocity
        phase0 = ellipse.phase
        env.step(np.zeros(8, np.float32))
        tx2, ty2 = env.target
        dphase = math.remainder(env.reference.phase - phase0, 2 * math.pi)
        phi = np.linspace(phase0, phase0 + dphase, 2001)
        speed = np.sqrt((ellipse.a * np.sin(phi)) ** 2 + (ellipse.b * np.cos(phi)) ** 2)
        arc = abs(np.trapezoid(speed, phi))
        assert arc == pytest.approx(0.05 * 0.5, rel=1e-6)  # ref_speed * control_period along the ellipse
        assert math.hypot(tx2 - tx, ty2 - ty) == pytest.approx(0.025, rel=1e-2)
        assert ((tx2 - tx) * velocity[0] + (ty2 - ty) * velocity[1]) > 0  # in the direction of travel
        heading = math.atan2(obs[3], obs[2])
        travel = math.atan2(velocity[1], velocity[0])
        assert abs(math.remainder(heading - travel, 2 * math.pi)) <= 0.3 + 1e-6


def test_truncation_after_max_episode_steps():
    env = gym.make("PectoralFish-Averaged-v0", task="track", max_episode_steps=5)
    env.reset(seed=2)
    for _ in range(5):
        _, _, terminated, truncated, _ = env.step(np.zeros(8, np.float32))
        assert not terminated
    assert truncated
