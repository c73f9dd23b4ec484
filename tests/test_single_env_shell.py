"""The single env's shell around the compiled step: the fin block in the fused call, the reset's shortcuts."""

import copy
import math
import pickle

import numpy as np
import pytest

from pectoral_gym import AveragedModel, FinBeat, FullModel
from pectoral_gym.envs import fused
from pectoral_gym.envs.core import EnvConfig, EnvCore
from pectoral_gym.envs.observation import FIN_OBS_FIELDS, OBS_FINS
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.model import strokes

REST = FinBeat.rest()


def fin_block_by_hand(fins: np.ndarray, period_max: float) -> np.ndarray:
    """The fin block of ``envs.observation``'s table, from the half-strokes (``docs/model.md`` 3.2), in Python."""
    block = np.empty((fins.shape[0], 2, FIN_OBS_FIELDS))
    for i in range(fins.shape[0]):
        for f in range(2):
            g_from, g_to = fins[i, f, strokes.ANGLE_FROM], fins[i, f, strokes.ANGLE_TO]
            duration, elapsed = fins[i, f, strokes.DURATION], fins[i, f, strokes.ELAPSED]
            left = max(duration - elapsed, 0.0)
            # the half-cosine from g_from (s = 0) to g_to (s = duration); parked or finished: at g_to
            angle = g_from + (g_to - g_from) * (1.0 - math.cos(math.pi * elapsed / duration)) / 2 if left > 0 else g_to
            block[i, f] = ((angle - math.pi / 2) / (math.pi / 2), (g_to - math.pi / 2) / (math.pi / 2),
                           1.0 if fins[i, f, strokes.POWER] > 0.5 else -1.0, min(left / period_max, 1.0))
    return block.reshape(fins.shape[0], -1)


@pytest.mark.parametrize(("n", "extra"), [(1, {}), (3, {}), (64, {}), (2, {"timing": True})])
def test_every_step_writes_the_fin_block_of_the_half_strokes_after_it(n, extra):
    # n = 1 and 3: the serial build of the one-argument step; 64: its parallel build; timing: the step in Python
    config = EnvConfig(model="averaged", observe_fins=True, **extra)
    core = EnvCore(n, config)
    core.reset(np.arange(n), [np.random.default_rng(i) for i in range(n)])
    rng = np.random.default_rng(5)
    period_max = config.period_range[1]
    for step in range(8):
        skip = (np.arange(n) % 2 == 1) if step % 4 == 3 else None  # a step with a mask: the fin block of every env
        core.step(rng.uniform(-1, 1, (n, 8)), skip)
        expected = fin_block_by_hand(core.model.fins, period_max)
        np.testing.assert_allclose(core.obs[:, OBS_FINS], expected.astype(np.float32), rtol=0, atol=2e-7,
                                   err_msg=f"step {step}")
        assert np.all(np.abs(core.obs[:, OBS_FINS]) <= 1.0)


def test_without_observe_fins_the_step_writes_no_fin_block():
    core = EnvCore(1, EnvConfig(model="averaged", observe_fins=False))
    core.reset(np.array([0]), (np.random.default_rng(1),))
    core.step(np.full((1, 8), 0.5))
    assert core.obs.shape == (1, 19) and core._step.fin_period is None
    with pytest.raises(ValueError, match="fin_period must be > 0 s or None, got 0.0"):
        fused.FusedStep(core.model, 0.5, core.action_buffer, core.cfg, core.beats, core.obs, core.out, core.fish,
                        core.ep, np.zeros((1, 3)), fin_period=0.0)


@pytest.mark.parametrize("model_class", [AveragedModel, FullModel])
def test_a_reset_to_fin_beats_is_the_reset_to_the_same_patterns_as_arrays(model_class):
    # FinBeats take the kept start rows, arrays the general path (strokes.init_fins on the selected rows)
    a, b = FinBeat.from_degrees(80, 20, 1.0, 3), FinBeat.from_degrees(100, 10, 0.7, 2)
    fast, general = model_class(4), model_class(4)
    rng = np.random.default_rng(2)
    for model in (fast, general):  # leave the fins mid-stroke, the cache and the integrals filled
        model.command(right=a, left=b)
        model.advance(1.3)
    for right, left, index in [(a, b, None), (None, a, np.array([1, 3])), (REST, REST, np.array([True, False] * 2)),
                               (a, b, np.array([2])), (b, None, None)]:
        state = rng.uniform(0.1, 1.0, (4 if index is None else np.ones(4, bool)[index].sum(), 6))
        fast.reset(state, right=right, left=left, index=index)
        general.reset(state, right=(REST if right is None else right).as_array(),
                      left=(REST if left is None else left).as_array(), index=index)
        for name in ("state", "integral", "fins", "pending", "forcing_cache"):
            np.testing.assert_array_equal(getattr(fast, name), getattr(general, name), err_msg=name)
        assert fast.time == general.time
        for model in (fast, general):
            model.advance(0.4)
        np.testing.assert_array_equal(fast.state, general.state)


def test_a_reset_at_the_start_of_a_power_stroke_by_hand():
    beat = FinBeat.from_degrees(80, 20, 1.0, 3)
    model = AveragedModel(1)
    model.reset(right=beat, left=None)
    start = np.radians(80 - 20)  # bias - amplitude, at rest until the first advance latches the pattern
    assert model.fins[0, 0, strokes.ANGLE_FROM] == model.fins[0, 0, strokes.ANGLE_TO] == pytest.approx(start)
    assert model.fins[0, 1, strokes.ANGLE_TO] == pytest.approx(math.pi / 2)  # the rest pattern: 90 deg, no amplitude
    np.testing.assert_array_equal(model.pending[0, 0], beat.as_array())
    assert model.fins[0, 0, strokes.DURATION] == 0.0 and model.fins[0, 0, strokes.POWER] == 0.0


def test_the_reset_observation_is_the_same_for_any_index_array():
    config = EnvConfig(model="averaged", observe_fins=True)
    cores = [EnvCore(3, config) for _ in range(3)]
    readonly = np.array([2, 0], dtype=np.int64)
    readonly.flags.writeable = False
    for core, index in zip(cores, (np.array([2, 0]), readonly, np.array([2, 0], dtype=np.int32)), strict=True):
        core.reset(np.arange(3), [np.random.default_rng(i) for i in range(3)])
        core.step(np.full((3, 8), 0.3))
        core.reset(index, [np.random.default_rng(10 + i) for i in range(3)])
    for name in ("obs", "out", "ep", "beats"):
        for other in cores[1:]:
            np.testing.assert_array_equal(getattr(cores[0], name), getattr(other, name), err_msg=name)
    np.testing.assert_array_equal(cores[0].out[[0, 2], tk.O_REWARD], 0.0)  # reset rows: zero but the distance
    assert np.all(cores[0].out[[0, 2], tk.O_DISTANCE] > 0)


def test_a_copy_steps_on_its_own_arrays():
    import gymnasium as gym

    env = gym.make("PectoralFish-Averaged-v2")
    env.reset(seed=4)
    env.step(np.full(8, 0.2, dtype=np.float32))
    for clone in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        ours = env.unwrapped.core.obs.copy()
        step = clone.step(np.full(8, -0.4, dtype=np.float32))
        np.testing.assert_array_equal(env.unwrapped.core.obs, ours)  # the original did not move
        np.testing.assert_array_equal(step[0], copy.deepcopy(env).step(np.full(8, -0.4, dtype=np.float32))[0])
        clone.reset(seed=1)
        np.testing.assert_array_equal(env.unwrapped.core.obs, ours)


@pytest.mark.parametrize("extra", [{}, {"timing": True}])
def test_a_non_finite_action_raises_and_leaves_the_episode_as_it_was(extra):
    import gymnasium as gym

    env = gym.make("PectoralFish-Averaged-v2", **extra).unwrapped  # timing: the core's step in Python
    env.reset(seed=2)
    env.step(np.full(8, 0.1, dtype=np.float32))
    obs, state, time = env.core.obs.copy(), env.fish_state, env.model.time
    action = np.full(8, 0.1, dtype=np.float32)
    action[6] = np.nan
    with pytest.raises(ValueError, match=r"action must be finite, got \[.*nan.*\]$"):
        env.step(action)
    np.testing.assert_array_equal(env.core.obs, obs)
    np.testing.assert_array_equal(env.fish_state, state)
    assert env.model.time == time
