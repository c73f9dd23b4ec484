"""The identification-run controller: seeded random fin patterns, held 2-6 s, kept out of the stopping band."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.controllers.excitation import ExcitationController
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.registration import registered_settings

CONFIG = EnvConfig(**registered_settings("PectoralFish-Full-v1", {}))


def _obs() -> np.ndarray:
    env = gym.make("PectoralFish-Full-v1")
    obs, _ = env.reset(seed=3)
    env.close()
    return obs


def test_patterns_are_held_for_the_hold_range_and_cover_the_env_ranges():
    controller = ExcitationController(CONFIG, hold=(2.0, 6.0), seed=4, shield=False)
    obs = _obs()
    actions = np.array([controller.act(obs) for _ in range(2000)])
    changes = np.flatnonzero(np.any(np.diff(actions, axis=0) != 0, axis=1)) + 1
    holds = np.diff(changes) * CONFIG.control_period
    assert holds.min() >= 2.0 - 1e-9 and holds.max() <= 6.0 + 1e-9 and np.ptp(holds) >= 3.0
    # each field of each fin drawn across (nearly) its whole normalised range
    assert np.all(actions.min(axis=0) < -0.9) and np.all(actions.max(axis=0) > 0.9)
    assert actions.dtype == np.float32 and np.all(np.abs(actions) <= 1.0)


def test_the_same_seed_gives_the_same_patterns_and_another_seed_others():
    obs = _obs()
    a, b = (ExcitationController(CONFIG, seed=None, shield=False) for _ in range(2))
    a.reset(11)
    b.reset(11)
    first = [a.act(obs) for _ in range(40)]
    assert np.array_equal(first, [b.act(obs) for _ in range(40)])
    b.reset(12)
    assert not np.array_equal(first, [b.act(obs) for _ in range(40)])


def test_make_baseline_builds_it_and_bad_holds_are_refused():
    assert isinstance(make_baseline("excite", CONFIG), ExcitationController)
    for hold in ((0.0, 1.0), (3.0, 2.0), (1.0, float("nan"))):
        with pytest.raises(ValueError, match="hold"):
            ExcitationController(CONFIG, hold=hold)
    with pytest.raises(ValueError, match="obs must have shape"):
        ExcitationController(CONFIG).act(np.zeros(5))


def test_the_shield_keeps_the_excited_fish_out_of_the_stopping_band():
    # PectoralFish-Full-v1 ends an episode in the robot's stopping band (reward_wall, cost 1); without the shield
    # the random patterns meet it, with it none of these episodes does (docs: 0 of 20 on episodes 500-519)
    from pectoral_gym.agents.training.evaluate import evaluate

    shielded = evaluate(lambda: ExcitationController(CONFIG), "PectoralFish-Full-v1", n_episodes=4, seed=700,
                        env_kwargs={"max_episode_steps": 120})
    raw = evaluate(lambda: ExcitationController(CONFIG, shield=False), "PectoralFish-Full-v1", n_episodes=4,
                   seed=700, env_kwargs={"max_episode_steps": 120})
    assert shielded.metrics["wall"].mean == 0.0
    assert raw.metrics["wall"].mean > 0.0
