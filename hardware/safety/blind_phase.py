"""The robot's half-strokes over every take time the radio allows: the blind rule's bound on *when* a stroke runs.

The robot takes each command somewhere between its send and the STATUS that acknowledges it (a lost command never;
an acknowledgement covers its command or a later one), and the firmware acts on it at its next tick
(:data:`pectoral_gym.model.finrules.CHUNK`). What a fin runs depends on the take times only through *which* command
is the newest taken at each of its turning points (a still fin: when it takes one): the firmware's rules
(:func:`pectoral_gym.model.finrules.next_latch`, the latch of ``pectoral_gym.model.strokes``) are exact given that
sequence. :func:`phase_strokes` therefore follows each fin through a tree of those choices from the arm, every
node a half-stroke known exactly (pattern, turning points, duration, kind) whose start is known to lie in an
interval of time; at each turning point it branches on the commands that can be the newest taken somewhere in the
interval and trims the interval to where each can. Nodes that run the same half-stroke after the same command are
merged (the hull of their intervals: more take times, never fewer). The half-strokes that can overlap a span are
those the span's bound holds; whatever the take times, the robot's own half-stroke is one of them
(``docs/guide/safety.md``, "When the robot runs a stroke").

Unknown at the arm, and after a possible halt: the angle the fins rest at. The first half-stroke from rest is taken
at its worst (its swing from the far end of the servo range, its shortest period; the firmware may stretch it by
the swing), and its turning point over the whole range of periods; if what the fins latch next depends on the rest
angle, or the tree grows past its budget, nothing is claimed (``None``) and the box of patterns rules alone. A
possible halt (a stop, a lease's end, a watchdog) is one the supervisor tells (``CommandedGain.still``) before it
sends its next command: the fins halted at or after the time told and restart, from rest, with the first command
they take after it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from pectoral_gym.model import strokes
from pectoral_gym.model.finrules import CHUNK, next_latch
from pectoral_gym.model.servo import ServoLimits

__all__ = ["phase_strokes"]

_INTERVALS_PER_NODE = 4  # more start intervals for one half-stroke are merged (the hull of the closest two)
_BUDGET = 6000  # half-strokes followed per fin and query; past it the box rules alone

Command = tuple[float, np.ndarray, "Callable[[], float | None] | None"]


def _takes(commands: Sequence[Command]) -> tuple[np.ndarray, np.ndarray]:
    """Earliest and latest instants [s] the firmware can act on each command (send; acknowledgement plus a tick).

    Not acknowledged yet: any time from its send on. A link that does not tell: when sent (as the box assumes).
    """
    sent = np.array([c[0] for c in commands], dtype=float)
    late = np.empty_like(sent)
    for k, (s, _, acknowledged) in enumerate(commands):
        if acknowledged is None:
            late[k] = s + CHUNK
        else:
            ack = acknowledged()
            late[k] = math.inf if ack is None else max(float(ack), s) + CHUNK
    # An acknowledgement of a later command covers the earlier ones; none is taken after a later one's latest.
    late = np.minimum.accumulate(late[::-1])[::-1]
    return sent, late


def _latch(row: np.ndarray, pattern: np.ndarray) -> np.ndarray:
    """The half-stroke a fin ``row`` (``strokes.FIN_FIELDS``) starts at its turning point with ``pattern`` (4,)."""
    new = row.copy()
    bias, amp, period, ratio = pattern
    power = 1.0 - row[strokes.POWER]
    new[strokes.ANGLE_FROM] = row[strokes.ANGLE_TO]
    new[strokes.ANGLE_TO] = bias + amp if power > 0.5 else bias - amp
    new[strokes.DURATION] = (period if power > 0.5 else ratio * period) / (ratio + 1.0)  # eq. (21)
    new[strokes.ELAPSED], new[strokes.POWER], new[strokes.SWEPT] = 0.0, power, 0.0
    new[strokes.BIAS:strokes.RATIO + 1] = pattern
    return new


def _next_pattern(command: np.ndarray, row: np.ndarray, fin: int, limits: ServoLimits) -> np.ndarray:
    """What fin ``fin`` in half-stroke ``row`` latches of ``command`` (2, 4) at its turning point (the firmware's)."""
    fins = np.stack([row, row])
    return next_latch(np.stack([command[fin], command[fin]]), fins, limits)[0]


def _still_row(angle: float) -> np.ndarray:
    """A fin at rest at ``angle`` [rad]: its next half-stroke is a power stroke latched whole."""
    row = np.zeros(strokes.FIN_FIELDS)
    row[strokes.ANGLE_FROM] = row[strokes.ANGLE_TO] = angle
    return row


def _first_from_rest(command: np.ndarray, fin: int, limits: ServoLimits) -> np.ndarray:
    """The first half-stroke from rest at an unknown angle: its start angle ``nan``, its period the shortest.

    The firmware stretches the period of a transitional half-stroke by its swing from the rest angle
    (:func:`pectoral_gym.model.finrules.stretch_transition`): from none (a rest at the stroke's end) to the most at
    an end of the servo range, so the period lies between the two. The longest is kept in the row's
    ``strokes.SWEPT`` field (0: never stretched), which the tree does not otherwise use.
    """
    ends = [_next_pattern(command, _still_row(a), fin, limits) for a in (limits.angle_min, limits.angle_max)]
    plain = _next_pattern(command, _still_row(float(ends[0][0] + ends[0][1])), fin, limits)  # no swing: no stretch
    row = _latch(_still_row(math.nan), plain)
    row[strokes.ANGLE_FROM] = math.nan
    longest = max(float(ends[0][2]), float(ends[1][2]))
    row[strokes.SWEPT] = longest if longest > plain[2] else 0.0
    return row


def _stretched(row: np.ndarray) -> np.ndarray | None:
    """A first stroke from rest with its longest period (``None``: its period is known)."""
    if row[strokes.SWEPT] <= 0.0:
        return None
    out = row.copy()
    out[strokes.PERIOD] = row[strokes.SWEPT]
    out[strokes.DURATION] = out[strokes.PERIOD] / (out[strokes.RATIO] + 1.0)  # a power stroke
    out[strokes.SWEPT] = 0.0
    return out


def _reaches(command: np.ndarray, row: np.ndarray, limits: ServoLimits) -> bool:
    """Whether the rate rule latches ``command`` (4,) itself at the end of half-stroke ``row`` (a moving fin).

    Every parameter within ``max_rate`` times the half-stroke's duration of the command. For a first stroke whose
    period lies between two (:func:`_first_from_rest`): if it holds at both, it holds between (``|b - T|`` is
    convex in ``T``, the reach ``max_rate T / (zeta + 1)`` linear; the other parameters' reach grows with ``T``),
    and the pattern latched next is then the same for every rest angle.
    """
    reach = np.asarray(limits.max_rate, dtype=float) * row[strokes.DURATION]
    return bool(np.all(np.abs(np.asarray(command, dtype=float) - row[strokes.BIAS:strokes.RATIO + 1]) <= reach))


def _peak(row: np.ndarray, limits: ServoLimits) -> float:
    """The half-stroke's peak rate [rad/s] (a half-cosine); from an unknown angle, from the far end of the range."""
    to, start, d = row[strokes.ANGLE_TO], row[strokes.ANGLE_FROM], row[strokes.DURATION]
    swing = max(to - limits.angle_min, limits.angle_max - to) if math.isnan(start) else abs(to - start)
    return min(math.pi * swing / (2.0 * d), limits.max_speed) if d > 0 else 0.0


class _Nodes:
    """Half-strokes keyed by (fin row, newest command taken), each with its start intervals."""

    def __init__(self) -> None:
        self.open: dict[tuple, tuple[np.ndarray, int, list[list[float]]]] = {}

    def add(self, row: np.ndarray, taken: int, lo: float, hi: float) -> None:
        if lo > hi:
            return
        key = (row[1:].tobytes(), taken)
        entry = self.open.get(key)
        if entry is None:
            self.open[key] = (row, taken, [[lo, hi]])
            return
        spans = entry[2]
        spans.append([lo, hi])
        spans.sort()
        merged = [spans[0]]
        for s in spans[1:]:
            if s[0] <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], s[1])
            else:
                merged.append(s)
        while len(merged) > _INTERVALS_PER_NODE:
            gaps = [merged[i + 1][0] - merged[i][1] for i in range(len(merged) - 1)]
            i = int(np.argmin(gaps))
            merged[i:i + 2] = [[merged[i][0], merged[i + 1][1]]]
        spans[:] = merged

    def pop_earliest(self) -> tuple[np.ndarray, int, list[float]] | None:
        if not self.open:
            return None
        key = min(self.open, key=lambda k: self.open[k][2][0][0])
        row, taken, spans = self.open[key]
        span = spans.pop(0)
        if not spans:
            del self.open[key]
        return row, taken, span


def phase_strokes(commands: Sequence[Command], t0: float, t1: float, limits: ServoLimits,
                  halts: Sequence[tuple[float, int | None]] = (), memo: dict | None = None) -> list[np.ndarray] | None:
    """Per fin, ``(m, 2)`` the peak rate [rad/s] and duration [s] of every half-stroke that can run in ``[t0, t1]``.

    A fin that cannot move in the span has none (``(0, 2)``).
    ``commands``: every command sent since the arm (the fins at rest, at an unknown angle), oldest first, as
    ``(sent, clipped beats (2, 4) as received, acknowledged-at)`` (:class:`pectoral_gym.hardware.safety.blind.
    CommandedGain`'s); ``halts``: possible halts (anywhere), each at or after a time [s] and before the command of
    an index was sent (``None``: none sent since). ``memo``:
    the firmware's latches computed before, kept by the caller between calls with the same commands (cleared when
    they change other than by a new one). ``None``: nothing claimed (module docstring).
    """
    found: list[set[tuple[float, float]]] = [set(), set()]
    commands = [c for c in commands if c[0] <= t1]
    if not commands:
        return [np.zeros((0, 2)), np.zeros((0, 2))]
    sent, late = _takes(commands)
    n = len(commands)
    memo = {} if memo is None else memo

    def pattern(k: int, row: np.ndarray, fin: int) -> np.ndarray:
        key = (k, fin, row.tobytes())
        if key not in memo:
            memo[key] = _next_pattern(commands[k][1], row, fin, limits)
        return memo[key]

    for fin in range(2):
        nodes = _Nodes()
        # The first command taken after the arm, or after a possible halt, is latched at once from rest, at its take
        # (the robot restarts halted fins for a new command only). A halt told at ``h`` happened at ``h`` or later
        # but before the next command ``m`` was sent: the first command taken after it is taken by ``m``'s latest.
        starts = [(k, sent[k], late[k]) for k in range(n) if sent[k] <= late[0]]
        for h, m in halts:
            if h <= t1:
                limit = late[m] if m is not None and m < n else math.inf
                starts += [(k, max(sent[k], h), late[k]) for k in range(n) if late[k] >= h and sent[k] <= limit]
        for k, first, last in starts:
            key = (k, fin, b"rest")
            if key not in memo:
                memo[key] = _first_from_rest(commands[k][1], fin, limits)
            nodes.add(memo[key], k, first, min(last, t1))
        budget = _BUDGET
        while (item := nodes.pop_earliest()) is not None:
            row, taken, (lo, hi) = item
            if lo > t1:
                continue
            budget -= 1
            if budget < 0:
                return None
            d = row[strokes.DURATION]
            longest = _stretched(row)  # a first stroke from rest: its period between d's and longest's
            d_hi = d if longest is None else longest[strokes.DURATION]
            swing = row[strokes.ANGLE_TO] - row[strokes.ANGLE_FROM]
            still = swing == 0.0
            if not still and hi + d_hi >= t0:  # it can overlap the span (at its far-end rate, its shortest)
                found[fin].add((_peak(row, limits), float(d)))
            if still:
                # A fin at rest takes a command whole as soon as the firmware acts on it: the newest taken when this
                # rest began again (the rest may not be its pattern), or a later one when it is taken.
                for k in range(taken, n):
                    new = pattern(k, row, fin)
                    if np.array_equal(new, row[strokes.BIAS:strokes.RATIO + 1]):
                        continue  # the same rest again
                    rest = row.copy()
                    rest[strokes.POWER] = 0.0  # a still fin's next half-stroke is a power stroke
                    start = _latch(rest, new)
                    if k == taken:
                        nodes.add(start, k, lo, min(hi + CHUNK, t1))
                    else:
                        nodes.add(start, k, max(lo, sent[k]), min(late[k], t1))
                continue
            turn_lo, turn_hi = lo + d, hi + d_hi  # the turning point
            for k in range(taken, n):
                # Command k is the newest taken at the turning point: taken by then, no later one surely taken.
                first = max(turn_lo, sent[k]) if k > taken else turn_lo
                if first > turn_hi or first > t1:
                    break  # (sent times grow with k)
                last = min(turn_hi, late[k + 1]) if k + 1 < n else turn_hi
                if first > last:
                    continue
                new = pattern(k, row, fin)
                if longest is not None and not (_reaches(commands[k][1][fin], row, limits)
                                                and _reaches(commands[k][1][fin], longest, limits)):
                    return None  # what is latched next depends on the rest angle: nothing claimed
                nodes.add(_latch(row, new), k, first, min(last, t1))
    return [np.array(sorted(f), dtype=float).reshape(-1, 2) for f in found]
