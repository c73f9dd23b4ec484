"""The fins as the robot ran them, replayed from the commands sent: the liveness check's view of the fins.

The robot takes a command somewhere between its send and the STATUS that acknowledges it (the radio's forward
delay). :class:`ShadowFins` replays the fins (the firmware's rules, :class:`pectoral_gym.model.finreplay.FinReplay`)
with every command taken a given share of the way from its send to its acknowledgement, and keeps snapshots of
them; :class:`pectoral_gym.hardware.safety.liveness.LivenessWatch` runs three (shares 0, 0.5 and 1) and drives its
fish models with their snapshots.

The robot also reports each latch it makes (LATCH, ``docs/protocol.md``), a return delay late and not every one:
:meth:`ShadowFins.latch` starts the reported half-stroke where and when the robot says
(:meth:`~pectoral_gym.model.finreplay.FinReplay.latch`), so a replay that inferred another stroke finds the robot's
phase again; between reports it infers as before. The replay is run for good only ``hold`` s behind the newest
sighting (the reports' delay), the rest provisionally, so that a report that comes that late still starts its
half-stroke at its own time in every snapshot.
"""

from __future__ import annotations

import bisect
import collections
import math
from collections.abc import Callable

import numpy as np

from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.params import FishParams

__all__ = ["ShadowFins"]


class ShadowFins:
    """Replayed fins that take each command ``share`` of the way from its send time to its acknowledgement.

    The fins are the firmware's (:class:`pectoral_gym.model.finreplay.FinReplay`: hand-over at the next
    turning point, rate rule, the transition's stretch), as the robot runs them; a snapshot of them every
    0.05 s. A command whose acknowledgement is not known yet was acknowledged after the newest sighting ``t``
    (the poses come after their capture), so a shadow with ``share`` > 0 takes it no earlier than
    ``sent + share (t - sent)``: the replay is run for good (:attr:`snapshots`) only that far, never past a
    take it does not know, and :meth:`view` adds a provisional stretch to ``t`` with every such command taken at
    that earliest instant. (Taking it when its acknowledgement becomes known would take it at the
    acknowledgement whatever the share.)

    The robot's latch reports (:meth:`latch`) are taken at their own times, in order with the commands; the run
    for good stays ``hold`` s behind the time it is asked to run to, so a report that much late is still in time.
    One later than that starts its half-stroke as far in as the replay for good is (the snapshots before stay).
    """

    def __init__(self, params: FishParams, config: FirmwareConfig, share: float):
        self.share = share
        self.replay = FinReplay(params, config)
        self.queue: collections.deque[tuple[float, np.ndarray, Callable[[], float | None] | None]] = \
            collections.deque()  # sent, not yet taken
        self.snapshots: collections.deque[tuple[float, np.ndarray, np.ndarray]] = collections.deque(maxlen=512)
        self.latches: list[tuple[float, int, np.ndarray, float, bool]] = []  # reported, not yet taken, by time
        self.hold = 0.0  # the run for good stays this far behind the time asked for [s]
        self.t = math.nan

    def reset(self, t: float) -> None:
        """Fins still at ``t`` [s] (``nan``: not started); no commands."""
        self.queue.clear()
        self.latches.clear()
        self.snapshots.clear()
        self.replay.reset(0.0 if math.isnan(t) else t)
        self.t = float(t)
        if math.isfinite(self.t):
            self._snapshot()

    def _snapshot(self, into: collections.deque | list | None = None) -> None:
        model = self.replay.model
        (self.snapshots if into is None else into).append((self.t, model.fins.copy(), model.pending.copy()))

    def _start(self, sent: float, acknowledged: Callable[[], float | None] | None,
               newest: float) -> tuple[float, bool]:
        """When this shadow takes a command sent at ``sent`` [s], and whether that is known.

        Not known: its earliest, the acknowledgement coming after ``newest`` [s].
        """
        if self.share == 0.0 or acknowledged is None:
            return sent, True
        ack = acknowledged()
        if ack is None:
            return sent + self.share * max(newest - sent, 0.0), False
        return sent + self.share * max(ack - sent, 0.0), True

    def latch(self, t: float, fin: int, beat: np.ndarray, turn: float, power: bool) -> None:
        """The robot reported that fin ``fin`` latched ``beat`` at angle ``turn`` [rad] at time ``t`` [s] (a LATCH).

        Taken at ``t`` if the replay for good is not past it, at once (as far in as the replay is) otherwise.
        """
        if not math.isfinite(self.t):
            return
        report = (float(t), int(fin), np.asarray(beat, dtype=float), float(turn), bool(power))
        if report[0] < self.t:
            self.replay.latch(*report)
        else:
            bisect.insort(self.latches, report, key=lambda r: r[0])

    def _run(self, to: float, newest: float, step: float, provisional: list | None) -> None:
        """Run the fins to ``to``; for good (stopping before a take not known), or ``provisional``ly.

        ``newest`` [s]: the newest sighting (a take not known comes after it).
        """
        queue = self.queue if provisional is None else collections.deque(self.queue)
        latches = self.latches if provisional is None else list(self.latches)
        taken = 0  # reports taken from the front of ``latches``
        while self.t < to:
            target = min(to, self.t + step)
            while True:
                start, known = self._start(queue[0][0], queue[0][2], newest) if queue else (math.inf, True)
                report = latches[taken][0] if taken < len(latches) else math.inf
                if report <= start and report <= target:  # a report before the next take: the robot's latch
                    self.replay.latch(*latches[taken])
                    taken += 1
                    continue
                if start > target:
                    break
                if not known and provisional is None:
                    target = start  # run for good only up to the take not known yet
                    break
                _, beats, _ = queue.popleft()
                self.replay.command(max(start, self.t), beats)
            if target <= self.t:
                break
            self.replay.advance(target)
            self.t = target
            self._snapshot(provisional)
        if provisional is None:
            del latches[:taken]

    def advance(self, to: float, step: float = 0.05) -> None:
        """Run the fins for good towards ``to`` less :attr:`hold` [s], taking the commands and reports due by then.

        A snapshot every ``step`` s.
        """
        self._run(to - self.hold, to, step, None)

    def view(self, to: float, step: float = 0.05) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """The snapshots to ``to`` [s]: those for good, then a provisional stretch.

        In it the commands not yet acknowledged are taken at their earliest and the reports known so far at their
        times; the replay is put back as it was.
        """
        if self.t >= to:
            return list(self.snapshots)
        saved, saved_t = self.replay.checkpoint(), self.t
        tail: list[tuple[float, np.ndarray, np.ndarray]] = []
        try:
            self._run(to, to, step, tail)
        finally:
            self.replay.restore(saved)
            self.t = saved_t
        return list(self.snapshots) + tail

    @staticmethod
    def differs(mine: list, other: list, since: float, memo: dict | None = None) -> bool:
        """Whether the snapshots ``other`` from ``since`` [s] (less one step) on differ from ``mine``.

        ``memo``, if given, keeps the verdicts of the pairs of snapshots compared, keyed by the pair's identities
        (a snapshot is never changed once taken), and holds both so that neither identity is reused: the snapshots
        for good recur from check to check and are compared once. It is emptied and refilled with this call's
        pairs, so it holds no more than one call's.
        """
        start = since - 0.05
        own = {s[0]: s for s in mine if s[0] >= start}  # only these are ever looked up
        previous = {} if memo is None else dict(memo)
        if memo is not None:
            memo.clear()
        for snapshot in other:
            t, fins, pending = snapshot
            if t < start:
                continue
            match = own.get(t)
            if match is None:
                return True
            key = (id(match), id(snapshot))
            known = previous.get(key)
            if known is None:  # np.array_equal on arrays of the same shapes, without its conversions
                same = match[1].shape == fins.shape and match[2].shape == pending.shape and \
                    bool((match[1] == fins).all()) and bool((match[2] == pending).all())
            else:
                same = known[2]
            if memo is not None:
                memo[key] = (match, snapshot, same)
            if not same:
                return True
        return False
