"""The deploy's episode summary: time to goal as the simulated envs count it (steps x control period)."""

import io
from types import SimpleNamespace

import numpy as np

from pectoral_gym.hardware.deploy_episodes import run_episode


class _GoalAfter:
    """A stand-in env whose fish reaches the goal at step ``reach`` (or never: ``None``), ended at ``limit`` steps."""

    def __init__(self, reach: int | None, limit: int = 10, control_period: float = 0.5):
        self.reach, self.limit, self.steps = reach, limit, 0
        self.unwrapped = SimpleNamespace(config=SimpleNamespace(control_period=control_period), target=[1.0, 0.5])

    def _info(self, success: bool) -> dict:
        return {"pose": [0.0, 0.0, 0.0], "target": [1.0, 0.5], "command": [], "estimate": [], "safety_stop": "",
                "distance": 0.0 if success else 0.3, "link": {}, "tracking": {}, "is_success": success}

    def reset(self, seed=None):
        self.steps = 0
        return np.zeros(3), self._info(False)

    def step(self, action):
        self.steps += 1
        success = self.reach is not None and self.steps >= self.reach
        return np.zeros(3), 0.0, success, self.steps >= self.limit, self._info(success)


class _Still:
    def reset(self, seed=None):
        pass

    def act(self, obs):
        return np.zeros(8)


def test_time_to_goal_is_steps_times_the_control_period():
    summary = run_episode(_GoalAfter(reach=7, control_period=0.5), _Still(), 0, io.StringIO())
    assert summary["success"] and summary["steps"] == 7
    assert summary["time_to_goal"] == 3.5  # 7 steps of 0.5 s
    missed = run_episode(_GoalAfter(reach=None, limit=4), _Still(), 0, io.StringIO())
    assert not missed["success"] and missed["time_to_goal"] is None
