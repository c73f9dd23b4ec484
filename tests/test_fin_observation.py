"""The optional fin block of the observation (``observe_fins=True``): each fin's half-stroke in progress.

The reference is the parameter-change rule of ``docs/model.md`` section 5, written out by hand here:
a fin at rest at 90 deg latches a command at once and starts a power stroke to ``bias + amplitude``
(duration ``T/(zeta+1)``), then recovery strokes to ``bias - amplitude`` (``zeta T/(zeta+1)``) and
power strokes alternate, every half-stroke a half-cosine.
"""

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym.envs import PectoralFishEnv, PectoralFishVectorEnv
from pectoral_gym.envs.observation import FIN_OBS_SIZE, OBS_FINS, OBS_SIZE, decode, one_observation
from pectoral_gym.registration import registered_settings

IDS = ("PectoralFish-Averaged-v0", "PectoralFish-Full-v0")
BIAS, AMPLITUDE, PERIOD, RATIO = math.radians(80.0), math.radians(20.0), 1.0, 3.0  # d1 = 0.25 s, d2 = 0.75 s


def by_hand(t: float, bias: float, amplitude: float, period: float, ratio: float):
    """(angle, end angle, +1 power / -1 recovery, time left [s]) at ``t`` after the first command from rest."""
    d1 = period / (ratio + 1.0)
    d2 = ratio * d1
    g_from, g_to, power, duration, start = math.pi / 2, bias + amplitude, 1.0, d1, 0.0
    while t >= start + duration:  # move on to the half-stroke in progress at t
        start += duration
        g_from, g_to = g_to, (bias - amplitude if power > 0 else bias + amplitude)
        power, duration = -power, (d2 if power > 0 else d1)
    s = t - start
    angle = 0.5 * (g_from + g_to) - 0.5 * (g_to - g_from) * math.cos(math.pi * s / duration)
    return angle, g_to, power, duration - s


def scaled(angle: float) -> float:
    return (angle - math.pi / 2) / (math.pi / 2)


@pytest.mark.parametrize("env_id", IDS)
def test_fin_block_follows_the_stroke_schedule_derived_by_hand(env_id):
    env = gym.make(env_id, observe_fins=True)
    config = env.unwrapped.config
    right = (BIAS, AMPLITUDE, PERIOD, RATIO)
    left = (math.radians(100.0), math.radians(10.0), 1.6, 1.0)  # symmetric beat: 0.8 s half-strokes
    action = np.concatenate([config.encode(np.array(right)), config.encode(np.array(left))]).astype(np.float32)
    obs, _ = env.reset(seed=3)
    assert obs.shape == (OBS_SIZE + FIN_OBS_SIZE,)
    period_max = config.period_range[1]
    for step in range(1, 9):
        obs, _, terminated, truncated, _ = env.step(action)
        assert not (terminated or truncated)
        t = step * config.control_period
        fins = decode(obs).fins
        for f, beat in enumerate((right, config.decode(action[4:]))):
            angle, angle_to, power, left_time = by_hand(t, *beat)
            expected = (scaled(angle), scaled(angle_to), power, min(left_time / period_max, 1.0))
            np.testing.assert_allclose(fins[f], expected, atol=2e-6, err_msg=f"fin {f}, t = {t} s")


def test_both_models_report_the_same_fin_block_for_the_same_actions():
    envs = [gym.make(env_id, observe_fins=True) for env_id in IDS]
    rng = np.random.default_rng(0)
    firsts = [env.reset(seed=5)[0] for env in envs]
    np.testing.assert_array_equal(firsts[0][OBS_FINS], firsts[1][OBS_FINS])
    for _ in range(20):
        action = rng.uniform(-1, 1, 8).astype(np.float32)  # changing commands: transitional strokes included
        blocks = [env.step(action)[0][OBS_FINS] for env in envs]
        np.testing.assert_allclose(blocks[0], blocks[1], atol=1e-6)


def test_the_default_observation_is_unchanged_and_the_block_is_inside_the_space():
    assert gym.make(IDS[0]).observation_space.shape == (OBS_SIZE,)
    env = gym.make(IDS[1], observe_fins=True)
    assert env.unwrapped.observation_structure["fins"] == FIN_OBS_SIZE
    assert sum(env.unwrapped.observation_structure.values()) == OBS_SIZE + FIN_OBS_SIZE
    obs, _ = env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(60):
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        if terminated or truncated:
            obs, _ = env.reset()
    assert decode(obs[:OBS_SIZE]).fins is None
    with pytest.raises(ValueError, match="entries in its last axis"):
        decode(obs[:-1])


@pytest.mark.parametrize("env_id", IDS)
def test_checkers_pass_with_the_fin_block(env_id):
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", ".*is out of date", DeprecationWarning)  # make's notice that v1 exists
        envs = gym.make(env_id, observe_fins=True), gym.make(env_id, observe_fins=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(envs[0].unwrapped)
        sb3_check_env(envs[1])


def test_vector_env_fin_block_matches_the_single_env():
    vec = PectoralFishVectorEnv(num_envs=3, **registered_settings("PectoralFish-Averaged-v0", dict(observe_fins=True)))
    single = PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0", dict(observe_fins=True)))
    vec_obs, _ = vec.reset(seed=[7, 8, 9])
    obs, _ = single.reset(seed=8)
    action = np.full(8, 0.3, dtype=np.float32)
    for _ in range(5):
        vec_obs, *_ = vec.step(np.tile(action, (3, 1)))
        obs, *_ = single.step(action)
    assert vec.observation_space.shape == (3, OBS_SIZE + FIN_OBS_SIZE)
    np.testing.assert_allclose(vec_obs[1], obs, atol=1e-6)


def test_a_bad_setting_raises():
    with pytest.raises(ValueError, match="observe_fins must be True or False"):
        PectoralFishEnv(observe_fins="yes")


@pytest.mark.parametrize("shape", [(OBS_SIZE,), (OBS_SIZE + FIN_OBS_SIZE,)])
def test_one_observation_takes_either_size_as_float64(shape):
    obs = np.arange(shape[0], dtype=np.float32)
    out = one_observation(obs)
    assert out.dtype == np.float64 and out.shape == shape and np.array_equal(out, np.arange(shape[0]))


@pytest.mark.parametrize("shape", [(), (OBS_SIZE - 1,), (OBS_SIZE + 1,), (2, OBS_SIZE), (1, OBS_SIZE + FIN_OBS_SIZE)])
def test_one_observation_refuses_other_shapes_with_the_sizes_it_takes(shape):
    with pytest.raises(ValueError, match=rf"obs must have shape \({OBS_SIZE},\) or \({OBS_SIZE + FIN_OBS_SIZE},\)"):
        one_observation(np.zeros(shape))
