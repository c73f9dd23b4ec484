"""The settings that prepare a policy for the robot stack: stopping band, servo limit, insets, the v1 ids."""

import math

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.hardware.safety.geofence import Geofence
from pectoral_gym.model import tank
from pectoral_gym.model.params import FishParams, body_coefficients
from pectoral_gym.model.servo import ROBOT_MAX_FIN_RATE, ServoLimits, clip_beats, servo_period
from pectoral_gym.registration import ENV_SETTINGS, ROBOT_READY, registered_settings

PARAMS = FishParams()
K = tank.coast_rate(body_coefficients(PARAMS))
HALF, WIDTH, SPAN = 0.5 * PARAMS.body_length, PARAMS.fin_offset, PARAMS.fin_span


def _clearance_need_by_hand(x, y, psi, vx, vy, rule):
    """Per wall, the outline's clearance and the need, from the circles written out here (module docstring of tank)."""
    c, s = math.cos(psi), math.sin(psi)
    circles = [(x + c * HALF, y + s * HALF, WIDTH), (x - c * HALF, y - s * HALF, WIDTH),
               (x + s * WIDTH, y - c * WIDTH, SPAN), (x - s * WIDTH, y + c * WIDTH, SPAN)]
    gaps = [min(px - r for px, _, r in circles), min(tank.TANK_LENGTH - px - r for px, _, r in circles),
            min(py - r for _, py, r in circles), min(tank.TANK_WIDTH - py - r for _, py, r in circles)]
    needs = []
    for v in (-vx, vx, -vy, vy):
        v = max(v, 0.0)
        coast = math.log(max(v, rule.contact_speed) / rule.contact_speed) / K  # down to the contact speed
        needs.append(rule.margin + v * rule.reaction_time + coast)
    return gaps, needs


def test_band_shortfall_is_the_written_out_rule_on_random_states():
    rng = np.random.default_rng(3)
    rule = tank.ROBOT_STOP_RULE
    geofence = Geofence(PARAMS, rule)
    for _ in range(300):
        x, y = rng.uniform(0, tank.TANK_LENGTH), rng.uniform(0, tank.TANK_WIDTH)
        psi, vx, vy = rng.uniform(-math.pi, math.pi), rng.normal(0, 0.1), rng.normal(0, 0.1)
        gaps, needs = _clearance_need_by_hand(x, y, psi, vx, vy, rule)
        expected = max(n - g for n, g in zip(needs, gaps, strict=True))
        got = tank.band_shortfall(x, y, math.cos(psi), math.sin(psi), (-vx, vx, -vy, vy), (HALF, WIDTH, SPAN), K,
                                  rule.margin, rule.reaction_time, rule.contact_speed)
        assert got == pytest.approx(expected, abs=1e-12)
        assert geofence.breached(x, y, psi, vx, vy) == (expected > 0)


def test_stop_band_ends_the_episode_with_a_cost_where_the_geofence_would_stop():
    env = gym.make("PectoralFish-Averaged-v1")
    env.reset(seed=0)
    rest = env.unwrapped.config.encode(np.array([math.pi / 2, 0.0, 1.0, 1.0]))
    action = np.concatenate([rest, rest]).astype(np.float32)
    # 0.45 m from the wall X = 0, heading at it at 0.15 m/s: need 0.05 + 0.0225 + ln(1 + 6.45 * 0.75) / 6.45
    # = 0.35 m, clearance 0.45 - L/2 - C_p = 0.32 m, and the fish coasts closer during the step.
    env.unwrapped.set_fish_state((0.45, 0.6, math.pi, 0.15, 0.0, 0.0))
    _, reward, terminated, _, info = env.step(action)
    assert terminated and info["cost"] == 1.0 and info["reward_wall"] == -10.0
    assert not info["is_success"]
    # In the middle of the tank at rest: no cost, the episode goes on.
    env.reset(seed=0)
    env.unwrapped.set_fish_state((1.15, 0.575, 0.0, 0.0, 0.0, 0.0))
    _, _, terminated, _, info = env.step(action)
    assert not terminated and info["cost"] == 0.0 and info["reward_wall"] == 0.0
    env.close()


def test_the_same_state_without_stop_band_goes_on_and_has_no_cost_key():
    env = gym.make("PectoralFish-Averaged-v1", stop_band=False)
    env.reset(seed=0)
    env.unwrapped.set_fish_state((0.45, 0.6, math.pi, 0.15, 0.0, 0.0))
    _, _, terminated, _, info = env.step(np.zeros(8, dtype=np.float32))
    assert not terminated and "cost" not in info


def test_vector_env_reports_the_cost_like_the_single_env():
    venv = gym.make_vec("PectoralFish-Averaged-v1", num_envs=3, vectorization_mode="vector_entry_point")
    _, info = venv.reset(seed=1)
    assert "cost" in info and info["cost"].shape == (3,)
    venv.close()


@pytest.mark.parametrize("beat", [(1.57, 0.5236, 0.5, 5.0), (1.0, 0.3, 0.6, 0.7), (2.0, 0.1, 0.5, 5.0),
                                  (1.57, 0.4, 1.9, 2.0)])
def test_servo_period_is_the_firmware_clipping(beat):
    clipped, _ = clip_beats(np.array([beat, beat]), ServoLimits())
    assert servo_period(beat[1], beat[2], beat[3], ROBOT_MAX_FIN_RATE) == pytest.approx(clipped[0, 2], rel=1e-12)
    # The peak rate of the faster half-stroke at the returned period is at most the limit (eq. 21 by hand).
    period = servo_period(beat[1], beat[2], beat[3], ROBOT_MAX_FIN_RATE)
    peak = math.pi * beat[1] * (beat[3] + 1) / (period * min(1.0, beat[3]))
    assert peak <= ROBOT_MAX_FIN_RATE * (1 + 1e-12)


def test_servo_limit_stretches_the_fastest_pattern_and_decode_agrees():
    config = EnvConfig(model="averaged", servo_limit=ROBOT_MAX_FIN_RATE)
    fastest = config.decode(np.array([0.0, 1.0, -1.0, 1.0]))
    # 30 deg at 0.5 s and ratio 5 peaks at pi (pi/6) 6 / 0.5 = 19.7 rad/s > 13: period pi (pi/6) 6 / 13 = 0.759 s.
    assert fastest[2] == pytest.approx(math.pi * (math.pi / 6) * 6 / 13.0)
    env = gym.make("PectoralFish-Averaged-v1")
    env.reset(seed=0)
    env.step(np.array([0.0, 1.0, -1.0, 1.0] * 2, dtype=np.float32))
    assert env.unwrapped.fin_patterns[0] == pytest.approx(fastest)


def test_goals_and_starts_keep_their_insets():
    env = gym.make("PectoralFish-Averaged-v1")
    for seed in range(200):
        env.reset(seed=seed)
        gx, gy = env.unwrapped.target
        x, y = env.unwrapped.fish_state[:2]
        assert 0.3 <= gx <= tank.TANK_LENGTH - 0.3 and 0.3 <= gy <= tank.TANK_WIDTH - 0.3
        assert 0.3 <= x <= tank.TANK_LENGTH - 0.3 and 0.3 <= y <= tank.TANK_WIDTH - 0.3


def test_v1_ids_are_their_settings_everywhere():
    for env_id in ("PectoralFish-Averaged-v1", "PectoralFish-Full-v1"):
        config = gym.make(env_id).unwrapped.config
        for name, value in ENV_SETTINGS[env_id].items():
            assert getattr(config, name) == value, (env_id, name)
        assert all(getattr(config, k) == v for k, v in ROBOT_READY.items())
    assert gym.make("PectoralFish-Full-v1").unwrapped.config.integration == "fast"
    assert registered_settings("PectoralFish-Averaged-v1", {"task": "track"})["task"] == "track"
    with pytest.raises(ValueError, match="contradicts"):
        registered_settings("PectoralFish-Averaged-v1", {"model": "full"})
    with pytest.raises(ValueError, match="unknown env id"):
        registered_settings("CartPole-v1")


def test_v2_is_v1_with_the_averaged_models_ripple_offsets():
    """v2 changes one setting: the averaged id's ripple offsets (docs/model.md 3.8); the full id moves unchanged."""
    from pectoral_gym.model.spec import AVERAGED

    assert ENV_SETTINGS["PectoralFish-Full-v2"] == ENV_SETTINGS["PectoralFish-Full-v1"]
    assert ENV_SETTINGS["PectoralFish-Averaged-v2"] == {**ENV_SETTINGS["PectoralFish-Averaged-v1"],
                                                         "ripple_offsets": True}
    spec = gym.make("PectoralFish-Averaged-v2").unwrapped.config.model_spec()
    assert spec.transitions and spec.ripple_offsets
    assert spec == AVERAGED  # the averaged model's own defaults


@pytest.mark.parametrize("kwargs, match", [({"goal_inset": 0.6}, "goal_inset"), ({"start_inset": -1}, "start_inset"),
                                           ({"stop_rule": (0.05, 0.1)}, "stop_rule"),
                                           ({"stop_rule": (0.05, math.nan, 5.0)}, "stop_rule: StopRule.reaction_time"),
                                           ({"stop_rule": {"margin": 0.05}}, "stop_rule"),
                                           ({"stop_rule": "0.05"}, "stop_rule"),
                                           ({"servo_limit": 0.0}, "servo_limit"), ({"stop_band": 1}, "stop_band")])
def test_bad_settings_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        EnvConfig(**kwargs)
