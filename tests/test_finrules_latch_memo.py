"""The firmware's tick skips the fin rules when their inputs did not change, and the fins run as if it never did.

:func:`pectoral_gym.model.finrules.apply_firmware` keeps what :func:`~pectoral_gym.model.finrules.next_latch` read
at the last hand-over (``FinState.latch_memo``) and, with the same setpoint and fin fields bit for bit, hands
nothing over. The reference here is the numpy form run at every tick: a replay whose firmware never keeps a memo.
"""

import math

import numpy as np
import pytest

from pectoral_gym.model import finreplay, finrules
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.servo import ServoLimits


class _NoMemo(finreplay._ReplayedFirmware):
    """The replay's firmware that never keeps a memo: ``next_latch`` runs at every tick (the reference)."""

    @property
    def latch_memo(self) -> None:
        return None

    @latch_memo.setter
    def latch_memo(self, value: object) -> None:
        pass


class _ReferenceReplay(FinReplay):
    def reset(self, t: float) -> None:
        super().reset(t)
        self.firmware = _NoMemo(self.firmware_config)


def _beats(rng: np.random.Generator) -> np.ndarray:
    """Random ``(2, 4)`` commands, many outside the servo limits (clipped, stretched) and some of still fins."""
    beats = np.column_stack([rng.uniform(0.0, math.pi, 2), rng.uniform(0.0, 1.4, 2), rng.uniform(0.15, 4.5, 2),
                             rng.uniform(0.2, 8.0, 2)])
    beats[rng.random(2) < 0.2, 1] = 0.0  # a fin held still
    return beats


def _state(replay: FinReplay) -> bytes:
    firmware = replay.firmware
    handed = b"none" if firmware.handed is None else firmware.handed.tobytes()
    return b"|".join([replay.model.fins.tobytes(), replay.model.pending.tobytes(), replay.model.state.tobytes(),
                      np.float64(replay.model.time).tobytes(), handed, firmware.setpoint.tobytes(),
                      bytes([firmware.running, firmware.halt])])


def _script(seed: int, seconds: float) -> list[tuple]:
    """A seeded sequence of replay events: commands (some repeated), stops, latch reports, look-aheads, advances."""
    rng = np.random.default_rng(seed)
    events: list[tuple] = []
    t, last = 0.0, _beats(rng)
    while t < seconds:
        t += float(rng.choice([0.003, 0.01, 0.037, 0.1, 0.25, 0.5]))
        kind = rng.random()
        if kind < 0.25:
            last = last if rng.random() < 0.2 else _beats(rng)  # the same command again: a new identity
            events.append(("command", t, last))
        elif kind < 0.3:
            events.append(("stop", t))
        elif kind < 0.36:
            beat = _beats(rng)[0]
            events.append(("latch", t, int(rng.integers(2)), beat, float(rng.uniform(0.3, 2.8)),
                           bool(rng.random() < 0.5)))
        elif kind < 0.42:
            events.append(("look_ahead", t, _beats(rng), t + float(rng.uniform(0.05, 0.6))))
        else:
            events.append(("advance", t))
    return events


def _play(replay: FinReplay, events: list[tuple], state=_state) -> list[bytes]:
    """``state(replay)`` after each event (and the look-ahead's before it is put back)."""
    states = []
    for event in events:
        kind, t = event[0], event[1]
        if kind == "command":
            replay.command(t, event[2])
        elif kind == "stop":
            replay.stop(t)
        elif kind == "latch":
            replay.latch(t, *event[2:])
        elif kind == "look_ahead":  # a provisional stretch, then the replay put back (as ShadowFins.view does)
            saved = replay.checkpoint()
            replay.command(t, event[2])
            replay.advance(event[3])
            states.append(state(replay))
            replay.restore(saved)
        else:
            replay.advance(t)
        states.append(state(replay))
    return states


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("limits", [ServoLimits(), ServoLimits(max_speed=8.0, max_rate=(0.5, 0.4, 0.6, 2.0))])
def test_the_ticks_with_the_memo_run_the_fins_as_the_numpy_rules_at_every_tick(seed, limits, monkeypatch):
    calls = {"n": 0}
    rules = finrules.next_latch

    def counted(*args, **kwargs):
        calls["n"] += 1
        return rules(*args, **kwargs)

    monkeypatch.setattr(finrules, "next_latch", counted)
    events = _script(seed, 20.0)
    config = FirmwareConfig(limits=limits)
    reference = _play(_ReferenceReplay(None, config), events)
    reference_calls, calls["n"] = calls["n"], 0
    fast = _play(FinReplay(None, config), events)
    assert len(fast) == len(reference)
    for i, (mine, theirs) in enumerate(zip(fast, reference, strict=True)):
        assert mine == theirs, f"seed {seed}: the replays part at event {i} ({events[min(i, len(events) - 1)][0]})"
    # the memo is used: the rules run at hand-overs and turning points, not at every tick
    assert reference_calls > 1000
    assert calls["n"] < reference_calls / 3


def test_a_changed_fin_field_is_seen_whatever_changed_it():
    """A fin's pattern changed behind the firmware's back (no tick saw it): the rules run again at the next tick."""
    replay = FinReplay(None, FirmwareConfig(limits=ServoLimits(max_rate=(0.5, 0.4, 0.6, 2.0))))
    replay.command(0.0, np.array([[1.5, 0.6, 1.0, 1.0], [1.6, 0.5, 1.2, 2.0]]))
    replay.advance(0.3)
    memo, handed = replay.firmware.latch_memo, replay.firmware.handed
    assert memo is not None
    replay.advance(0.35)  # no turning point in between: the same inputs, the memo kept, nothing handed over
    assert replay.firmware.latch_memo is memo and replay.firmware.handed is handed
    replay.model.fins[0, 0, finrules.strokes.PERIOD] = 3.0  # the right fin now runs a slower pattern
    expected = finrules.next_latch(replay.firmware.command, replay.model.fins[0], replay.firmware.config.limits)
    assert not np.array_equal(expected, handed)  # the rate rule holds the period back from the command
    replay.advance(0.36)
    np.testing.assert_array_equal(replay.firmware.handed, expected)
    np.testing.assert_array_equal(replay.model.pending[0], expected)
