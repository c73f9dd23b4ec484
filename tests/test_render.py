"""Rendering: rgb_array frames show the fish where the state says; human mode runs headless."""

import math
import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # no display needed

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("pygame")

import pectoral_gym  # noqa: F401, E402  (registers the ids)
from pectoral_gym.envs.rendering import BODY_COLOR, FIN_COLOR, SCALE, TARGET_COLOR  # noqa: E402


def pixel(x, y, height=460):
    """Row and column of tank point (x, y) [m]."""
    return int(round(height - y * SCALE)), int(round(x * SCALE))


def near(img, row, col, color, radius=2):
    patch = img[max(row - radius, 0):row + radius + 1, max(col - radius, 0):col + radius + 1]
    return bool(np.any(np.all(patch == color, axis=-1)))


@pytest.mark.parametrize("env_id", ["PectoralFish-Averaged-v0", "PectoralFish-Full-v0"])
def test_rgb_array_shows_the_fish_at_its_pose(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=4)
    for _ in range(3):
        env.step(np.array([0, 1, 0, 1, 0, 1, 0, 1], np.float32))
    img = env.render()
    assert img.shape == (460, 920, 3) and img.dtype == np.uint8
    x, y, psi = env.unwrapped.model.state[0, :3]
    length = env.unwrapped.fish_params.body_length
    row, col = pixel(x, y)
    assert near(img, row, col, BODY_COLOR)  # centre of the body
    behind = pixel(x - 0.3 * length * math.cos(psi), y - 0.3 * length * math.sin(psi))
    assert near(img, *behind, BODY_COLOR)  # along the heading
    across = pixel(x + 0.3 * length * math.sin(psi), y - 0.3 * length * math.cos(psi))
    assert not near(img, *across, BODY_COLOR, radius=0)  # the body is slender
    gx, gy = env.unwrapped.target
    assert near(img, *pixel(gx, gy), TARGET_COLOR)
    assert np.sum(np.all(img == FIN_COLOR, axis=-1)) > 20  # the fins are drawn
    far = pixel(x + 0.5 if x < 1.15 else x - 0.5, y)
    assert not near(img, *far, BODY_COLOR)
    env.close()


def test_render_track_task_and_frames_change():
    env = gym.make("PectoralFish-Averaged-v0", task="track", render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    env.step(np.array([0, 1, -1, 1, 0, 1, -1, 1], np.float32))
    second = env.render()
    assert first.shape == second.shape == (460, 920, 3)
    assert not np.array_equal(first, second)
    tx, ty = env.unwrapped.target
    assert near(second, *pixel(tx, ty), TARGET_COLOR)
    env.close()


def test_human_mode_runs_headless_starts_the_display_only_and_close_quits_it():
    import pygame

    env = gym.make("PectoralFish-Averaged-v0", render_mode="human")
    env.reset(seed=0)
    env.step(np.zeros(8, np.float32))
    assert env.render() is None
    assert pygame.display.get_init()
    assert not pygame.mixer.get_init()  # pygame.init() would open the audio device (ALSA errors headless)
    env.close()
    assert not pygame.display.get_init()
