"""A deploy displaced by another PC's take-over ends at once and sends nothing more, not even STOP.

Before: its resets succeeded (the robot confirmed the STOP the reset had just caused), every episode ended
``taken_over`` at its first step, and each of those STOPs halted the new controller's fins.
"""

import math
import threading
import time

import numpy as np
import pytest
from emulator_helpers import wait_for

from pectoral_gym.hardware.deploy_episodes import displaced_reason, run_episodes
from pectoral_gym.hardware.emulator import RECEIVED_KEPT, EmulatedRobot
from pectoral_gym.hardware.env import HardwareFishEnv
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio.link import DisplacedError, RadioLink

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")

SPEED = 2.0
BEATS = np.array([[math.pi / 2, math.radians(20), 1.0, 3.0]] * 2)


class _Forward:
    def reset(self, seed=None):
        pass

    def act(self, obs):
        return np.array([0.5, 0.5, 0.0, 0.5] * 2, dtype=np.float32)


def _link(url, **kwargs):
    link = RadioLink(url, keepalive_period=0.1 / SPEED, ack_timeout=0.05 / SPEED, **kwargs)
    link.lease_scale = 1.0 / SPEED
    return link


class _Driver:
    """The new controller: commands ``link``'s fins anew every 0.2 robot s in a thread of its own."""

    def __init__(self, link):
        self.link, self.done = link, threading.Event()
        self.thread = threading.Thread(target=self._run)

    def _run(self):
        while not self.done.is_set():
            self.link.set_fins(BEATS, 0.5)
            time.sleep(0.2 / SPEED)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.done.set()
        self.thread.join()


def test_displaced_link_sends_nothing_but_the_operators_stop():
    with EmulatedRobot(speed=SPEED) as robot:
        a = _link(robot.url)
        b = None
        try:
            assert a.wait_ack(a.set_fins(BEATS, 0.5), 2.0)
            b = _link(robot.url, take_over=True)
            assert wait_for(lambda: a.control_lost == "taken_over", 2.0) and a.displaced
            with _Driver(b):
                assert wait_for(lambda: robot.firmware.running and b.served == b.session, 1.0)
                time.sleep(0.1)  # a's frames in flight when it learnt arrive
                n = len(robot.received)
                assert not a.stop(wait=0.3)  # the program's own stop: suppressed
                a.close()
                time.sleep(0.3)
                assert not [m for m in robot.received[n:] if m.session == a.session]
                assert robot.firmware.running and robot.firmware.session == b.session  # the new controller's fins
            b.stop(wait=1.0)
            assert b.wait_ack(b.set_fins(BEATS, 0.5), 1.0) and wait_for(lambda: robot.firmware.running, 1.0)
            a.emergency_stop()  # the operator's stop still goes out, and halts (a stop needs no authority)
            assert wait_for(lambda: not robot.firmware.running, 1.0)
        finally:
            a.close()
            if b is not None:
                b.close()


def test_deploy_displaced_by_a_take_over_ends_at_once_and_stops_nobody(tmp_path):
    with EmulatedRobot(speed=SPEED, seed=3) as robot:
        robot.place(0.9, 0.5, 0.0)
        env = HardwareFishEnv(robot.url, robot.camera(seed=3), speed=SPEED, max_episode_steps=4)
        out: dict = {}
        run = threading.Thread(target=lambda: out.setdefault(
            "summaries", run_episodes(env, _Forward(), 50, tmp_path / "steps.jsonl", seed=0, progress=False)))
        b = None
        try:
            run.start()
            assert wait_for(lambda: robot.firmware.running, 20.0)  # the deploy drives the fish
            b = _link(robot.url, take_over=True)
            assert wait_for(lambda: env.link.displaced, 3.0)
            claimed = time.monotonic()
            run.join(timeout=10.0)
            assert not run.is_alive() and time.monotonic() - claimed < 4.0 / SPEED + 1.0
            assert displaced_reason(env) == "taken_over" and len(out["summaries"]) < 50
            time.sleep(0.1)
            n = len(robot.received)
            with _Driver(b):
                assert wait_for(lambda: robot.firmware.running, 1.0)
                with pytest.raises(DisplacedError):
                    env.reset()  # a further reset is refused without a STOP
                env.close()
                time.sleep(0.5)
                assert robot.firmware.running  # never halted by the displaced deploy
            assert not [m for m in robot.received[n:] if m.session == env.link.session]
        finally:
            env.close()
            run.join(timeout=5.0)
            if b is not None:
                b.close()


def test_emulator_keeps_a_bounded_message_list():
    with EmulatedRobot(speed=SPEED) as robot:
        robot.received.extend([pr.Message(pr.MsgType.HEARTBEAT, k, 1) for k in range(2 * RECEIVED_KEPT)])
        link = _link(robot.url)
        try:
            assert link.stop(wait=1.0)
        finally:
            link.close()
        assert RECEIVED_KEPT <= len(robot.received) <= 2 * RECEIVED_KEPT
        assert any(m.type == pr.MsgType.STOP for m in robot.received[-5:])  # the newest are kept
