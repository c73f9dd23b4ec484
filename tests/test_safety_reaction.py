"""The geofence's reaction time on a slow radio: a STOP halts the fins one forward delay after it is sent.

``effective_reaction_time`` adds the link's measured round trip to the prompt radio's budget (the forward delay
is at most the round trip). Checked by hand and against the emulated robot's trace in lockstep, where the
fins' last running chunk after a STOP is known to the firmware's tick.
"""

from __future__ import annotations

import contextlib
import math
import threading

import numpy as np
import pytest

from pectoral_gym.hardware.emurig import RigConditions, open_rig
from pectoral_gym.hardware.env import HardwareFishEnv
from pectoral_gym.hardware.safety.rules import SafetyConfig, effective_reaction_time
from pectoral_gym.model import tank

TICK = 0.01  # the firmware's tick [s]: a halt comes at most this late
CHUNK = 0.01  # the emulator's trace resolution [s]


def test_effective_reaction_time_by_hand():
    rule = tank.StopRule(0.05, 0.15, 0.03)
    assert effective_reaction_time(rule, 0.6) == pytest.approx(0.75)  # 0.3 s each way
    assert effective_reaction_time(rule, 0.0) == pytest.approx(0.15)
    assert effective_reaction_time(rule, None) == pytest.approx(0.15)  # no round trip measured yet
    assert SafetyConfig().stop_rule == tank.ROBOT_STOP_RULE  # the budget it extends
    for bad in (math.nan, -0.1, math.inf):
        with pytest.raises(ValueError, match="round_trip"):
            effective_reaction_time(rule, bad)


def test_a_stop_on_a_slow_radio_halts_within_the_effective_reaction_time():
    """0.3 s each way: the fins run 0.3 s past the STOP's send (more than the prompt budget 0.15 s), and the
    effective reaction time from the link's own round trip bounds it."""
    latency = 0.3
    out: dict = {}

    def scenario():
        with contextlib.ExitStack() as resources:
            clock, robot, port, camera = open_rig(resources, 5, RigConditions(radio_latency=latency), lockstep=True)
            env = HardwareFishEnv(port, camera, reset_hook=lambda rng: robot.place(1.0, 0.75, 0.0),
                                  handle_signals=False, clock=clock, max_episode_steps=10)
            resources.callback(env.close)
            env.reset(seed=5)
            action = np.array([0.0, 0.2, 0.0, 0.0] * 2, dtype=np.float32)
            for _ in range(3):
                env.step(action)
            robot.trace = []
            sent = robot.now()
            port.stop()
            clock.sleep(1.0)
            out["rtt"] = port.rtt()
            out["sent"] = sent
            out["trace"] = [(t, bool(running)) for t, _, _, _, running in robot.trace]

    thread = threading.Thread(target=scenario, daemon=True)
    thread.start()
    thread.join(timeout=600.0)
    assert not thread.is_alive() and "trace" in out
    running = [t for t, run in out["trace"] if run]
    halted_after = max(running) - out["sent"]
    assert halted_after > tank.ROBOT_STOP_RULE.reaction_time  # the prompt budget alone does not cover it
    assert halted_after <= latency + TICK + CHUNK + 1e-9  # the STOP's arrival, to the tick
    assert out["rtt"] == pytest.approx(2 * latency, abs=0.02)
    assert halted_after <= effective_reaction_time(tank.StopRule(0.05, 0.0, 0.03), out["rtt"]) + TICK + CHUNK
