"""settle_garbage: a collection at a harmless moment, the survivors frozen, the frozen garbage bounded."""

import gc
import weakref

import pytest

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


def test_garbage_among_frozen_objects_waits_for_the_frozen_set_to_grow():
    try:
        settle_garbage()  # nothing frozen before: a full walk
        alive = _cycle()
        ref = weakref.ref(alive)
        settle_garbage()  # alive now: frozen
        del alive  # a cycle, so only the collector can free it, and a frozen one only after unfreezing
        gc.collect()
        assert ref() is not None, "frozen objects must be out of the collector's reach"
        settle_garbage(growth=10.0)
        assert ref() is not None, "a call that finds the frozen set grown little must not walk it"
        keep = [[] for _ in range(1000)]  # survivors: the frozen set grows past its size after the last walk
        settle_garbage(growth=0.0)
        assert ref() is None, "a call that finds the frozen set grown past the bound must collect all of it"
        assert keep
    finally:
        gc.unfreeze()


def test_frozen_garbage_stays_within_the_growth_bound():
    growth = 0.2
    try:
        settle_garbage(growth)
        live = gc.get_freeze_count()  # no cyclic garbage: a full walk just ran
        size = max(1, int(0.03 * live) // 2)  # cycles of 2 objects: 3 % of the frozen set per round
        refs, survived_a_call = [], False
        for _ in range(40):
            cycles = [_cycle() for _ in range(size)]
            refs.append([weakref.ref(c) for c in cycles[:10]])
            settle_garbage(growth)  # this round's cycles frozen while alive
            del cycles  # garbage now, but frozen
            settle_garbage(growth)
            survived_a_call = survived_a_call or refs[-1][0]() is not None
            # the garbage frozen so far: every round's cycles not yet freed
            frozen_garbage = 2 * size * sum(1 for r in refs if r[0]() is not None)
            assert frozen_garbage <= growth * live * 1.1 + 2 * size, "frozen garbage beyond the bound"
        assert survived_a_call, "every call walked the frozen set"
        assert sum(1 for r in refs if r[0]() is not None) < len(refs) // 2
        assert all((r[0]() is None) == (r[-1]() is None) for r in refs)
    finally:
        gc.unfreeze()


def test_growth_must_not_be_negative():
    with pytest.raises(ValueError, match="growth"):
        settle_garbage(-0.1)


def test_garbage_made_before_the_call_is_collected():
    try:
        ref = weakref.ref(_cycle())
        settle_garbage()  # the first: a full walk
        assert ref() is None
        ref = weakref.ref(_cycle())
        settle_garbage(growth=10.0)  # a later one, which walks only what was made since the last
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
