"""Helpers shared by the hardware tests: waiting on a condition, and when the emulated robot's fins stopped."""

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
