"""The SB3 VecEnv adapter against DummyVecEnv of single envs, SB3's wrappers and its API contract."""

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv, VecCheckNan, VecMonitor, VecNormalize

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.agents.training.vec_adapter import FishVecEnv, make_fish_vec_env
from pectoral_gym.envs import PectoralFishVectorEnv
from pectoral_gym.registration import registered_settings

ENV = "PectoralFish-Averaged-v0"


def reference(n, seed, max_steps, **kwargs):
    venv = DummyVecEnv([lambda: gym.make(ENV, max_episode_steps=max_steps, **kwargs) for _ in range(n)])
    venv.seed(seed)
    return venv


@pytest.mark.parametrize("task", ["goal", "track"])
def test_same_as_dummy_vec_env_of_single_envs(task):
    # short episodes so that both terminations (walls, goals) and truncations happen
    n, seed, max_steps = 5, 3, 15
    ours = make_fish_vec_env(ENV, n, {"task": task}, seed=seed, max_episode_steps=max_steps)
    ref = reference(n, seed, max_steps, task=task)
    np.testing.assert_array_equal(ours.reset(), ref.reset())
    rng = np.random.default_rng(0)
    dones = truncations = 0
    for step in range(80):
        actions = rng.uniform(-1, 1, (n, 8)).astype(np.float32)
        obs, rewards, done, infos = ours.step(actions)
        obs_ref, rewards_ref, done_ref, infos_ref = ref.step(actions)
        np.testing.assert_array_equal(obs, obs_ref, err_msg=f"step {step}")
        np.testing.assert_allclose(rewards, rewards_ref, rtol=1e-6)
        np.testing.assert_array_equal(done, done_ref)
        assert rewards.dtype == np.float32 and done.dtype == np.bool_
        for info, info_ref in zip(infos, infos_ref, strict=True):
            assert set(info) == set(info_ref)
            for key, value in info_ref.items():
                if key == "terminal_observation":
                    np.testing.assert_array_equal(info[key], value)
                else:
                    assert info[key] == pytest.approx(value), key
        dones += done.sum()
        truncations += sum(info["TimeLimit.truncated"] for info in infos)
    assert dones > n and truncations > 0


def test_terminal_observation_is_the_last_observation_of_the_episode():
    n, seed = 4, 0
    v0 = registered_settings("PectoralFish-Averaged-v0")
    native = PectoralFishVectorEnv(num_envs=n, max_episode_steps=6, **v0)
    ours = FishVecEnv(PectoralFishVectorEnv(num_envs=n, max_episode_steps=6, autoreset_mode="SameStep", **v0))
    native.reset(seed=seed)
    ours.seed(seed)
    ours.reset()
    actions = np.zeros((n, 8), dtype=np.float32)
    for _ in range(6):
        native_obs, *_ = native.step(actions)
        obs, _, done, infos = ours.step(actions)
    assert done.all()  # truncated after 6 steps
    for i in range(n):
        np.testing.assert_array_equal(infos[i]["terminal_observation"], native_obs[i])
        assert infos[i]["TimeLimit.truncated"]
        # the returned observation is already the next episode's first one: a fish at rest
        assert obs[i, 4:7] == pytest.approx([0, 0, 0])
        assert not np.array_equal(obs[i], native_obs[i])


def test_seeding_repeats_and_spaces():
    a = make_fish_vec_env(ENV, 3, seed=42)
    b = make_fish_vec_env(ENV, 3, seed=42)
    first = a.reset()
    np.testing.assert_array_equal(first, b.reset())
    assert first.shape == (3, 19) and first.dtype == np.float32
    assert a.observation_space.shape == (19,) and a.action_space.shape == (8,)
    assert a.num_envs == 3 and a.render_mode is None
    a.seed(42)
    np.testing.assert_array_equal(a.reset(), first)  # seed() applies to the next reset
    assert not np.array_equal(a.reset(), first)  # and only once
    assert a.get_attr("max_episode_steps") == [240] * 3
    assert a.env_is_wrapped(gym.Wrapper) == [False] * 3
    assert a.config.task == "goal"


def test_sb3_wrappers_and_checks_run():
    venv = VecCheckNan(VecNormalize(VecMonitor(make_fish_vec_env(ENV, 4, seed=1, max_episode_steps=10))),
                       raise_exception=True)
    obs = venv.reset()
    episodes = 0
    for _ in range(25):
        obs, rewards, dones, infos = venv.step(np.random.default_rng(0).uniform(-1, 1, (4, 8)).astype(np.float32))
        episodes += sum("episode" in info for info in infos)
        assert np.all(np.isfinite(obs))
    assert episodes >= 4  # VecMonitor saw every env finish at least once (10-step limit)


def test_errors():
    with pytest.raises(TypeError, match="PectoralFishVectorEnv"):
        FishVecEnv(gym.make(ENV))
    with pytest.raises(ValueError, match="unknown env id"):
        make_fish_vec_env("CartPole-v1", 2)
    with pytest.raises(ValueError, match="model"):
        make_fish_vec_env(ENV, 2, {"model": "full"})
    venv = make_fish_vec_env(ENV, 2, seed=0)
    venv.reset()
    with pytest.raises(RuntimeError, match="step_async"):
        venv.step_wait()
    venv.step_async(np.full((2, 8), np.nan, dtype=np.float32))
    with pytest.raises(ValueError, match="finite"):
        venv.step_wait()


def test_params_given_as_a_dict():
    venv = make_fish_vec_env(ENV, 2, {"params": {"fin_offset": 0.01}, "check_scaling_params": False})
    assert venv.config.params.fin_offset == 0.01
    assert venv.config.params.body_mass == pectoral_gym.model.params.FishParams().body_mass
    with pytest.raises(ValueError, match="params"):
        make_fish_vec_env(ENV, 2, {"params": {"fin_width": 1.0}})
