"""A slow, lossy radio in lockstep: the step's command renewed against its deadline, the safety bounds unchanged.

At 0.3 s one way the deadline (``DEADLINE_HORIZON`` after ``set_fins()`` on a lower bound of the robot's clock,
which runs behind by the return latency) halted the fins 0.95 - 0.6 = 0.35 s after each command reached the
robot, while the next one came 0.5 s after it: the fins rested for a third of every step. Renewing the command
while ``step()`` runs (``linkclock.renewal_lease``) keeps them running; each call is still bounded by its own
deadline and the lease still ends where the step's did. Robot-side times come from the emulator's trace (one
entry per 10 ms physics chunk) on the same virtual clock.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np
import pytest
from test_lockstep import _in_thread

from pectoral_gym.hardware.emurig import RigConditions, open_rig
from pectoral_gym.hardware.env import HardwareFishEnv
from pectoral_gym.hardware.radio.link import DEADLINE_HORIZON
from pectoral_gym.hardware.radio.linkclock import RENEWAL_INTERVAL, renewal_lease
from pectoral_gym.hardware.radio.protocol import DEFAULT_LEASE

TICK = 0.01  # the firmware's tick [s]: a halt comes at most this late
CHUNK = 0.01  # the emulator's trace resolution [s]


def test_renewal_lease_by_hand():
    horizon, lease = 0.95, 0.8
    # a clean radio: the deadline (0.95 s) comes after the lease (0.8 s): nothing to renew
    assert renewal_lease(0.2, 0.0, lease, horizon, rtt=0.001) is None
    # 0.3 s each way: the deadline may halt the fins 0.95 - 0.6 = 0.35 s after the call, before the lease's 0.8 s
    assert renewal_lease(0.1, 0.0, lease, horizon, rtt=0.6) == pytest.approx(0.7)
    assert renewal_lease(0.05, 0.0, lease, horizon, rtt=0.6) is None  # within one interval of the last send
    assert renewal_lease(0.3337, 0.2, lease, horizon, rtt=0.6) == 0.466  # the lease left, rounded down to ms
    assert renewal_lease(0.75, 0.6, lease, horizon, rtt=0.6) is None  # less lease left than an interval
    assert renewal_lease(0.2, 0.0, lease, horizon, rtt=None) is None  # no round trip measured, no deadline sent
    # 0.1 s each way: 0.95 - 0.2 - 0.05 = 0.70 < 0.8: renewed too (losses delay the next command)
    assert renewal_lease(0.1, 0.0, lease, horizon, rtt=0.2) == pytest.approx(0.7)
    assert RENEWAL_INTERVAL <= 0.1


def _steps_on_a_slow_radio(renew: bool, steps: int = 8, loss: float = 0.0, seed: int = 3):
    """Run ``steps`` steps of a gentle constant action at 0.3 s one way, then stop calling ``step()``.

    Returns ``(calls, step_starts, trace, stop_time)``: robot times of every ``set_fins()`` call and of each
    step's start, the emulator's trace ``(t, running)`` and the robot time the last step returned.
    """
    def scenario():
        with contextlib.ExitStack() as resources:
            clock, robot, port, camera = open_rig(resources, seed, RigConditions(radio_latency=0.3, radio_loss=loss),
                                                  lockstep=True)
            env = HardwareFishEnv(port, camera, reset_hook=lambda rng: robot.place(1.0, 0.75, 0.0),
                                  handle_signals=False, clock=clock, max_episode_steps=steps + 1)
            resources.callback(env.close)
            calls = []
            set_fins = port.set_fins

            def recorded(beats, lease=DEFAULT_LEASE):
                calls.append(robot.now())
                return set_fins(beats, lease)

            port.set_fins = recorded
            if not renew:
                env._renewal = lambda t: None
            env.reset(seed=seed)
            robot.trace = []
            starts = []
            action = np.array([0.0, 0.2, 0.0, 0.0] * 2, dtype=np.float32)  # rest bias, small amplitude
            for _ in range(steps):
                starts.append(robot.now())
                *_, terminated, truncated, info = env.step(action)
                assert not (terminated or truncated), info["safety_stops"]
            stop_time = robot.now()
            clock.sleep(2.0)  # no more step(): the lease and the deadline end the fins
            trace = [(t, bool(running)) for t, _, _, _, running in robot.trace]
            return calls, starts, trace, stop_time

    return _in_thread(scenario, timeout=600.0)


def _running_share(trace, start, end):
    chunks = [running for t, running in trace if start <= t <= end]
    return sum(chunks) / len(chunks)


def _bounds_hold(calls, starts, trace):
    """No running chunk later than its newest call + horizon + tick; none past the last step's lease end."""
    calls = np.asarray(calls)
    for t, running in trace:
        if running:
            newest = calls[calls < t].max()  # a chunk runs on a command sent before it
            assert t <= newest + DEADLINE_HORIZON + TICK + CHUNK + 1e-9, (t, newest)
    last_running = max(t for t, running in trace if running)
    # the lease: from the robot's receipt of the last step's command (0.3 s after its start) plus 0.8 s
    assert last_running <= starts[-1] + 0.3 + DEFAULT_LEASE + TICK + CHUNK + 1e-9
    return last_running


def test_renewal_keeps_the_fins_running_on_a_slow_radio_within_every_bound():
    calls, starts, trace, stop_time = _steps_on_a_slow_radio(renew=True)
    old_calls, old_starts, old_trace, _ = _steps_on_a_slow_radio(renew=False)
    # from the first command's arrival to the end of the last step
    share = _running_share(trace, starts[0] + 0.35, stop_time)
    old_share = _running_share(old_trace, old_starts[0] + 0.35, old_starts[-1] + 0.5)
    assert old_share < 0.8  # without renewals the deadline halts the fins for ~0.15 s of every 0.5 s step
    assert share > 0.97
    assert len(calls) > len(starts)  # renewals were sent
    _bounds_hold(old_calls, old_starts, old_trace)
    last_running = _bounds_hold(calls, starts, trace)
    assert last_running > stop_time  # the fins ran on after the last step, as far as its lease
    assert not math.isnan(last_running)


@pytest.mark.slow
def test_renewal_bounds_hold_under_loss():
    """30 % loss each way: the bounds hold for every call, and the fins run most of the time."""
    calls, starts, trace, stop_time = _steps_on_a_slow_radio(renew=True, steps=16, loss=0.3, seed=11)
    _bounds_hold(calls, starts, trace)
    assert _running_share(trace, starts[0] + 0.6, stop_time) > 0.85
