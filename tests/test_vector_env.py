"""The native vector env: equal to single envs step for step, and Gymnasium's vector conventions."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym.envs import PectoralFishVectorEnv
from pectoral_gym.registration import registered_settings

IDS = {"averaged": "PectoralFish-Averaged-v0", "full": "PectoralFish-Full-v0"}
# goal_radius 0.45 m makes successes (terminations) frequent; max_episode_steps 12 adds truncations.
CASES = [("goal", {"goal_radius": 0.45}), ("track", {})]


def actions_for(num_envs, steps, seed=0):
    return np.random.default_rng(seed).uniform(-1.2, 1.2, (steps, num_envs, 8)).astype(np.float32)


@pytest.mark.parametrize("model", ["averaged", "full"])
@pytest.mark.parametrize(("task", "kwargs"), CASES)
def test_vector_env_equals_single_envs_step_for_step(model, task, kwargs):
    n, steps, seed, horizon = 3, 40, 5, 12
    venv = PectoralFishVectorEnv(n, **registered_settings(IDS[model], dict(task=task, max_episode_steps=horizon,
                                                                          **kwargs)))
    envs = [gym.make(IDS[model], task=task, max_episode_steps=horizon, **kwargs) for _ in range(n)]
    vobs, _ = venv.reset(seed=seed)
    done = [False] * n
    for i, env in enumerate(envs):
        obs, _ = env.reset(seed=seed + i)
        np.testing.assert_array_equal(vobs[i], obs)
    seen = {"terminated": 0, "truncated": 0}
    for actions in actions_for(n, steps):
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(actions)
        for i, env in enumerate(envs):
            if done[i]:  # next-step autoreset: the reset's observation and info
                obs, info = env.reset()
                reward, terminated, truncated = 0.0, False, False
            else:
                obs, reward, terminated, truncated, info = env.step(actions[i])
            np.testing.assert_array_equal(vobs[i], obs)
            assert vrew[i] == reward and vterm[i] == terminated and vtrunc[i] == truncated
            for key in vinfo:
                if key.startswith("_"):
                    assert vinfo[key][i]
                else:
                    assert vinfo[key][i] == info[key]
            assert set(info) == {k for k in vinfo if not k.startswith("_")}
            done[i] = terminated or truncated
            seen["terminated"] += terminated
            seen["truncated"] += truncated
    assert seen["truncated"] > 0
    if task == "goal":
        assert seen["terminated"] > 0


@pytest.mark.parametrize("task", ["goal", "track"])
def test_vector_env_equals_sync_vector_env(task):
    n = 4
    venv = gym.make_vec(IDS["averaged"], num_envs=n, vectorization_mode="vector_entry_point",
                        task=task, max_episode_steps=10, goal_radius=0.4)
    sync = gym.make_vec(IDS["averaged"], num_envs=n, vectorization_mode="sync",
                        task=task, max_episode_steps=10, goal_radius=0.4)
    assert isinstance(venv.unwrapped, PectoralFishVectorEnv) and isinstance(sync, SyncVectorEnv)
    a, _ = venv.reset(seed=3)
    b, _ = sync.reset(seed=3)
    np.testing.assert_array_equal(a, b)
    for actions in actions_for(n, 25, seed=1):
        out_a = venv.step(actions)
        out_b = sync.step(actions)
        for x, y in zip(out_a[:4], out_b[:4], strict=True):
            np.testing.assert_array_equal(x, y)
        info_a, info_b = out_a[4], out_b[4]
        assert set(info_b) <= set(info_a)
        for key, value in info_b.items():
            np.testing.assert_array_equal(info_a[key], value, err_msg=key)
            # SyncVectorEnv stores np.bool_ scalars in an object array (gymnasium 1.4 _add_info); ours is bool
            assert info_a[key].dtype == (np.bool_ if value.dtype == object else value.dtype), key


def test_parallel_path_equals_single_envs():
    """64 envs and more run the threaded kernels; they must give the same numbers."""
    n, seed = 70, 9
    venv = PectoralFishVectorEnv(n, **registered_settings("PectoralFish-Averaged-v0", dict(max_episode_steps=6)))
    vobs, _ = venv.reset(seed=seed)
    actions = actions_for(n, 8)
    for i in (0, 41, 69):
        env = gym.make(IDS["averaged"], max_episode_steps=6)
        obs, _ = env.reset(seed=seed + i)
        np.testing.assert_array_equal(vobs[i], obs)
    outs = [venv.step(a) for a in actions]
    for i in (0, 41, 69):
        env = gym.make(IDS["averaged"], max_episode_steps=6)
        env.reset(seed=seed + i)
        done = False
        for a, (vobs, vrew, *_rest) in zip(actions, outs, strict=True):
            if done:
                obs, _ = env.reset()
                done, reward = False, 0.0
            else:
                obs, reward, terminated, truncated, _ = env.step(a[i])
                done = terminated or truncated
            np.testing.assert_array_equal(vobs[i], obs)
            assert vrew[i] == reward


def test_vector_spaces_dtypes_and_metadata():
    n = 5
    venv = gym.make_vec(IDS["full"], num_envs=n, vectorization_mode="vector_entry_point")
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert venv.unwrapped.max_episode_steps == 240
    assert venv.num_envs == n
    assert venv.single_action_space == gym.spaces.Box(-1, 1, (8,), np.float32)
    assert venv.single_observation_space == gym.make(IDS["full"]).observation_space
    assert venv.action_space.shape == (n, 8) and venv.observation_space.shape == (n, 19)
    obs, info = venv.reset(seed=0)
    assert obs.shape == (n, 19) and obs.dtype == np.float32
    assert set(info) == set(venv.step(np.zeros((n, 8)))[4]) and info["_distance"].all()
    obs, info = venv.reset(seed=0)
    assert venv.observation_space.contains(obs)
    venv.action_space.seed(0)
    obs, rew, term, trunc, info = venv.step(venv.action_space.sample())
    assert venv.observation_space.contains(obs)
    assert rew.shape == (n,) and rew.dtype == np.float64
    assert term.dtype == np.bool_ and trunc.dtype == np.bool_ and term.shape == trunc.shape == (n,)
    for key, value in info.items():
        assert value.shape == (n,), key
    assert info["is_success"].dtype == np.bool_ and info["_reward_progress"].all()
    venv.close()


def test_vector_accessors_match_the_single_envs():
    venv = PectoralFishVectorEnv(2, **registered_settings("PectoralFish-Averaged-v0"))
    assert venv.observation_structure == gym.make("PectoralFish-Averaged-v0").unwrapped.observation_structure
    venv.reset(seed=4)
    actions = np.array([[-1, 1, 0, 0.5, 1, -1, 1, -1], [0, 0, 0, 0, 0, 0, 0, 0]], np.float32)
    obs, *_ = venv.step(actions)
    np.testing.assert_array_equal(venv.last_observations, obs)
    for i in range(2):
        env = gym.make("PectoralFish-Averaged-v0").unwrapped
        env.reset(seed=4 + i)
        env.step(actions[i])
        np.testing.assert_array_equal(venv.fin_patterns[i], env.fin_patterns)


def test_vector_reset_seeds_and_mask():
    venv = PectoralFishVectorEnv(3, **registered_settings("PectoralFish-Averaged-v0"))
    a, _ = venv.reset(seed=[10, 11, 12])
    b, _ = venv.reset(seed=10)
    np.testing.assert_array_equal(a, b)
    c, _ = venv.reset(seed=[None, 11, None])
    np.testing.assert_array_equal(c[1], a[1])
    before = venv.last_observations
    d, _ = venv.reset(options={"reset_mask": np.array([False, True, False])})
    np.testing.assert_array_equal(d[[0, 2]], before[[0, 2]])
    with pytest.raises(ValueError):
        venv.reset(seed=[1, 2])


def test_vector_action_checks():
    venv = PectoralFishVectorEnv(3, **registered_settings("PectoralFish-Averaged-v0"))
    venv.reset(seed=0)
    actions = np.zeros((3, 8), np.float32)
    actions[2, 0] = np.nan
    with pytest.raises(ValueError, match="action must be finite"):
        venv.step(actions)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((2, 8)))
    venv.step(np.zeros((3, 8)))  # float64 and lists of numbers are fine
    venv.step(np.zeros((3, 8), dtype=np.int64))
    with pytest.raises(ValueError):
        PectoralFishVectorEnv(0)
    with pytest.raises(ValueError, match="render_mode"):
        PectoralFishVectorEnv(2, render_mode="human")  # rgb_array only (tests/test_vector_render.py)
