"""Helpers shared by the hardware tests: waiting on a condition, when the emulated robot's fins stopped, and an
emulated robot with a ``HardwareFishEnv`` driving it."""

import contextlib
import time

import numpy as np


def wait_for(cond, timeout=5.0):
    """Poll ``cond()`` every 5 ms until it is true or ``timeout`` wall seconds pass; returns its last value."""
    deadline = time.monotonic() + timeout
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.005)
    return cond()


def stopped_at(robot, after):
    """First emulated time >= ``after`` from which the fins never beat again (``None``: still beating)."""
    wait_for(lambda: not robot.firmware.running)  # a STOP may still be on its way
    n = len(robot.trace)
    wait_for(lambda: len(robot.trace) > n + 1)  # and the chunk that applied it in the trace
    trace = list(robot.trace)
    last_running = max((t for t, _, rates, _, running in trace if running or np.any(rates != 0)), default=None)
    if trace and trace[-1][4]:
        return None
    return max(after, last_running) if last_running is not None else after


def make_rig(speed=2.0, start=(1.15, 0.575, 0.0), camera=None, task="goal", **safety):
    """An emulated robot (seed 0, tracing from now on) and a ``HardwareFishEnv`` driving it: ``(robot, env)``.

    ``camera(robot)`` gives the env's camera (default: the robot's, seed 1); ``safety`` are ``SafetyConfig``
    fields (a 2 s link timeout unless given).
    """
    from pectoral_gym.hardware.emulator import EmulatedRobot
    from pectoral_gym.hardware.env import HardwareFishEnv
    from pectoral_gym.hardware.safety.rules import SafetyConfig

    robot = EmulatedRobot(speed=speed, seed=0, start_pose=start).start()
    robot.trace = []
    safety.setdefault("link_timeout", 2.0)
    env = HardwareFishEnv(robot.url, camera(robot) if camera else robot.camera(seed=1), speed=speed, task=task,
                          safety=SafetyConfig(**safety))
    return robot, env


@contextlib.contextmanager
def rig(**kwargs):
    """:func:`make_rig`'s robot and env, both closed at the end."""
    robot, env = make_rig(**kwargs)
    try:
        yield robot, env
    finally:
        env.close()
        robot.stop()
