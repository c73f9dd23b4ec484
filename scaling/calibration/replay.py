"""The logged fins, replayed once, and the body of many candidate fish driven by them.

The fins move by the firmware's rules alone (:mod:`pectoral_gym.model.finrules`, the
parameter-change rule of ``docs/model.md`` section 5): their motion does not depend on the body's
parameters. :func:`replay_fins` therefore runs the one implementation of those rules,
:class:`pectoral_gym.model.finreplay.FinReplay` (which ticks the firmware with
:func:`~pectoral_gym.model.finrules.advance_with_firmware` and hands its decisions to the fins with
:func:`~pectoral_gym.model.finrules.apply_firmware`), once per log, and records what the firmware
handed to the fins and when (a :class:`FinTrack`). :func:`simulate` then drives a batched full model
of any number of candidate fish with those same hand-overs, so every candidate sees exactly the fins the
firmware rules produce, and re-initialises the bodies at the start of each shooting window.

Where the log holds the robot's latch reports (``latch`` records, ``docs/run-log.md``), the replay starts each
reported half-stroke as reported (:meth:`FinReplay.latch`): whether a command that reached the robot near a
turning point was latched there depends on the firmware's tick and the radio's delay, which the PC's commands do
not show. Between reports (a lost one,
a log without them) the rules infer the latches as before.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import FirmwareConfig, force_latch
from pectoral_gym.model.models import FullModel
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.spec import FULL_FAST, FullSpec
from pectoral_gym.runlog import RunLog

__all__ = ["FinTrack", "replay_fins", "simulate"]

_COMMAND, _HALT, _LATCH = 0, 1, 2


class _RecordingModel(FullModel):
    """A one-fish model that records the firmware's hand-overs (``finrules.apply_firmware``).

    ``apply_firmware`` commands the setpoint with ``command_array`` and halts the fins with
    ``reset(..., index=...)``; both are recorded with the model time, then run as usual.
    """

    def __init__(self) -> None:
        self.events: list[tuple[float, int, np.ndarray]] = []
        super().__init__(1, None, integration="fast")  # fins only: the body's integration does not matter

    def command_array(self, beats: np.ndarray, mask: np.ndarray | None = None, validate: bool = True) -> None:
        row = np.array(beats, dtype=float).reshape(2, 4)
        last = next((e for e in reversed(self.events) if e[1] == _COMMAND), None)
        if last is None or not np.array_equal(last[2], row) or self.events[-1][1] == _HALT:
            self.events.append((self.time, _COMMAND, row))  # an unchanged setpoint is no new hand-over
        super().command_array(beats, mask, validate)

    def reset(self, state=None, right=None, left=None, index=None) -> None:  # noqa: D102 - FishModel.reset
        if index is not None and getattr(self, "events", None) is not None and isinstance(right, FinBeat):
            self.events.append((self.time, _HALT, np.array([right.bias, left.bias])))
        super().reset(state, right, left, index)


@dataclass(frozen=True)
class FinTrack:
    """What the firmware handed to the fins during one log, in time order.

    Attributes:
        times: ``(e,)`` times of the hand-overs [s, the log's clock].
        kinds: ``(e,)`` 0: a setpoint commanded (``command_array``), 1: the fins halted where they were,
            2: a reported latch (:func:`~pectoral_gym.model.finrules.force_latch`).
        values: ``(e, 2, 4)`` the setpoint (right fin first); for a halt the fins' angles in ``[:, 0, 0]``
            and ``[:, 1, 0]`` [rad]; for a latch the pattern in ``[0]`` and ``[fin, turn, power, 0]`` in ``[1]``.
        t0: The replay's start [s]; the fins are at rest at 90 deg then (power-up).
    """

    times: np.ndarray
    kinds: np.ndarray
    values: np.ndarray
    t0: float


class _Replay(FinReplay):
    """:class:`FinReplay` on a recording model (the fins' rules unchanged)."""

    def __init__(self, firmware: FirmwareConfig):
        super().__init__(None, firmware)
        self.model = _RecordingModel()
        self.reset(0.0)

    def latch(self, t: float, fin: int, beat: np.ndarray, turn: float, power: bool) -> bool:  # noqa: D102
        applied = super().latch(t, fin, beat, turn, power)
        if applied:
            value = np.stack([np.asarray(beat, dtype=float), np.array([fin, turn, float(power), 0.0])])
            self.model.events.append((self.model.time, _LATCH, value))
        return applied


def replay_fins(log: RunLog) -> FinTrack:
    """Replay the fins of ``log`` once under its firmware settings; returns the hand-overs to drive candidates with.

    Commands, stops and the robot's latch reports of all episodes run on one clock (a hand placing the fish does
    not move its servos); a reported latch starts the half-stroke the robot reported (:meth:`FinReplay.latch`).
    """
    commands = [(float(t), 0, b) for ep in log.episodes for t, b in zip(ep.command_t, ep.beats, strict=True)]
    stops = [(float(t), 1, None) for ep in log.episodes for t in ep.stop_t]
    latches = [(float(t), 2, (int(f), beat, float(turn), bool(power))) for ep in log.episodes
               for t, f, beat, turn, power in zip(ep.latch_t, ep.latch_fin, ep.latch_beat, ep.latch_turn,
                                                  ep.latch_power, strict=True)]
    items = sorted(commands + stops + latches, key=lambda item: (item[0], item[1]))
    t0 = min([log.episodes[0].t_start, *(item[0] for item in items)])
    replay = _Replay(log.firmware)
    replay.reset(t0)
    replay.model.events.clear()
    for t, kind, value in items:
        if kind == 0:
            replay.command(t, value)
        elif kind == 1:
            replay.stop(t)
        else:
            replay.latch(t, *value)
    replay.advance(max(ep.t_end for ep in log.episodes) + 0.05)  # the last setpoints' hand-overs
    events = replay.model.events
    values = np.zeros((len(events), 2, 4))
    for k, (_, kind, value) in enumerate(events):
        if kind in (_COMMAND, _LATCH):
            values[k] = value
        else:
            values[k, :, 0] = value
    return FinTrack(np.array([e[0] for e in events]), np.array([e[1] for e in events], dtype=int), values, t0)


def simulate(track: FinTrack, params: Sequence[FishParams], window_t: np.ndarray, starts: np.ndarray,
             sample_t: np.ndarray, spec: FullSpec = FULL_FAST) -> np.ndarray:
    """Poses of candidate fish driven by the replayed fins, each window started from its own state.

    Args:
        track: The replayed fins (:func:`replay_fins`).
        params: One :class:`FishParams` per candidate fish (``n``).
        window_t: ``(w,)`` window start times [s], increasing.
        starts: ``(n, w, 6)`` each candidate's state ``X, Y, psi, vx, vy, omega`` at each window's start.
        sample_t: ``(s,)`` times to report [s]; a sample reports the window started last before it.
        spec: The full model's integration (default :data:`~pectoral_gym.model.spec.FULL_FAST`).

    Returns:
        ``(n, s, 3)`` the candidates' ``X, Y, psi`` [m, m, rad] at the sample times (``psi`` unwrapped).
    """
    n = len(params)
    model = spec.build(n, list(params))
    model.reset()
    model.time = track.t0
    out = np.empty((n, len(sample_t), 3))
    # One timeline: hand-overs (order 2), window starts (0) and samples (1); at equal times a window starts,
    # then the sample is read, then the fins get their new setpoint.
    times = np.concatenate([track.times, window_t, sample_t])
    order_key = np.concatenate([np.full(len(track.times), 2), np.zeros(len(window_t)), np.ones(len(sample_t))])
    index = np.concatenate([np.arange(len(track.times)), np.arange(len(window_t)), np.arange(len(sample_t))])
    order = np.lexsort((index, order_key, times))
    everyone = np.arange(n)
    for k in order:
        t, key, i = times[k], order_key[k], index[k]
        if t > model.time:
            model.advance(t - model.time)
            model.time = t  # no drift of the summed durations
        if key == 0:
            model.state[:] = starts[:, i]
        elif key == 1:
            out[:, i] = model.state[:, :3]
        elif track.kinds[i] == _COMMAND:
            model.command_array(np.broadcast_to(track.values[i], (n, 2, 4)).copy(), validate=False)
        elif track.kinds[i] == _LATCH:  # the robot's report: every candidate's fin starts that half-stroke
            fin, turn, power = track.values[i, 1, :3]
            force_latch(model, int(fin), t, track.values[i, 0], turn, power > 0.5)
        else:  # a halt: as apply_firmware does, the fins rest where they are and the body keeps its state
            time_now = model.time
            model.reset(model.state.copy(), right=FinBeat.rest(float(track.values[i, 0, 0])),
                        left=FinBeat.rest(float(track.values[i, 1, 0])), index=everyone)
            model.time = time_now
    return out
