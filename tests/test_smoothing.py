"""The training-only action-change penalty (pectoral_gym.agents.training.smoothing).

Values by hand, episode starts, config.
"""

import numpy as np
import pytest

from pectoral_gym.agents.training.config import resolve_config
from pectoral_gym.agents.training.smoothing import INFO_KEY, ActionChangePenalty
from pectoral_gym.agents.training.vec_adapter import make_fish_vec_env

ENV = "PectoralFish-Averaged-v0"


def test_penalty_is_weight_times_mean_absolute_change_by_hand():
    plain = make_fish_vec_env(ENV, 2, {"task": "goal"}, seed=5)
    wrapped = ActionChangePenalty(make_fish_vec_env(ENV, 2, {"task": "goal"}, seed=5), weight=0.5)
    plain.reset()
    wrapped.reset()
    a0 = np.zeros((2, 8), dtype=np.float32)
    a1 = a0.copy()
    a1[0, :4] = 1.0  # env 0: four components change by 1 -> mean change 0.5 -> penalty 0.25
    a1[1, 0] = -0.8  # env 1: one component by 0.8 -> mean 0.1 -> penalty 0.05
    for actions, expected in ((a0, [0.0, 0.0]), (a1, [-0.25, -0.05]), (a1, [0.0, 0.0])):
        plain.step_async(actions)
        _, r_plain, done_plain, _ = plain.step_wait()
        wrapped.step_async(actions)
        _, r_wrapped, done_wrapped, infos = wrapped.step_wait()
        assert not done_plain.any() and np.array_equal(done_plain, done_wrapped)
        np.testing.assert_allclose(r_wrapped - r_plain, expected, atol=1e-6)
        assert [i[INFO_KEY] for i in infos] == pytest.approx(expected, abs=1e-7)  # float32 actions


def test_no_penalty_on_the_first_step_of_an_episode():
    venv = ActionChangePenalty(make_fish_vec_env(ENV, 1, {"task": "goal"}, seed=0), weight=1.0)
    venv.reset()
    venv.has_previous[:] = True
    venv.previous[:] = 1.0
    venv.step_async(np.full((1, 8), 1.0, dtype=np.float32))
    venv.step_wait()
    venv.reset()  # a reset forgets the previous action
    venv.step_async(np.full((1, 8), -1.0, dtype=np.float32))
    _, _, _, infos = venv.step_wait()
    assert infos[0][INFO_KEY] == 0.0
    # after a done, the next step starts an episode: simulate one on the wrapper's own bookkeeping
    venv.has_previous[:] = False
    venv.step_async(np.full((1, 8), 1.0, dtype=np.float32))
    assert venv.step_wait()[3][0][INFO_KEY] == 0.0


def test_config_key_and_bad_values():
    assert resolve_config("ppo", ENV, 0, hyperparams={"action_change_penalty": 0})["action_change_penalty"] == 0.0
    assert resolve_config("ppo", ENV, 0, hyperparams={"action_change_penalty": "0.5"})["action_change_penalty"] == 0.5
    for bad in (-1, "x", float("inf")):
        with pytest.raises(ValueError, match="action_change_penalty"):
            resolve_config("ppo", ENV, 0, hyperparams={"action_change_penalty": bad})
    with pytest.raises(ValueError, match="finite number >= 0"):
        ActionChangePenalty(make_fish_vec_env(ENV, 1, {"task": "goal"}), weight=-0.1)
