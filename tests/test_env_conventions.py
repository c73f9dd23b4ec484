"""Gymnasium conventions of the fish envs: reset info, spec round trip, autoreset modes, pickling."""

import copy
import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import EnvSpec
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym import FishParams
from pectoral_gym.envs import PectoralFishEnv, PectoralFishVectorEnv
from pectoral_gym.registration import registered_settings

IDS = ("PectoralFish-Averaged-v0", "PectoralFish-Full-v0")
TASKS = ("goal", "track")


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("task", TASKS)
def test_reset_info_has_the_step_keys_zero_terms_and_the_real_distance(env_id, task):
    env = gym.make(env_id, task=task)
    obs, info = env.reset(seed=4)
    _, _, _, _, step_info = env.step(env.action_space.sample())
    assert list(info) == list(step_info)
    for key, value in info.items():
        assert isinstance(value, np.generic), key  # numpy scalars (TorchRL reads .dtype)
        assert type(value) is type(step_info[key]), key
    for key in info:
        if key.startswith("reward_"):
            assert info[key] == 0.0, key
    # the distance from the observation: |target offset| in the body frame
    assert info["distance"] == pytest.approx(math.hypot(obs[7], obs[8]), rel=1e-6)
    assert info["distance"] > 0
    if task == "goal":
        assert not info["is_success"]
    else:
        assert info["tracking_error"] == info["distance"]


@pytest.mark.parametrize("task", TASKS)
def test_vector_reset_info_has_the_step_keys(task):
    venv = PectoralFishVectorEnv(3, **registered_settings("PectoralFish-Averaged-v0", dict(task=task)))
    obs, info = venv.reset(seed=0)
    _, _, _, _, step_info = venv.step(np.zeros((3, 8)))
    assert set(info) == set(step_info)
    for i in range(3):
        assert info["distance"][i] == pytest.approx(math.hypot(obs[i, 7], obs[i, 8]), rel=1e-6)
    assert all(info["_" + k].all() for k in info if not k.startswith("_"))
    _, info = venv.reset(options={"reset_mask": np.array([False, True, False])})
    assert info["_distance"].tolist() == [False, True, False]
    assert info["distance"][0] == 0.0 and info["distance"][1] > 0  # zero where not reset, as SyncVectorEnv


def test_spec_json_round_trip_with_custom_params_gives_the_same_env():
    params = FishParams(fin_span=0.07, body_mass=0.9)
    env = gym.make("PectoralFish-Full-v0", params=params, task="track")
    spec = EnvSpec.from_json(env.spec.to_json())
    assert isinstance(spec.kwargs["params"], dict)  # JSON keeps the dataclass as a dict
    again = gym.make(spec)
    assert again.unwrapped.config == env.unwrapped.config
    a, _ = env.reset(seed=11)
    b, _ = again.reset(seed=11)
    np.testing.assert_array_equal(a, b)
    action = np.linspace(-1, 1, 8, dtype=np.float32)
    np.testing.assert_array_equal(env.step(action)[0], again.step(action)[0])


@pytest.mark.parametrize("env_id", ("PectoralFish-Averaged-v0", "PectoralFish-Averaged-v2"))
def test_info_is_a_new_dict_every_step_so_a_wrappers_key_stays_in_its_step(env_id):
    # RecordEpisodeStatistics writes "episode" into the info of an episode's last step: a dict the env
    # handed out before must not be the one it fills next.
    env = gym.wrappers.RecordEpisodeStatistics(gym.make(env_id))
    env.reset(seed=5)
    env.action_space.seed(5)
    infos = []
    while not infos or "episode" not in infos[-1]:
        _, _, terminated, truncated, info = env.step(env.action_space.sample())
        infos.append(info)
        assert ("episode" in info) == (terminated or truncated)
    assert len(infos) > 1
    assert len({id(info) for info in infos}) == len(infos)
    _, reset_info = env.reset()
    _, _, _, _, info = env.step(env.action_space.sample())
    for fresh in (reset_info, info):
        assert "episode" not in fresh
        assert ("cost" in fresh) == env.unwrapped.config.stop_band  # v2's stop band: info["cost"]
        assert list(fresh) == list(infos[0])


@pytest.mark.parametrize("env_id", IDS)
def test_pickle_and_deepcopy_at_any_time_also_after_render(env_id):
    pytest.importorskip("pygame")
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=2)
    env.step(np.zeros(8, np.float32))
    assert env.render().shape == (460, 920, 3)
    action = np.full(8, 0.3, np.float32)
    for clone in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        np.testing.assert_array_equal(clone.step(action)[0], copy.deepcopy(env).step(action)[0])
        assert clone.render().shape == (460, 920, 3)  # a copy draws with its own renderer
    env.close()


def test_render_fps_is_the_control_rate():
    assert gym.make("PectoralFish-Averaged-v0").metadata["render_fps"] == 2.0
    env = gym.make("PectoralFish-Averaged-v0", control_period=0.25)
    assert env.metadata["render_fps"] == 4.0
    assert PectoralFishEnv.metadata["render_fps"] == 2  # the class keeps the default's rate


def test_observation_bounds_scale_with_the_settings_and_hold_on_extreme_rollouts():
    env = PectoralFishEnv(**registered_settings("PectoralFish-Full-v0",
                                                dict(control_period=1.0, ref_speed=0.05, task="track")))
    low, high = env.observation_space.low, env.observation_space.high
    assert low[0] == -2.0 and high[0] == pytest.approx(2.30 + 2.0)  # margin 2 m/s x 1 s
    assert high[9] == pytest.approx(0.0505)
    env = gym.make("PectoralFish-Full-v0", max_episode_steps=60)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    for _ in range(300):  # bang-bang actions: the fastest turns and swims
        obs, _, terminated, truncated, _ = env.step(rng.choice([-1.0, 1.0], 8).astype(np.float32))
        assert env.observation_space.contains(obs)
        if terminated or truncated:
            env.reset()


def _sync(mode, n, **kwargs):
    return SyncVectorEnv([lambda: gym.make("PectoralFish-Averaged-v0", **kwargs) for _ in range(n)],
                         autoreset_mode=mode)


def _assert_infos_equal(ours, theirs, where):
    assert set(theirs) <= set(ours), where
    for key, value in theirs.items():
        if isinstance(value, dict):
            _assert_infos_equal(ours[key], value, f"{where}/{key}")
        elif value.dtype == object and key != "final_obs":  # SyncVectorEnv keeps np.bool_ scalars as objects
            np.testing.assert_array_equal(ours[key], value.astype(bool), err_msg=f"{where}/{key}")
        elif key == "final_obs":
            for a, b in zip(ours[key], value, strict=True):
                assert (a is None and b is None) or np.array_equal(a, b), where
        else:
            np.testing.assert_array_equal(ours[key], value, err_msg=f"{where}/{key}")


@pytest.mark.parametrize("mode", [AutoresetMode.SAME_STEP, AutoresetMode.NEXT_STEP])
@pytest.mark.parametrize("task", TASKS)
def test_autoreset_modes_equal_sync_vector_env(mode, task):
    n, kwargs = 3, {"task": task, "max_episode_steps": 7, "goal_radius": 0.45}
    ours = gym.make_vec("PectoralFish-Averaged-v0", num_envs=n, vectorization_mode="vector_entry_point",
                        autoreset_mode=mode, **kwargs)
    sync = _sync(mode, n, **kwargs)
    assert ours.metadata["autoreset_mode"] == mode == sync.metadata["autoreset_mode"]
    a, info_a = ours.reset(seed=1)
    b, info_b = sync.reset(seed=1)
    np.testing.assert_array_equal(a, b)
    _assert_infos_equal(info_a, info_b, "reset")
    finals = 0
    for t, actions in enumerate(np.random.default_rng(3).uniform(-1, 1, (20, n, 8))):
        out_a, out_b = ours.step(actions), sync.step(actions)
        for x, y in zip(out_a[:4], out_b[:4], strict=True):
            np.testing.assert_array_equal(x, y, err_msg=f"step {t}")
        _assert_infos_equal(out_a[4], out_b[4], f"step {t}")
        finals += int("final_obs" in out_b[4])
    if mode is AutoresetMode.SAME_STEP:
        assert finals > 0


def test_disabled_autoreset_equals_sync_vector_env_and_refuses_to_step_a_finished_env():
    n, kwargs = 2, {"max_episode_steps": 3}
    ours = PectoralFishVectorEnv(n, **registered_settings("PectoralFish-Averaged-v0",
                                                          dict(autoreset_mode="Disabled", **kwargs)))
    sync = _sync(AutoresetMode.DISABLED, n, **kwargs)
    assert ours.metadata["autoreset_mode"] is AutoresetMode.DISABLED
    np.testing.assert_array_equal(ours.reset(seed=0)[0], sync.reset(seed=0)[0])
    actions = np.zeros((n, 8))
    for _ in range(3):
        out_a, out_b = ours.step(actions), sync.step(actions)
    assert out_a[3].all() and out_b[3].all()  # truncated
    with pytest.raises(ValueError, match="reset_mask"):
        ours.step(actions)
    mask = np.array([True, False])
    np.testing.assert_array_equal(ours.reset(options={"reset_mask": mask})[0],
                                  sync.reset(options={"reset_mask": mask})[0])
    with pytest.raises(ValueError, match=r"envs \[1\]"):
        ours.step(actions)


def test_bad_autoreset_mode():
    with pytest.raises(ValueError, match="autoreset_mode"):
        PectoralFishVectorEnv(2, autoreset_mode="sometimes")
