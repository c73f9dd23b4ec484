"""settle_garbage: a full collection at a harmless moment, the survivors frozen, nothing leaked."""

import gc
import weakref

from pectoral_gym.hardware.realtime import settle_garbage


class _Node:
    def __init__(self):
        self.other = None


def _cycle():
    a, b = _Node(), _Node()
    a.other, b.other = b, a
    return a


def test_survivors_are_frozen_out_of_later_collections():
    try:
        keep = _cycle()
        settle_garbage()
        frozen = gc.get_freeze_count()
        assert frozen > 0
        # A later full collection walks only the objects made since: the frozen ones are not in any generation.
        assert not any(o is keep for o in gc.get_objects(generation=2))
        assert gc.get_freeze_count() == frozen
    finally:
        gc.unfreeze()


def test_garbage_among_frozen_objects_is_collected_by_the_next_call():
    try:
        alive = _cycle()
        ref = weakref.ref(alive)
        settle_garbage()  # alive now: frozen
        del alive  # a cycle, so only the collector can free it, and a frozen one only after unfreezing
        gc.collect()
        assert ref() is not None, "frozen objects must be out of the collector's reach"
        settle_garbage()
        assert ref() is None, "the next call must collect what became garbage while frozen"
    finally:
        gc.unfreeze()


def test_garbage_made_before_the_call_is_collected():
    try:
        ref = weakref.ref(_cycle())
        settle_garbage()
        assert ref() is None
    finally:
        gc.unfreeze()


def test_reset_settles_the_collector_while_the_fins_are_stopped(monkeypatch):
    from pectoral_gym.hardware import env_reset
    from pectoral_gym.hardware.emulator import EmulatedRobot
    from pectoral_gym.hardware.env import HardwareFishEnv
    from pectoral_gym.hardware.safety.rules import SafetyConfig

    calls = []

    def settle():
        calls.append((env.supervisor.armed, robot.firmware.state.name))
        return 0.0

    monkeypatch.setattr(env_reset, "settle_garbage", settle)
    with EmulatedRobot(speed=2.0, seed=0, start_pose=(1.15, 0.575, 0.3)) as robot, \
            HardwareFishEnv(robot.url, robot.camera(seed=1), speed=2.0,
                            safety=SafetyConfig(tracking_timeout=1.5, link_timeout=2.0)) as env:
        env.reset(seed=0)
        assert len(calls) == 1, "once per reset"
        armed, firmware = calls[0]
        assert not armed and firmware != "RUNNING", "only while the rules are disarmed and the fins stopped"
