"""HardwareFishEnv reports the simulated envs' task info (one builder, envs.core.task_info), from reset on."""

import math

import numpy as np
import pytest

from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.env import HardwareFishEnv
from pectoral_gym.hardware.safety.rules import SafetyConfig

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")  # no numba compile inside a timed loop

SPEED = 2.0


@pytest.fixture
def rig():
    robot = EmulatedRobot(speed=SPEED, seed=0, start_pose=(1.15, 0.575, 0.3)).start()
    env = HardwareFishEnv(robot.url, robot.camera(seed=1), speed=SPEED,
                          safety=SafetyConfig(tracking_timeout=1.5, link_timeout=2.0))
    yield env
    env.close()
    robot.stop()


def test_reset_and_step_info_carry_the_task_keys_of_the_simulated_envs(rig):
    import gymnasium as gym

    import pectoral_gym  # noqa: F401

    sim_keys = list(gym.make("PectoralFish-Full-v0").reset(seed=0)[1])
    obs, info = rig.reset(seed=0)
    assert list(info)[:len(sim_keys)] == sim_keys
    assert info["distance"] == pytest.approx(math.hypot(obs[7], obs[8]), rel=1e-5)
    assert info["reward_progress"] == 0.0 and not info["is_success"]
    assert {"pose", "target", "in_geofence"} <= set(info)
    _, reward, _, _, info = rig.step(np.zeros(8, np.float32))
    assert list(info)[:len(sim_keys)] == sim_keys
    assert all(isinstance(info[k], np.generic) for k in sim_keys)
    assert reward == pytest.approx(sum(info[k] for k in sim_keys if k.startswith("reward_")))
