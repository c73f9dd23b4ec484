"""The native vector env renders as Gymnasium's vector envs do: one frame per env, the frames of single envs."""

import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # no display needed

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("pygame")

import pectoral_gym  # noqa: F401, E402  (registers the ids)
from pectoral_gym.versions import LATEST_AVERAGED, LATEST_FULL  # noqa: E402

N = 3


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_frames_are_those_of_single_envs_through_autoresets(mode):
    # SyncVectorEnv of single envs is the reference: the same seeds, actions and autoresets give the same pixels
    makers = {vectorization: gym.make_vec(LATEST_AVERAGED, N, vectorization_mode=vectorization,
                                          render_mode="rgb_array", max_episode_steps=4,
                                          **({"vector_kwargs": {"autoreset_mode": mode}} if vectorization == "sync"
                                             else {"autoreset_mode": mode}))
              for vectorization in ("vector_entry_point", "sync")}
    native, sync = makers["vector_entry_point"], makers["sync"]
    assert native.metadata["render_fps"] == sync.metadata["render_fps"] == 2.0
    native.reset(seed=5)
    sync.reset(seed=5)
    actions = np.random.default_rng(0).uniform(-1, 1, (7, N, 8))
    first = native.render()
    for action in actions:  # through the truncation at step 4 and the next episode's start
        native.step(action)
        sync.step(action)
        frames, expected = native.render(), sync.render()
        assert isinstance(frames, tuple) and len(frames) == N
        for frame, reference in zip(frames, expected, strict=True):
            assert frame.shape == (460, 920, 3) and frame.dtype == np.uint8
            np.testing.assert_array_equal(frame, reference)
    assert not np.array_equal(first[0], frames[0])  # the frames move with the fish
    assert not np.array_equal(frames[0], frames[1])  # and differ between envs
    native.close()
    sync.close()


def test_human_rendering_wrapper_tiles_the_frames():
    from gymnasium.wrappers.vector import HumanRendering

    venv = HumanRendering(gym.make_vec(LATEST_AVERAGED, 4, vectorization_mode="vector_entry_point",
                                       render_mode="rgb_array"))
    venv.reset(seed=0)
    venv.step(np.zeros((4, 8)))
    assert venv.num_rows * venv.num_cols >= 4
    venv.close()


def test_render_without_a_mode_warns_with_the_envs_own_id():
    venv = gym.make_vec(LATEST_FULL, 2, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    with pytest.warns(UserWarning, match=f'gym.make_vec\\("{LATEST_FULL}", render_mode="rgb_array"\\)'):
        assert venv.render() is None
    env = gym.make(LATEST_FULL)
    env.reset(seed=0)
    with pytest.warns(UserWarning, match=f'gym.make\\("{LATEST_FULL}", render_mode="rgb_array"\\)'):
        assert env.render() is None


def test_unknown_render_mode_is_refused():
    from pectoral_gym.envs import PectoralFishVectorEnv

    with pytest.raises(ValueError, match="render_mode must be 'rgb_array' or None, got 'human'"):
        PectoralFishVectorEnv(2, render_mode="human")
