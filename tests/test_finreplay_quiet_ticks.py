"""A replay of the fins advances the ticks whose rules would be skipped in one compiled call, bit for bit.

Its checkpoints copy the firmware's state by hand: the look-aheads restored from them run as from deep copies.

The reference is the firmware's own loop, :func:`pectoral_gym.model.finrules.advance_with_firmware`: every tick the
setpoint, :func:`~pectoral_gym.model.finrules.apply_firmware` and one model call of a tick's length.
"""

import copy

import numpy as np
import pytest
from test_finrules_latch_memo import _play, _script

from pectoral_gym.model import finreplay, segment_runs, strokes
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import CHUNK, FirmwareConfig, advance_with_firmware
from pectoral_gym.model.servo import ServoLimits
from pectoral_gym.model.spec import FULL_REFERENCE


class _TickByTick(FinReplay):
    """The reference: every tick from Python, as the firmware's loop runs it; checkpoints by ``copy.deepcopy``."""

    def advance(self, t: float) -> None:
        advance_with_firmware(self.firmware, self.model, float(t))

    def checkpoint(self) -> tuple:
        saved = super().checkpoint()
        return (copy.deepcopy(self.firmware), *saved[1:])


def _state(replay: FinReplay) -> bytes:
    firmware, model = replay.firmware, replay.model
    handed = b"none" if firmware.handed is None else firmware.handed.tobytes()
    memo = b"none" if firmware.latch_memo is None else b"".join(firmware.latch_memo[0])
    return b"|".join([model.fins.tobytes(), model.pending.tobytes(), model.state.tobytes(), model.integral.tobytes(),
                      model.forcing_cache.tobytes(), np.float64(model.time).tobytes(), handed, memo,
                      firmware.setpoint.tobytes(), bytes([firmware.running, firmware.halt])])


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("limits", [ServoLimits(), ServoLimits(max_speed=8.0, max_rate=(0.5, 0.4, 0.6, 2.0))])
def test_quiet_ticks_in_one_call_run_the_fins_as_tick_by_tick(seed, limits, monkeypatch):
    runs = {"calls": 0, "ticks": 0}
    quiet = segment_runs.run_quiet_ticks

    def counted(model, target, chunk):
        start = model.time
        quiet(model, target, chunk)
        runs["calls"] += 1
        runs["ticks"] += round((model.time - start) / chunk)

    monkeypatch.setattr(finreplay, "run_quiet_ticks", counted)
    config = FirmwareConfig(limits=limits)
    events = _script(seed, 20.0)  # commands, stops, latch reports, look-aheads from checkpoints, advances
    reference = _play(_TickByTick(None, config), events, _state)
    fast = _play(FinReplay(None, config), events, _state)
    assert len(fast) == len(reference)
    for i, (mine, theirs) in enumerate(zip(fast, reference, strict=True)):
        assert mine == theirs, f"seed {seed}: the replays part at event {i}"
    assert runs["calls"] > 50 and runs["ticks"] > 3 * runs["calls"]  # many ticks per call: the kernel was used


def test_quiet_ticks_end_one_tick_past_a_turning_point():
    """The fields of a half-stroke change where it starts: the ticks stop there, the rules run at the next tick."""
    model = FULL_REFERENCE.build(1)
    beat = np.array([1.5, 0.5, 1.0, 1.0])  # ratio 1: each half-stroke lasts 0.5 s
    model.reset(right=beat, left=beat)
    model.advance(0.3)  # the first half-stroke latched at 0, the next turning point at 0.5 s
    model.time = 0.3
    segment_runs.run_quiet_ticks(model, 2.0, CHUNK)
    # ticks to 0.5 s, the tick from 0.5 s that starts the next half-stroke, and no more
    assert model.time == pytest.approx(0.51, abs=1e-12)
    assert model.fins[0, 0, strokes.ELAPSED] == pytest.approx(0.01, abs=1e-12)
    segment_runs.run_quiet_ticks(model, 0.8, CHUNK)  # no turning point before the target: ticks to it exactly
    assert model.time == pytest.approx(0.8, abs=1e-12)


def test_a_checkpoint_shares_no_array_with_the_replay_and_keeps_the_memo_of_its_own_hand_over():
    replay = FinReplay()
    replay.command(0.0, np.array([[1.5, 0.5, 1.0, 2.0], [1.4, 0.4, 0.8, 1.5]]))
    replay.advance(0.3)
    firmware = replay.firmware
    assert firmware.latch_memo is not None and firmware.latch_memo[2] is firmware.handed
    saved = replay.checkpoint()[0]
    deep = copy.deepcopy(firmware)
    assert type(saved) is type(firmware) and vars(saved).keys() == vars(deep).keys()
    for name, value in vars(deep).items():
        mine = getattr(saved, name)
        if isinstance(value, np.ndarray):
            assert not np.shares_memory(mine, getattr(firmware, name)), name
            assert mine.tobytes() == value.tobytes(), name
        elif name != "latch_memo":
            assert mine == value, name
    assert saved.latch_memo[0] == deep.latch_memo[0]
    assert saved.latch_memo[2] is saved.handed and saved.latch_memo[1] is saved.config.limits
