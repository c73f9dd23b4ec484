"""The envs with real RL clients: TorchRL and Minari (the ``clients`` extra; skipped without it)."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym import FishParams
from pectoral_gym.envs import PectoralFishVectorEnv
from pectoral_gym.registration import registered_settings

INFO_KEYS = {"reward_progress", "reward_goal", "reward_wall", "reward_energy", "reward_time", "distance",
             "is_success"}


@pytest.mark.parametrize("env_id", ["PectoralFish-Averaged-v0", "PectoralFish-Full-v0"])
def test_torchrl_gym_env_passes_check_env_specs(env_id):
    pytest.importorskip("torchrl")
    from torchrl.envs import GymEnv
    from torchrl.envs.utils import check_env_specs

    env = GymEnv(env_id)
    env.auto_register_info_dict()  # reads the info's dtypes: fails on Python floats
    check_env_specs(env)
    rollout = env.rollout(6)
    assert rollout["observation"].shape == (6, 19)
    assert INFO_KEYS <= set(rollout["next"].keys())  # the info keys, read from numpy scalars


@pytest.mark.parametrize("mode", ["SameStep", "Disabled"])
def test_torchrl_wraps_the_native_vector_env(mode):
    pytest.importorskip("torchrl")
    from torchrl.envs import GymWrapper
    from torchrl.envs.utils import check_env_specs

    venv = PectoralFishVectorEnv(3, **registered_settings("PectoralFish-Averaged-v0",
                                                          dict(autoreset_mode=mode, max_episode_steps=4)))
    env = GymWrapper(venv)
    assert tuple(env.batch_size) == (3,)
    check_env_specs(env)
    if mode == "SameStep":
        rollout = env.rollout(10, break_when_any_done=False)  # through two truncations
        assert rollout["next", "truncated"].sum() == 6
        np.testing.assert_array_equal(rollout["next", "distance"].numpy() > 0, True)


def test_minari_records_infos_and_recovers_the_env_with_custom_params(tmp_path, monkeypatch):
    minari = pytest.importorskip("minari")
    pytest.importorskip("h5py")
    pytest.importorskip("jax")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    robot = FishParams(fin_span=0.07)
    env = minari.DataCollector(gym.make("PectoralFish-Full-v0", params=robot, max_episode_steps=5),
                               record_infos=True)
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(12):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # Minari's advice to add a description, an eval env
        dataset = env.create_dataset(dataset_id="pectoral/test-v0", algorithm_name="random")
    assert dataset.total_episodes >= 2
    episode = next(dataset.iterate_episodes())
    assert set(episode.infos) == INFO_KEYS
    assert len(episode.infos["distance"]) == len(episode.rewards) + 1  # the reset's info too
    assert episode.infos["reward_progress"][0] == 0.0 and episode.infos["distance"][0] > 0
    recovered = dataset.recover_environment()
    assert recovered.unwrapped.config.params == robot
    first, _ = recovered.reset(seed=0)
    again, _ = gym.make("PectoralFish-Full-v0", params=robot).reset(seed=0)
    np.testing.assert_array_equal(first, again)
