"""EnvConfig.sensing: the observation through a simulated camera and the robot's observer (pectoral_gym.envs.sensed)."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401 - registers the envs
from pectoral_gym.envs import PectoralFishEnv, PectoralFishVectorEnv
from pectoral_gym.envs.config import EnvConfig
from pectoral_gym.envs.observation import OBS_COS_PSI, OBS_SIN_PSI, OBS_VELOCITY, OBS_X, OBS_Y
from pectoral_gym.registration import registered_settings
from pectoral_gym.sensing import SensingConfig

ENV_ID = "PectoralFish-Averaged-v1"


def _env(sensing=None, **kwargs):
    return PectoralFishEnv(**registered_settings(ENV_ID, {"sensing": sensing, **kwargs}))


def _actions(steps, seed=0, n=None):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, (steps, 8) if n is None else (steps, n, 8)).astype(np.float32)


def test_off_by_default_and_the_registered_ids_are_unchanged():
    assert EnvConfig().sensing is None
    for env_id in ("PectoralFish-Averaged-v0", "PectoralFish-Averaged-v1", "PectoralFish-Full-v0",
                   "PectoralFish-Full-v1"):
        assert "sensing" not in registered_settings(env_id)
        assert gym.make(env_id).unwrapped.core.sensed is None


def test_only_the_observation_changes_reward_termination_and_info_stay_true():
    plain, sensed = _env(), _env({})
    (obs0, info0), (obs1, info1) = plain.reset(seed=11), sensed.reset(seed=11)
    assert info0 == info1
    np.testing.assert_array_equal(plain.fish_state, sensed.fish_state)  # the same episode start
    assert not np.array_equal(obs0, obs1)
    for action in _actions(60):
        step0, step1 = plain.step(action), sensed.step(action)
        assert step0[1:] == step1[1:]  # reward, terminated, truncated, info
        np.testing.assert_array_equal(plain.fish_state, sensed.fish_state)
        np.testing.assert_array_equal(step0[0][19:], step1[0][19:])  # the fin block: true (replayed on the robot)
        if step0[2]:
            break


def test_reset_with_a_seed_reproduces_and_another_seed_differs():
    env = _env({})
    runs = []
    for seed in (5, 5, 6):
        obs = [env.reset(seed=seed)[0]]
        obs += [env.step(a)[0] for a in _actions(20)]
        runs.append(np.array(obs))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])


def test_single_and_vector_env_agree_through_autoresets():
    n, steps, seed = 3, 50, 40
    vector = PectoralFishVectorEnv(n, max_episode_steps=15, **registered_settings(ENV_ID, {"sensing": {}}))
    singles = [gym.wrappers.TimeLimit(_env({}), 15) for _ in range(n)]
    obs, _ = vector.reset(seed=seed)
    single_obs = [s.reset(seed=seed + i)[0] for i, s in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.array(single_obs))
    done = [False] * n
    for actions in _actions(steps, n=n):
        obs, rewards, terminated, truncated, _ = vector.step(actions)
        for i, s in enumerate(singles):
            if done[i]:  # the vector env's NEXT_STEP autoreset
                o, done[i] = s.reset()[0], False
            else:
                o, r, te, tr, _ = s.step(actions[i])
                assert (r, te, tr) == (rewards[i], terminated[i], truncated[i])
                done[i] = te or tr
            np.testing.assert_array_equal(obs[i], o)


def test_gymnasium_and_sb3_checkers_pass_without_warnings():
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(_env({}), skip_render_check=True)
        sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
        sb3.check_env(_env({}), warn=True)


def test_frame_poses_are_the_model_advanced_from_frame_to_frame():
    """Every frame's pose is the true model at the period's start, given the step's command, advanced to the frame."""
    env = _env({})
    env.reset(seed=3)
    core, sensed = env.core, env.core.sensed
    config = core.config
    model = config.model_spec().build(1, config.params)
    from pectoral_gym.model.models import REST

    model.reset(core.model.state.copy(), right=REST, left=REST)
    phase, frame_dt = sensed.levels[0, 4], 1.0 / config.sensing.frame_rate
    t, k = 0.0, 0
    for step, action in enumerate(_actions(12, seed=2)):
        for name in ("state", "fins", "forcing_cache", "pending", "integral"):  # the env's model at the start
            getattr(model, name)[...] = getattr(core.model, name)
        env.step(action)
        model.command_array(core.beats.copy())
        end = (step + 1) * config.control_period
        while phase + k * frame_dt <= end:
            model.advance(phase + k * frame_dt - t)
            t = phase + k * frame_dt
            np.testing.assert_allclose(sensed.poses[0, k % sensed.poses.shape[1]], model.state[0, :3], rtol=0,
                                       atol=1e-12)
            k += 1
        assert sensed.recorded[0] == k
        t = end


def test_pose_noise_has_the_set_standard_deviation():
    """At the reset the observation shows one noisy frame of the start pose: its spread over episodes is the setting."""
    noise, heading = 5e-3, math.radians(2.0)
    env = _env({"position_noise": noise, "heading_noise": heading})
    errors = []
    for seed in range(400):
        obs, _ = env.reset(seed=seed)
        x, y, psi = env.fish_state[:3]
        errors.append((obs[OBS_X] - x, obs[OBS_Y] - y, _wrap(math.atan2(obs[OBS_SIN_PSI], obs[OBS_COS_PSI]) - psi)))
    spread = np.std(np.array(errors), axis=0)
    # the sample deviation of 400 normal draws has a relative spread of 1/sqrt(800) = 3.5 %: 4 sigma
    np.testing.assert_allclose(spread, [noise, noise, heading], rtol=0.14)


def _wrap(angle):
    return (angle + math.pi) % (2 * math.pi) - math.pi


def test_a_lost_camera_leaves_the_observer_at_the_start():
    """Every frame dropped: the observer never updates, so the observation holds the start pose, at rest."""
    env = _env({"frame_drop": 1.0, "position_noise": 0.0, "heading_noise": 0.0})
    obs, _ = env.reset(seed=1)
    start = obs.copy()
    np.testing.assert_allclose(obs[[OBS_X, OBS_Y]], env.fish_state[:2], atol=1e-6)  # float32
    for action in _actions(6):
        obs = env.step(action)[0]
        np.testing.assert_array_equal(obs[:4], start[:4])
        np.testing.assert_array_equal(obs[OBS_VELOCITY], 0.0)
    assert not np.allclose(env.fish_state[:2], start[:2], atol=1e-3)  # the fish itself swam


@pytest.mark.parametrize("latency", [0.0, 0.3])
def test_frames_are_delivered_after_the_latency(latency):
    env = _env({"latency": latency, "frame_drop": 0.0})
    env.reset(seed=9)
    sensed = env.core.sensed
    phase, rate = sensed.levels[0, 4], env.core.config.sensing.frame_rate
    for step, action in enumerate(_actions(3), start=1):
        env.step(action)
        deadline = step * 0.5 - latency  # frames captured at phase + k / rate up to here have arrived
        assert sensed.frame[0] == math.floor((deadline - phase) * rate + 1e-9) + 1
        assert sensed.last[0, 0] == pytest.approx(phase + (sensed.frame[0] - 1) / rate)


@pytest.mark.parametrize("sensing, message", [
    ("yes", "sensing must be None, True, or a mapping"),
    ({"pose_noise": 1.0}, "unknown settings \\['pose_noise'\\]"),
    ({"latency": 0.5}, "below the control period"),
    ({"frame_drop": (0.0, 1.5)}, "must stay <= 1.0"),
    ({"position_noise": -1e-3}, "0 <= low <= high"),
    ({"heading_noise": (0.1, 0.01)}, "0 <= low <= high"),
    ({"frame_rate": 0}, "frame_rate"),
])
def test_invalid_settings_are_refused_with_a_clear_error(sensing, message):
    with pytest.raises(ValueError, match=message):
        EnvConfig(sensing=sensing)


def test_settings_coerce_and_draw_within_their_ranges():
    assert EnvConfig(sensing=True).sensing == SensingConfig() == EnvConfig(sensing={}).sensing
    assert EnvConfig(sensing=False).sensing is None
    config = SensingConfig(latency=0.05, frame_drop=(0.1, 0.2))
    assert config.latency == (0.05, 0.05)
    levels = np.array([config.draw(np.random.default_rng(s)) for s in range(200)])
    assert np.all((levels[:, 2] >= 0.1) & (levels[:, 2] <= 0.2)) and np.all(levels[:, 3] == 0.05)
    assert np.all((levels[:, 4] > 0) & (levels[:, 4] <= 1 / 30))


def test_a_run_records_sensing_and_evaluations_leave_it_out_unless_asked(tmp_path):
    pytest.importorskip("yaml")
    from pectoral_gym.agents.training.evaluate import trained_env_kwargs
    from pectoral_gym.agents.training.policy import _trained_settings

    (tmp_path / "config.yaml").write_text("env_id: PectoralFish-Averaged-v1\nenv_kwargs:\n  task: goal\n"
                                          "  sensing: {latency: 0.05}\n")
    assert trained_env_kwargs(tmp_path, "PectoralFish-Full-v1") == {"task": "goal"}
    import yaml

    config = yaml.safe_load((tmp_path / "config.yaml").read_text())
    assert _trained_settings(config, tmp_path)["sensing"] == {"latency": 0.05}
