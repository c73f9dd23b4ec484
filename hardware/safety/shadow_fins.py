"""The fins as the robot ran them, replayed from the commands sent: the liveness check's view of the fins.

The robot takes a command somewhere between its send and the STATUS that acknowledges it (the radio's forward
delay). :class:`ShadowFins` replays the fins (the firmware's rules, :class:`pectoral_gym.model.finreplay.FinReplay`)
with every command taken a given share of the way from its send to its acknowledgement, and keeps snapshots of
them; :class:`pectoral_gym.hardware.safety.liveness.LivenessWatch` runs three (shares 0, 0.5 and 1) and drives its
fish models with their snapshots.

The robot also reports each latch it makes (LATCH, ``docs/protocol.md``), a return delay late and not every one:
:meth:`ShadowFins.latch` starts the reported half-stroke where and when the robot says
(:meth:`~pectoral_gym.model.finreplay.FinReplay.latch`), so a replay that inferred another stroke finds the robot's
phase again; between reports it infers as before. A report comes after the replay passed its time: the replay
keeps its state at each snapshot of the last :data:`REWIND` s, and a report that the replay's half-stroke there
does not already match rewinds it to the snapshot before the report's time and runs it again from there, so the
reported half-stroke starts at its own time in every snapshot.
"""

from __future__ import annotations

import bisect
import collections
import copy
import math
from collections.abc import Callable

import numpy as np

from pectoral_gym.model import strokes
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.params import FishParams

__all__ = ["ShadowFins", "REWIND"]

REWIND = 1.2  # how far back a report may rewind a replay [s]: the radio's return delay and more
_MARK_EVERY = 0.1  # the replay's state is kept this often [s] (a checkpoint costs a tenth of a 0.05 s step)
_SAME_START = 0.015  # a half-stroke that started this close to a report's time [s] is the one reported (a tick)
_SAME_VALUE = 2e-3  # ... with angles and pattern this close (the wire's quantum, 1e-3, and its rounding)


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

    The robot's latch reports (:meth:`latch`) are taken at their own times, in order with the commands; one that
    comes after the replay passed its time rewinds it (at most :data:`REWIND` s) unless the replay already ran
    that half-stroke there. One older than that starts its half-stroke as far in as the replay is (the snapshots
    before stay).
    """

    def __init__(self, params: FishParams, config: FirmwareConfig, share: float):
        self.share = share
        self.replay = FinReplay(params, config)
        self.queue: collections.deque[tuple[float, np.ndarray, Callable[[], float | None] | None]] = \
            collections.deque()  # sent, not yet taken
        self.snapshots: collections.deque[tuple[float, np.ndarray, np.ndarray]] = collections.deque(maxlen=512)
        self.latches: list[tuple[float, int, np.ndarray, float, bool]] = []  # reported, not yet taken, by time
        # The replay's state at each recent snapshot for good, with what it took after it: [t, checkpoint, taken]
        self._marks: collections.deque[list] = collections.deque()
        self.rewinds = 0  # reports that rewound the replay (for studies)
        self.t = math.nan

    def reset(self, t: float) -> None:
        """Fins still at ``t`` [s] (``nan``: not started); no commands."""
        self.queue.clear()
        self.latches.clear()
        self._marks.clear()
        self.snapshots.clear()
        self.replay.reset(0.0 if math.isnan(t) else t)
        self.t = float(t)
        if math.isfinite(self.t):
            self._snapshot()

    def _snapshot(self, into: collections.deque | list | None = None) -> None:
        model = self.replay.model
        (self.snapshots if into is None else into).append((self.t, model.fins.copy(), model.pending.copy()))
        if into is None and (not self._marks or self.t >= self._marks[-1][0] + _MARK_EVERY):  # a mark to rewind to
            self._marks.append([self.t, self.replay.checkpoint(), []])
            while self._marks[0][0] < self.t - REWIND:
                self._marks.popleft()

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

        Taken at ``t``: in order with the commands if the replay is not past it; if it is, by a rewind to the
        snapshot before ``t`` (at most :data:`REWIND` s back) unless the replay already started that half-stroke
        there; older still, at once, as far in as the replay is.
        """
        if not math.isfinite(self.t):
            return
        report = (float(t), int(fin), np.asarray(beat, dtype=float), float(turn), bool(power))
        if report[0] >= self.t:
            bisect.insort(self.latches, report, key=lambda r: r[0])
            return
        if self._ran(report):
            return
        marks = [m for m in self._marks if m[0] < report[0]]
        if not marks:
            self.replay.latch(*report)
            return
        instants = self._rewind(marks[-1])
        bisect.insort(self.latches, report, key=lambda r: r[0])
        for t in instants:  # as far as it was, with the report in its place, snapshots at the same instants
            self._run(t, t, 0.05, None)

    def _ran(self, report: tuple) -> bool:
        """Whether the replay's first snapshot after the report's time runs the reported half-stroke already."""
        t, fin, beat, turn, power = report
        after = next((s for s in self.snapshots if s[0] > t), None)
        if after is None:
            return False
        fins = after[1][0, fin]
        start = after[0] - fins[strokes.ELAPSED]
        return abs(start - t) <= _SAME_START and bool(fins[strokes.POWER]) == power and \
            abs(fins[strokes.ANGLE_FROM] - turn) <= _SAME_VALUE and \
            bool(np.all(np.abs(fins[strokes.BIAS:strokes.RATIO + 1] - beat) <= _SAME_VALUE))

    def _rewind(self, mark: list) -> list[float]:
        """Put the replay back to ``mark``; what it took since goes back to be taken again.

        Returns the instants of the snapshots dropped [s].
        """
        self.rewinds += 1
        while self._marks[-1] is not mark:
            _, _, taken = self._marks.pop()
            self._untake(taken)
        self._untake(mark[2])
        mark[2] = []
        t, checkpoint = mark[0], mark[1]
        self.replay.restore((copy.deepcopy(checkpoint[0]), *checkpoint[1:]))  # the mark stays for a later rewind
        instants = [self.t]
        self.t = t
        while self.snapshots and self.snapshots[-1][0] > t:
            instants.append(self.snapshots.pop()[0])
        return sorted(set(instants))

    def _untake(self, taken: list) -> None:
        for kind, item in reversed(taken):
            if kind == "command":
                self.queue.appendleft(item)
            else:
                bisect.insort(self.latches, item, key=lambda r: r[0])

    def _run(self, to: float, newest: float, step: float, provisional: list | None) -> None:
        """Run the fins to ``to``; for good (stopping before a take not known), or ``provisional``ly.

        ``newest`` [s]: the newest sighting (a take not known comes after it).
        """
        queue = self.queue if provisional is None else collections.deque(self.queue)
        latches = self.latches if provisional is None else list(self.latches)
        taken = 0  # reports taken from the front of ``latches``
        log = self._marks[-1][2] if provisional is None and self._marks else []  # what is taken after the mark
        while self.t < to:
            target = min(to, self.t + step)
            while True:
                start, known = self._start(queue[0][0], queue[0][2], newest) if queue else (math.inf, True)
                report = latches[taken][0] if taken < len(latches) else math.inf
                if report <= start and report <= target:  # a report before the next take: the robot's latch
                    self.replay.latch(*latches[taken])
                    log.append(("latch", latches[taken]))
                    taken += 1
                    continue
                if start > target:
                    break
                if not known and provisional is None:
                    target = start  # run for good only up to the take not known yet
                    break
                item = queue.popleft()
                self.replay.command(max(start, self.t), item[1])
                log.append(("command", item))
            if target <= self.t:
                break
            self.replay.advance(target)
            self.t = target
            self._snapshot(provisional)
            if provisional is None:
                log = self._marks[-1][2]
        if provisional is None:
            del latches[:taken]

    def advance(self, to: float, step: float = 0.05) -> None:
        """Run the fins for good towards ``to`` [s], taking the commands and reports due by then.

        A snapshot every ``step`` s.
        """
        self._run(to, to, step, None)

    def view(self, to: float, step: float = 0.05) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """The snapshots to ``to`` [s]: those for good, then a provisional stretch.

        In it the commands not yet acknowledged are taken at their earliest; the replay is put back as it was.
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
    def differs(mine: list, other: list, since: float, memo: dict | None = None, until: float = math.inf) -> bool:
        """Whether the snapshots ``other`` from ``since`` [s] (less one step) on differ from ``mine`` (time-ordered).

        ``memo``, if given, keeps the verdicts of the pairs of snapshots compared, keyed by the pair's identities
        (a snapshot is never changed once taken), and holds both so that neither identity is reused: the snapshots
        for good recur from check to check and are compared once. It is emptied and refilled with this call's
        pairs, so it holds no more than one call's. ``until`` [s]: only the snapshots before it (less one step).
        """
        start = since - 0.05
        # both in time order: only the snapshots from start on are compared, and only those are looked up
        own = {s[0]: s for s in mine[bisect.bisect_left(mine, start, key=_instant):]}
        previous = {} if memo is None else dict(memo)
        if memo is not None:
            memo.clear()
        stop = len(other) if until == math.inf else bisect.bisect_left(other, until - 0.05, key=_instant)
        for snapshot in other[bisect.bisect_left(other, start, key=_instant):stop]:
            t, fins, pending = snapshot
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


def _instant(snapshot: tuple) -> float:
    return snapshot[0]
