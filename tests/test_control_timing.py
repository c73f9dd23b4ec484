"""EnvConfig.timing: the robot's command delay and late ticks in the simulated envs (pectoral_gym.envs.timing)."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401 - registers the envs
from pectoral_gym.envs import PectoralFishEnv, PectoralFishVectorEnv
from pectoral_gym.envs.config import EnvConfig
from pectoral_gym.envs.observation import OBS_OMEGA
from pectoral_gym.envs.timing import LAG, SPAN, TimingConfig
from pectoral_gym.model.models import REST
from pectoral_gym.registration import registered_settings

NO_JITTER = {"latency_jitter": 0.0, "tick_jitter": 0.0}


def _env(env_id="PectoralFish-Averaged-v2", **kwargs):
    return PectoralFishEnv(**registered_settings(env_id, kwargs))


def _actions(steps, seed=0, n=None):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, (steps, 8) if n is None else (steps, n, 8)).astype(np.float32)


def _run(env, seed, actions):
    states = [env.reset(seed=seed)[0]]
    for action in actions:
        obs, _, terminated, _, _ = env.step(action)
        states.append(obs)
        if terminated:
            break
    return np.array(states)


def test_off_by_default_in_every_registered_id():
    assert EnvConfig().timing is None
    for env_id in ("PectoralFish-Averaged-v0", "PectoralFish-Averaged-v1", "PectoralFish-Averaged-v2",
                   "PectoralFish-Full-v0", "PectoralFish-Full-v1", "PectoralFish-Full-v2"):
        assert "timing" not in registered_settings(env_id)
        assert gym.make(env_id).unwrapped.core.timing.settings is None


@pytest.mark.parametrize("env_id", ["PectoralFish-Averaged-v2", "PectoralFish-Full-v2"])
def test_zero_delay_and_jitter_is_the_plain_step_to_the_bit(env_id):
    actions = _actions(30)
    plain = _run(_env(env_id), 3, actions)
    timed = _run(_env(env_id, timing={"command_latency": 0.0, **NO_JITTER}), 3, actions)
    np.testing.assert_array_equal(plain, timed)


@pytest.mark.parametrize("env_id", ["PectoralFish-Averaged-v2", "PectoralFish-Full-v2"])
def test_a_delayed_command_is_the_model_run_on_the_old_command_then_the_new(env_id):
    """Against the model driven by hand: advance ``d`` on the previous patterns, command, advance ``dt - d``."""
    delay = 0.2
    env = _env(env_id, timing={"command_latency": delay, **NO_JITTER})
    plain = _env(env_id)
    env.reset(seed=8)
    plain.reset(seed=8)
    config = env.unwrapped.config
    model = config.model_spec().build(1, config.params)
    model.reset(env.unwrapped.fish_state[None], right=REST, left=REST)
    dt = config.control_period
    for action in _actions(12, seed=1):
        env.step(action)
        plain.step(action)
        model.advance(delay)
        model.command_array(config.decode(np.asarray(action, dtype=np.float64).reshape(2, 4))[None])
        model.advance(dt - delay)
        np.testing.assert_allclose(env.unwrapped.fish_state, model.state[0], rtol=0, atol=1e-12)
    # the delay matters: the plain env, commanding at once, ends elsewhere
    assert np.linalg.norm(plain.unwrapped.fish_state[:2] - model.state[0, :2]) > 1e-3


def test_late_ticks_lengthen_and_shorten_periods_and_the_mean_yaw_rate_is_over_the_real_period():
    env = _env(timing={"command_latency": (0.0, 0.05), "latency_jitter": 0.05, "tick_jitter": 0.2})
    env.reset(seed=4)
    timing = env.unwrapped.core.timing
    spans, late = [], 0.0
    for action in _actions(25, seed=2):
        psi0 = env.unwrapped.fish_state[2]
        obs, *_ = env.step(action)
        lag, span = timing.timing[0]
        spans.append(span)
        assert 0.0 <= lag < span
        # the mean yaw rate observed times the period is the heading change over it (closed form: the integral)
        assert obs[OBS_OMEGA] * span == pytest.approx(env.unwrapped.fish_state[2] - psi0, rel=1e-5, abs=1e-7)
        # the grid stays: a late observation makes its period longer and the next one shorter
        assert span == pytest.approx(0.5 + timing.late[0] - late, abs=1e-15)
        late = timing.late[0]
    assert min(spans) < 0.45 and max(spans) > 0.55  # it did jitter (the yaw check above then means something)


def test_with_the_camera_the_frames_follow_the_real_instants():
    """The simulated camera captures every frame up to the last observation's real instant, no more."""
    env = _env(timing={"command_latency": (0.05, 0.1), "latency_jitter": 0.02, "tick_jitter": 0.08}, sensing={})
    env.reset(seed=6)
    core = env.unwrapped.core
    frame_dt = 1.0 / core.sensed.settings.frame_rate
    phase = core.sensed.levels[0, 4]
    for k, action in enumerate(_actions(20, seed=3), start=1):
        env.step(action)
        t = k * 0.5 + core.timing.late[0]  # the observation's instant since the reset
        assert core.sensed.recorded[0] == math.floor((t - phase) / frame_dt) + 1


def test_seeded_resets_reproduce_and_the_vector_env_matches_single_envs():
    settings = {"timing": {}}
    env = _env(**settings)
    actions = _actions(20)
    first, again, other = _run(env, 5, actions), _run(env, 5, actions), _run(env, 6, actions)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first[:5], other[:5])
    n = 3
    vector = PectoralFishVectorEnv(n, **registered_settings("PectoralFish-Averaged-v2", settings))
    singles = [_env(**settings) for _ in range(n)]
    obs, _ = vector.reset(seed=20)
    np.testing.assert_array_equal(obs, [s.reset(seed=20 + i)[0] for i, s in enumerate(singles)])
    done = [False] * n
    for step_actions in _actions(30, n=n):
        obs, _, terminated, truncated, _ = vector.step(step_actions)
        for i, single in enumerate(singles):
            if done[i]:  # the vector env's NEXT_STEP autoreset
                expected, done[i] = single.reset()[0], False
            else:
                expected, _, te, tr, _ = single.step(step_actions[i])
                done[i] = te or tr
            np.testing.assert_array_equal(obs[i], expected)


def test_a_non_finite_action_raises_and_draws_nothing():
    env, twin = _env(timing={}), _env(timing={})
    env.reset(seed=2)
    twin.reset(seed=2)
    bad = np.full(8, 0.2, dtype=np.float32)
    bad[3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        env.step(bad)
    for action in _actions(5):
        np.testing.assert_array_equal(env.step(action)[0], twin.step(action)[0])


@pytest.mark.parametrize("timing, message", [
    ({"command_latency": (0.3, 0.47)}, "longest command delay"),
    ({"command_latency": (0.2, 0.1)}, "low <= high"),
    ({"tick_jitter": -0.01}, "tick_jitter"),
    ({"latency_jitter": float("nan")}, "latency_jitter"),
    ({"delay": 0.1}, "unknown settings"),
    ("fast", "mapping"),
])
def test_bad_settings_are_named(timing, message):
    with pytest.raises(ValueError, match=message):
        EnvConfig(timing=timing)


def test_coerce_and_defaults():
    assert TimingConfig.coerce(None) is None and TimingConfig.coerce(False) is None
    assert TimingConfig.coerce(True) == TimingConfig() == TimingConfig.coerce({})
    assert TimingConfig(command_latency=0.1).command_latency == (0.1, 0.1)
    assert LAG == 0 and SPAN == 1


def test_check_env_passes_without_warnings():
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    for env_id in ("PectoralFish-Averaged-v2", "PectoralFish-Full-v2"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(gym.make(env_id, timing={}).unwrapped, skip_render_check=True)
            sb3_check_env(gym.make(env_id, timing={}), warn=True)


def test_a_run_records_timing_and_evaluations_leave_it_out_unless_asked(tmp_path):
    yaml = pytest.importorskip("yaml")
    from pectoral_gym.agents.training.evaluate import trained_env_kwargs
    from pectoral_gym.agents.training.policy import _trained_settings

    (tmp_path / "config.yaml").write_text("env_id: PectoralFish-Averaged-v2\nenv_kwargs:\n  task: goal\n"
                                          "  timing: {command_latency: [0.0, 0.1]}\n")
    assert trained_env_kwargs(tmp_path, "PectoralFish-Full-v2") == {"task": "goal"}
    config = yaml.safe_load((tmp_path / "config.yaml").read_text())
    assert _trained_settings(config, tmp_path)["timing"] == {"command_latency": [0.0, 0.1]}


def test_the_guides_cost_snippet_runs(capsys):
    from doc_snippets import ROOT, snippet, with_constants

    code = with_constants(snippet("timing-cost", ROOT / "docs" / "guide" / "envs.md"), STEPS=3)
    exec(compile(code, "timing-cost", "exec"), {})  # noqa: S102 - the docs' own snippet
    assert "ratio" in capsys.readouterr().out
