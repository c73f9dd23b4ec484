"""One task core (envs.task_core): the simulated envs and HardwareFishEnv give the same task outputs for the
same fish states and commands; a task registered in the table is a task of every env."""

import math
import pickle

import gymnasium as gym
import numba as nb
import numpy as np
import pytest
from gymnasium.utils import seeding

import pectoral_gym  # noqa: F401
from pectoral_gym.envs.core import TASKS, EnvConfig
from pectoral_gym.envs.layout import (
    C_W_TRACKING,
    C_WALL,
    E_DPREV,
    E_TX,
    E_TY,
    GOAL,
    N_OUT,
    O_DISTANCE,
    O_ENERGY,
    O_REWARD,
    O_SUCCESS,
    O_TERMINATED,
    O_TRACKING,
    O_WALL,
)
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.envs.tasks.table import TASK_TABLE, TaskState, observe_fish, register_task, unregister_task
from pectoral_gym.envs.vector import PectoralFishVectorEnv
from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.env import HardwareFishEnv
from pectoral_gym.hardware.safety.rules import SafetyConfig
from pectoral_gym.registration import registered_settings

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")  # no numba compile inside a timed loop

SPEED = 2.0  # emulated clock: a 0.5 s control period takes 0.25 s of wall time


def _same_info(a: dict, b: dict, keys) -> None:
    for k in keys:
        assert type(a[k]) is type(b[k]) and a[k] == b[k], (k, a[k], b[k])


def _replay(config, seed, pose, steps):
    """A fresh TaskState fed a recorded start pose and, per step, (action code, fish state, mean velocity)."""
    task = TaskState(1, config)
    task.reset_at(0, seeding.np_random(seed)[0], pose)
    yield task.obs[0].copy(), None, task.info(0)
    for code, state, velocity in steps:
        assert task.apply(np.asarray(code, dtype=np.float64)[None]) == -1
        task.observe(np.asarray(state, dtype=np.float64)[None])
        if velocity is not None:
            task.set_mean_velocity(0, velocity)
        yield task.obs[0].copy(), task.reward(0), task.info(0)


@pytest.mark.parametrize("model", ["Averaged", "Full"])
@pytest.mark.parametrize("task", ["goal", "track"])
def test_simulated_env_equals_the_task_core_fed_its_states(model, task):
    env = gym.make(f"PectoralFish-{model}-v0", task=task).unwrapped
    obs, info = env.reset(seed=4)
    sim = [(obs, None, info)]
    steps = []
    rng = np.random.default_rng(0)
    for _ in range(60):
        action = rng.uniform(-1, 1, 8)
        before = env.model.integral[0].copy()
        obs, reward, terminated, _, info = env.step(action)
        velocity = (env.model.integral[0] - before) / env.config.control_period  # the mean over the period
        steps.append((action, env.fish_state, velocity))
        sim.append((obs, reward, info))
        if terminated:
            break
    assert len(sim) > 10
    replay = list(_replay(env.config, 4, _start_pose(env.config, 4), steps))
    for (o1, r1, i1), (o2, r2, i2) in zip(sim, replay, strict=True):
        assert o1.tobytes() == o2.tobytes()
        assert r1 == r2
        _same_info(i1, i2, i1)
        assert list(i1) == list(i2)


def _start_pose(config, seed):
    """The simulated env's start pose for this seed (drawn independently of the env)."""
    draws = TaskState(1, config).draw(seeding.np_random(seed)[0])
    task = TaskState(1, config)
    start = task.start(np.zeros(1, dtype=np.int64), draws[None])
    return tuple(start[0, :3].tolist())


@pytest.fixture
def robot():
    robot = EmulatedRobot(speed=SPEED, seed=0, start_pose=(1.15, 0.575, 0.3)).start()
    yield robot
    robot.stop()


def _hardware_env(robot, **kwargs):
    return HardwareFishEnv(robot.url, robot.camera(seed=1), speed=SPEED,
                           safety=SafetyConfig(tracking_timeout=1.5, link_timeout=2.0), **kwargs)


@pytest.mark.parametrize("task", ["goal", "track"])
def test_hardware_env_equals_the_task_core_fed_its_estimates(robot, task, monkeypatch):
    env = _hardware_env(robot, task=task)
    try:
        velocities = []
        original = env.task_state.set_mean_velocity
        monkeypatch.setattr(env.task_state, "set_mean_velocity",
                            lambda i, v: velocities.append(np.array(v)) or original(i, v))
        obs, info = env.reset(seed=7)
        hardware = [(obs, None, info)]
        steps = []
        rng = np.random.default_rng(1)
        for _ in range(5):
            velocities.append(None)
            obs, reward, terminated, truncated, info = env.step(rng.uniform(-0.5, 0.5, 8).astype(np.float32))
            velocity = velocities[-1]
            code = np.concatenate([env.config.encode(np.array(c)) for c in info["command"]])
            steps.append((code, info["estimate"], velocity))
            hardware.append((obs, reward, info))
            if terminated or truncated:
                break
        pose = hardware[0][2]["pose"]
    finally:
        env.close()
    replay = list(_replay(env.config, 7, pose, steps))
    keys = list(replay[0][2])
    assert keys == list(hardware[0][2])[:len(keys)]
    for (o1, r1, i1), (o2, r2, i2) in zip(hardware, replay, strict=True):
        assert o1.tobytes() == o2.tobytes()
        assert r1 == r2
        _same_info(i1, i2, keys)
    assert any(v is not None for v in velocities)  # the mean velocities did come from the observer


# ---------------------------------------------------------------- a new task in the table
@nb.njit
def _hold_reward(i, state, cfg, ep, fish, obs, out):
    """Station keeping at the target: -tracking_weight * d per step, wall and energy as the built-in tasks."""
    d, wall = observe_fish(i, state, ep, fish, obs)
    r_hold = -cfg[C_W_TRACKING] * d
    r_wall = -cfg[C_WALL] if wall else 0.0
    out[i, O_TRACKING] = r_hold
    out[i, O_WALL] = r_wall
    out[i, O_REWARD] = r_hold + r_wall + out[i, O_ENERGY]
    out[i, O_DISTANCE] = d
    out[i, O_TERMINATED] = 1.0 if wall else 0.0
    out[i, O_SUCCESS] = 0.0
    ep[i, E_DPREV] = d


def _hold_start(index, draws, cfg, ep, start):
    for k, i in enumerate(index):
        start[k] = (draws[k, 0], draws[k, 1], draws[k, 2], 0.0, 0.0, 0.0)
        ep[i] = 0.0
        ep[i, E_TX], ep[i, E_TY] = draws[k, 3], draws[k, 4]


@pytest.fixture
def hold():
    task = register_task("hold", terms=(("reward_hold", O_TRACKING), ("reward_wall", O_WALL),
                                        ("reward_energy", O_ENERGY)),
                         draw=lambda rng, cfg: tk.draw_episode(rng, GOAL, cfg), start=_hold_start,
                         reward_one=_hold_reward)
    yield task
    unregister_task("hold")


HOLD_KEYS = ["reward_hold", "reward_wall", "reward_energy", "distance"]


def test_a_registered_task_is_a_task_of_the_simulated_envs(hold):
    assert "hold" in TASKS and TASKS["hold"] == hold.id not in (0, 1)
    env = gym.make("PectoralFish-Averaged-v0", task="hold")
    goal = gym.make("PectoralFish-Averaged-v0", task="goal")
    obs, info = env.reset(seed=2)
    obs_goal, _ = goal.reset(seed=2)
    assert list(info) == HOLD_KEYS and info["reward_hold"] == 0.0
    assert obs.tobytes() == obs_goal.tobytes()  # the same draws and start as goal
    rng = np.random.default_rng(3)
    for _ in range(20):
        action = rng.uniform(-1, 1, 8)
        obs, reward, terminated, _, info = env.step(action)
        obs_goal, _, terminated_goal, _, _ = goal.step(action)
        # The same fish and target: the generic loops observe (mean velocities included) as the built-in kernel.
        assert obs.tobytes() == obs_goal.tobytes()
        assert list(info) == HOLD_KEYS
        assert info["reward_hold"] == pytest.approx(-1.0 * math.hypot(obs[7], obs[8]), rel=1e-6)
        assert reward == pytest.approx(info["reward_hold"] + info["reward_wall"] + info["reward_energy"])
        if terminated or terminated_goal:
            break
    copy = pickle.loads(pickle.dumps(env.unwrapped))  # the task state pickles by name
    assert copy.core.task_state.task is hold
    drawn = gym.make("PectoralFish-Averaged-v0", task="hold", render_mode="rgb_array")
    drawn.reset(seed=2)
    assert drawn.render().shape[2] == 3  # a target without a reference ellipse is drawn as a goal
    drawn.close()
    venv = PectoralFishVectorEnv(3, **registered_settings("PectoralFish-Averaged-v0", dict(task="hold")))
    _, vinfo = venv.reset(seed=2)
    assert list(vinfo) == [k for key in HOLD_KEYS for k in (key, "_" + key)]
    _, rewards, _, _, vinfo = venv.step(np.zeros((3, 8)))
    assert np.allclose(rewards, vinfo["reward_hold"] + vinfo["reward_wall"] + vinfo["reward_energy"])


def test_a_registered_task_is_a_task_of_the_hardware_env(hold, robot):
    env = _hardware_env(robot, task="hold")
    try:
        obs, info = env.reset(seed=0)
        assert list(info)[:len(HOLD_KEYS)] == HOLD_KEYS
        assert info["distance"] == pytest.approx(math.hypot(obs[7], obs[8]), rel=1e-5)
        _, reward, _, _, info = env.step(np.zeros(8, np.float32))
        assert list(info)[:len(HOLD_KEYS)] == HOLD_KEYS
        assert reward == pytest.approx(info["reward_hold"] + info["reward_wall"] + info["reward_energy"])
    finally:
        env.close()


def test_registration_errors_and_unregistered_names():
    with pytest.raises(ValueError, match="task must be one of"):
        EnvConfig(task="hold")
    with pytest.raises(ValueError, match="already registered"):
        register_task("goal", terms=(("reward_x", O_TRACKING),), draw=lambda rng, cfg: None, start=_hold_start,
                      reward_one=_hold_reward)
    with pytest.raises(TypeError, match="numba.njit"):
        register_task("plain", terms=(("reward_x", O_TRACKING),), draw=lambda rng, cfg: None, start=_hold_start,
                      reward_one=_hold_reward.py_func)
    with pytest.raises(ValueError, match="repeat"):
        register_task("twice", terms=(("distance", O_TRACKING),), draw=lambda rng, cfg: None, start=_hold_start,
                      reward_one=_hold_reward)
    with pytest.raises(ValueError, match="built-in"):
        unregister_task("goal")
    assert "plain" not in TASK_TABLE and "twice" not in TASK_TABLE


def test_builtin_info_reads_the_documented_out_slots():
    # By hand from the docstring of PectoralFishEnv ("Rewards") and layout.O_*.
    out = np.arange(10, dtype=np.float64) / 10.0
    out[O_SUCCESS] = 1.0
    goal = TASK_TABLE["goal"].info(out)
    assert goal == {"reward_progress": 0.1, "reward_goal": 0.2, "reward_wall": 0.3, "reward_energy": 0.4,
                    "reward_time": 0.5, "distance": 0.7, "is_success": True}
    assert isinstance(goal["is_success"], np.bool_) and isinstance(goal["distance"], np.float64)
    track = TASK_TABLE["track"].info(out)
    assert track == {"reward_tracking": 0.6, "reward_wall": 0.3, "reward_energy": 0.4, "distance": 0.7,
                     "tracking_error": 0.7}


def test_a_given_info_function_must_give_the_task_fields():
    """A row's hand-written ``info`` is checked against its fields: the built-in ones agree, a wrong one is refused."""
    import dataclasses

    from pectoral_gym.envs.tasks.table import TASK_TABLE

    for task in TASK_TABLE.values():
        row = np.linspace(-1.0, 2.0, N_OUT)
        assert list(task.info(row).items()) == list(dataclasses.replace(task, info=None).info(row).items())
    goal = TASK_TABLE["goal"]
    with pytest.raises(ValueError, match="does not give info_fields"):
        dataclasses.replace(goal, info=TASK_TABLE["track"].info)
