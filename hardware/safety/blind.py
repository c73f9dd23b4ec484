"""The blind rule's speed gain: how fast the fish can speed up while unseen, from the fins the PC commanded.

While the camera shows nothing new, the geofence adds to the measured speed the most the fish can have gained
since its last pose (:class:`pectoral_gym.hardware.safety.supervisor.Supervisor`'s blind rule). The fastest gain
the servos allow (``SpeedBound.accel``, 2.8 m/s^2: both fins at 13 rad/s) assumes nothing about the fins; the
PC knows what it told them, the firmware's rules (``docs/protocol.md`` §5) say what the fins run from that, and
the liveness check (:mod:`pectoral_gym.hardware.safety.liveness`) stops a robot whose fish does not follow them.
:class:`CommandedGain` gives ``SpeedBound``'s impulse bound with the fins' peak rate taken from what they can
be running in the span (``docs/guide/safety.md``, "The blind rule and the commanded fins"):

* the fins replayed from the commands (:class:`pectoral_gym.model.finreplay.FinReplay`) give the patterns
  latched; the robot takes each command between its send and its acknowledgement, so its latched patterns lie
  in the box (componentwise hull) of the replay's over the span widened by a round trip and of the commands
  sent since (the rate rule moves a latched pattern towards the command, never past it; the clip only
  lengthens a period, a slower fin), the commands as quantised on the wire;
* a half-stroke of a pattern in that box, steady or transitional (from a turning point of the pattern run before,
  a lower one for a power stroke and an upper one for a recovery, to one of the new pattern, in the new one's
  duration), has a peak rate of at most :func:`box_rate`, never above ``max_speed`` (the firmware stretches the
  period), and lasts at least :func:`box_half_stroke`; a half-stroke in progress at the span's start began up to
  its duration earlier, from a turning point of the pattern run before it, so the box reaches back by the longest
  half-stroke of its patterns;
* a fin that may have been still (after an arm, a stop, a lease's end, a possible watchdog halt) latches the next
  command whole and swings from wherever it stopped, an angle within the servo range: until that first power
  stroke is over its peak rate is at most :func:`first_stroke`'s (the farthest end of the servo range to
  ``bias + A`` in the power stroke's time, at most ``max_speed``), and any command sent since may be the one.

One fin's force is at most ``k w^2 + I_p sqrt((pi w / d)^2 + w^4)`` for a peak rate ``w`` and half-strokes of at
least ``d`` (:func:`fin_force_bound`, ``SpeedBound``'s with ``max_speed`` replaced by ``w`` and the servos'
shortest half-stroke by ``d``), and the fish's speed grows at most at the two fins' sum over ``min(m1, m2)``.

The box assumes any of its half-strokes may run at any instant of the span. The take tree
(:func:`pectoral_gym.hardware.safety.blind_phase.phase_strokes`) follows the robot's half-strokes over every take
time the radio allows and bounds each fin's force per half-stroke, at its own rate and duration; the gain is the
least of the two bounds (both hold whatever the take times).
"""

from __future__ import annotations

import collections
import math
from collections.abc import Callable

import numpy as np

from pectoral_gym.hardware.safety.blind_phase import phase_strokes
from pectoral_gym.model import strokes
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import FirmwareConfig, wire_beats
from pectoral_gym.model.params import FishParams, body_coefficients
from pectoral_gym.model.servo import ServoLimits, clip_beats

__all__ = [
    "CommandedGain", "box_half_stroke", "box_rate", "fin_force_bound", "fin_pair_force_bound",
    "first_stroke", "longest_half_stroke", "ls_velocity", "shortest_half_stroke", "unseen_reason",
]

_MAX_TREE_COMMANDS = 400  # commands since the arm the take tree follows (200 s at 0.5 s); past them, the box alone
_MIN_POSES, _MIN_SPAN = 3, 0.1  # fewer poses, or a shorter span [s]: no velocity estimate (the physical bound rules)

def shortest_half_stroke(limits: ServoLimits) -> float:
    """The shortest half-stroke the firmware runs [s]: ``period_min`` times the smaller share at the ratio limits."""
    return limits.period_min * min(limits.ratio_min / (limits.ratio_min + 1.0), 1.0 / (limits.ratio_max + 1.0))


def fin_force_bound(params: FishParams, limits: ServoLimits, rate: float, shortest: float | None = None,
                    fin: int | None = None) -> float:
    """The largest force [N] one fin exerts on the body while its commanded peak rate is ``rate`` [rad/s] (eqs. 13-17).

    ``|F_n| = s k g'^2`` plus the fin's inertia ``I_p sqrt(g''^2 + g'^4)``, with ``|g''| <= pi |g'|_peak / d`` for a
    half-cosine stroke of duration ``d``: at least ``shortest`` [s] (the fins' shortest half-stroke, when known),
    never less than :func:`shortest_half_stroke`. The fin's actual rate is its servo scale ``a_1`` times the
    commanded one and ``s`` is its force factor (``FishParams``' per-fin fields; the servo offset moves the angle,
    not the rate). ``fin``: 0 the right fin, 1 the left; ``None``: the larger of the two.
    """
    if fin is None:
        return max(fin_force_bound(params, limits, rate, shortest, side) for side in (0, 1))
    side = ("right", "left")[fin]
    w = float(rate) * getattr(params, f"fin_angle_scale_{side}")
    d_min = shortest_half_stroke(limits)
    if shortest is not None:
        d_min = max(float(shortest), d_min)
    return (getattr(params, f"fin_force_scale_{side}") * params.fin_drag_constant * w * w
            + params.fin_inertia_constant * math.hypot(w * w, math.pi * w / d_min))


def fin_pair_force_bound(params: FishParams, limits: ServoLimits) -> float:
    """``|f_R| + |f_L|`` at most [N]: both fins at the servos' peak rate and shortest half-stroke."""
    return sum(fin_force_bound(params, limits, limits.max_speed, fin=fin) for fin in (0, 1))


def box_rate(patterns: np.ndarray, limits: ServoLimits, sources: np.ndarray | None = None) -> np.ndarray:
    """``(2,)`` the highest peak rate [rad/s] of any half-stroke of fins running patterns in the box of ``patterns``.

    ``patterns`` ``(n, 2, 4)`` (clipped, ``bias, A, T_p, zeta``); ``sources`` ``(m, 2, 4)``: the patterns whose
    turning points a half-stroke may start from (default ``patterns``; a half-stroke in progress at a window's start
    began at a turning point of an older one). A half-stroke, steady or transitional, goes from a turning point of
    the pattern run before to one of the new pattern: a power stroke from a lower one (``bias - A``) to
    ``bias + A`` in ``T_p / (zeta + 1)``, a recovery from an upper one to ``bias - A`` in ``zeta T_p / (zeta + 1)``
    (the strokes alternate); its peak rate is ``pi |swing| / (2 d)`` (a half-cosine). Capped at ``max_speed``.
    """
    p = np.asarray(patterns, dtype=float).reshape(-1, 2, 4)
    src = p if sources is None else np.concatenate([p, np.asarray(sources, dtype=float).reshape(-1, 2, 4)])
    lo, hi = p.min(axis=0), p.max(axis=0)
    s_lo, s_hi = src.min(axis=0), src.max(axis=0)
    power_swing = np.maximum(hi[:, 0] + hi[:, 1] - (s_lo[:, 0] - s_hi[:, 1]),
                             (s_hi[:, 0] - s_lo[:, 1]) - (lo[:, 0] + lo[:, 1]))
    recovery_swing = np.maximum((s_hi[:, 0] + s_hi[:, 1]) - (lo[:, 0] - hi[:, 1]),
                                (hi[:, 0] - lo[:, 1]) - (s_lo[:, 0] + s_lo[:, 1]))
    power_d, recovery_d = lo[:, 2] / (hi[:, 3] + 1.0), lo[:, 2] * lo[:, 3] / (lo[:, 3] + 1.0)
    peak = np.maximum(math.pi * np.maximum(power_swing, 0.0) / (2.0 * power_d),
                      math.pi * np.maximum(recovery_swing, 0.0) / (2.0 * recovery_d))
    return np.minimum(peak, limits.max_speed)


def box_half_stroke(patterns: np.ndarray) -> np.ndarray:
    """``(2,)`` the shortest half-stroke [s] of fins running patterns in the box of ``patterns`` ``(n, 2, 4)``.

    Power ``T_p / (zeta + 1)``, recovery ``zeta T_p / (zeta + 1)``: at least ``T_lo / (zeta_hi + 1)`` and
    ``T_lo zeta_lo / (zeta_lo + 1)``; a transitional half-stroke takes the new pattern's duration, and the firmware's
    stretches only lengthen a period.
    """
    p = np.asarray(patterns, dtype=float).reshape(-1, 2, 4)
    lo, hi = p.min(axis=0), p.max(axis=0)
    return np.minimum(lo[:, 2] / (hi[:, 3] + 1.0), lo[:, 2] * lo[:, 3] / (lo[:, 3] + 1.0))


def longest_half_stroke(patterns: np.ndarray) -> np.ndarray:
    """``(2,)`` the longest half-stroke [s] of fins running patterns in the box of ``patterns`` ``(n, 2, 4)``."""
    p = np.asarray(patterns, dtype=float).reshape(-1, 2, 4)
    lo, hi = p.min(axis=0), p.max(axis=0)
    return np.maximum(hi[:, 2] / (lo[:, 3] + 1.0), hi[:, 2] * hi[:, 3] / (hi[:, 3] + 1.0))


def first_stroke(commands: np.ndarray, limits: ServoLimits) -> tuple[np.ndarray, np.ndarray]:
    """``(2,)`` peak rate [rad/s] and ``(2,)`` shortest duration [s] of a still fin's first half-stroke.

    A still fin latches a command whole, at once, and swings with a power stroke from wherever it stopped (an angle
    within the servo range) to ``bias + A`` in ``T_p / (zeta + 1)``, the period stretched if that would exceed
    ``max_speed`` (:func:`pectoral_gym.model.finrules.stretch_transition`); a half-cosine, so its peak rate is
    ``pi |swing| / (2 d)``. Over every command of ``commands`` ``(n, 2, 4)`` (clipped) that may be the one latched.
    """
    p = np.asarray(commands, dtype=float).reshape(-1, 2, 4)
    to = p[..., 0] + p[..., 1]
    swing = np.maximum(limits.angle_max - to, to - limits.angle_min)
    duration = p[..., 2] / (p[..., 3] + 1.0)
    rate = np.minimum(math.pi * swing / (2.0 * duration), limits.max_speed)
    return rate.max(axis=0), duration.min(axis=0)


def _first_power_stroke(beats: np.ndarray, limits: ServoLimits) -> float:
    """The longest a still fin's first half-stroke of ``beats`` ``(2, 4)`` lasts [s].

    A fin that is not moving latches a command at once and starts with a power stroke
    (:func:`pectoral_gym.model.strokes.command_fins`): ``T_p / (zeta + 1)``, or longer if stretched to
    ``max_speed``, then at most ``pi (angle range) / (2 max_speed)``.
    """
    stretched = math.pi * (limits.angle_max - limits.angle_min) / (2.0 * limits.max_speed)
    return max(float((beats[:, 2] / (beats[:, 3] + 1.0)).max()), stretched)


class CommandedGain:
    """The fastest speed gain [m/s^2] the commanded fins allow over a span (module docstring).

    The fins are replayed from the commands at their send times (:class:`pectoral_gym.model.finreplay.FinReplay`,
    the firmware's rules); the robot takes each command up to a round trip later, so a span ``[t0, t1]`` is judged
    on the box of the patterns the replay latched from ``t0`` less the round trip on and of every command sent
    since: whatever the take times, each latched pattern lies between those (the rate rule moves a pattern
    towards the command it follows), and :func:`box_rate` covers their steady and transitional half-strokes.

    Args:
        params: Fish parameters (fin constants, masses).
        limits: The servo limits the firmware enforces.

    Attributes:
        full: The gain with nothing known of the fins (``SpeedBound.accel``'s impulse bound) [m/s^2].
    """

    def __init__(self, params: FishParams, limits: ServoLimits):
        self.params, self.limits = params, limits
        coef = body_coefficients(params)
        self.mass = min(coef.m1, coef.m2)
        self.full = fin_pair_force_bound(params, limits) / self.mass
        self._replay = FinReplay(params, FirmwareConfig(limits=limits))
        self._commands: collections.deque[tuple[float, np.ndarray, Callable[[], float | None] | None]] = \
            collections.deque(maxlen=64)  # (sent, clipped beats, acknowledged-at or None), newest last
        self._latched: collections.deque[tuple[float, np.ndarray]] = collections.deque(maxlen=256)
        self._still = math.inf  # nothing known until the first reset
        self._armed = math.inf
        self._since_arm: list[tuple[float, np.ndarray, Callable[[], float | None] | None]] = []  # for the take tree
        self._memo: dict = {}  # the take tree's latches, for the commands since the arm
        # Possible halts since the arm: [earliest time, index of the first command sent after it was told (None: none
        # yet)]; the supervisor tells one (still) before it sends its next command (module docstring).
        self._halts: list[list] = []

    def reset(self, t: float) -> None:
        """The fins are still at ``t`` [s] (an arm after a confirmed stop); commands before are forgotten."""
        self._commands.clear()
        self._latched.clear()
        self._replay.reset(float(t))
        self._still = self._armed = float(t)
        self._since_arm = []
        self._halts = []
        self._memo = {}

    def still(self, t: float) -> None:
        """The fins may have stopped at ``t`` [s] (a stop, a lease's end, a watchdog): the next latch is whole."""
        self._still = max(self._still, float(t)) if math.isfinite(self._still) else float(t)
        if float(t) > self._armed:  # (not before the first reset: the tree then claims nothing anyway)
            if self._halts and self._halts[-1][1] is None:
                self._halts[-1][0] = min(self._halts[-1][0], float(t))  # told again before a command: one halt
            else:
                self._halts.append([float(t), None])

    def command(self, t: float, beats: np.ndarray, acknowledged: Callable[[], float | None] | None = None) -> None:
        """A command ``(2, 4)`` sent at ``t`` [s]; ``acknowledged()``: when the robot had it [s] (``None``: not yet).

        Without ``acknowledged`` (a link that does not tell) the command counts as taken when sent.
        """
        if not math.isfinite(self._still):
            return  # never reset: accel() gives the full gain
        # What the robot runs: the pattern as quantised on the wire (a period a few ms shorter, a peak rate that much
        # higher), clipped again by the firmware.
        clipped = clip_beats(wire_beats(clip_beats(beats, self.limits)[0]), self.limits)[0]
        halted = bool(self._halts) and self._halts[-1][1] is None
        if len(self._since_arm) <= _MAX_TREE_COMMANDS and (halted or not self._since_arm
                                                           or not np.array_equal(self._since_arm[-1][1], clipped)):
            # (a renewal restarts halted fins: the tree keeps it after a possible halt)
            self._since_arm.append((float(t), clipped, acknowledged))
            if halted:
                self._halts[-1][1] = len(self._since_arm) - 1
        if self._commands and np.array_equal(self._commands[-1][1], clipped) and self._commands[-1][0] > self._still:
            return  # a renewal of the same command: nothing new can be latched
        self._run(t)
        self._replay.command(t, clipped)
        self._commands.append((float(t), clipped, acknowledged))

    def _run(self, to: float, step: float = 0.05) -> None:
        """Replay the fins to ``to`` [s], noting the latched patterns every ``step`` s (a half-stroke is longer)."""
        t = self._replay.model.time
        while t < to:
            t = min(to, t + step)
            self._replay.advance(t)
            fins = self._replay.fins[0]
            self._latched.append((t, fins[:, strokes.BIAS:strokes.RATIO + 1].copy()))

    def accel(self, t0: float, now: float, t1: float, round_trip: float) -> float:
        """The most the fish's speed can grow per second [m/s^2] anywhere in ``[t0, t1]`` [s], judged at ``now``.

        ``round_trip`` [s]: the most a command takes to reach the robot (the link's round trip). Each fin's force is
        the least of three bounds that each hold whatever the take times: the box's peak rate with its shortest
        half-stroke, :meth:`strokes`' (the tighter parts of the box and the take tree), and the largest force of the
        take tree's half-strokes, each at its own rate and duration.
        """
        box = self.box_strokes(t0, now, t1, round_trip)
        if box is None:
            return self.full  # nothing known of the fins
        tree = self._tree(t0, t1)
        total = 0.0
        for fin in range(2):
            force = fin_force_bound(self.params, self.limits, box[0][fin], box[1][fin], fin)
            if tree is not None:
                pairs = tree[fin]
                force = min(force, max((fin_force_bound(self.params, self.limits, w, d, fin) for w, d in pairs),
                                       default=0.0))
            total += force
        return total / self.mass

    def _tree(self, t0: float, t1: float) -> list[np.ndarray] | None:
        """The take tree's half-strokes in ``[t0, t1]`` (:func:`phase_strokes`), ``None`` where it claims nothing."""
        if len(self._since_arm) > _MAX_TREE_COMMANDS or len(self._halts) > _MAX_TREE_COMMANDS:
            return None
        return phase_strokes(self._since_arm, t0, t1, self.limits, [tuple(h) for h in self._halts], self._memo)

    def strokes(self, t0: float, now: float, t1: float, round_trip: float) -> tuple[np.ndarray, np.ndarray] | None:
        """``(2,)`` the highest peak rate [rad/s] and ``(2,)`` the shortest half-stroke [s] of the fins in ``[t0, t1]``.

        ``None``: nothing known (never reset). Fins that stay still (no command since the stop) give rate 0.
        Each part is the tighter of the box's (:meth:`box_strokes`) and the take-time tree's
        (:func:`pectoral_gym.hardware.safety.blind_phase.phase_strokes`, when it claims one: no halt possible since
        the arm, every command since known): both hold whatever the take times, so their tighter does too.
        """
        box = self.box_strokes(t0, now, t1, round_trip)
        tree = None if box is None else self._tree(t0, t1)
        if tree is None:
            return box
        rates = np.array([pairs[:, 0].max(initial=0.0) for pairs in tree])
        shortest = np.array([pairs[:, 1].min(initial=math.inf) for pairs in tree])
        return np.minimum(box[0], rates), np.maximum(box[1], shortest)

    def box_strokes(self, t0: float, now: float, t1: float,
                    round_trip: float) -> tuple[np.ndarray, np.ndarray] | None:
        """:meth:`strokes` from the box of patterns alone (module docstring)."""
        if not math.isfinite(self._still):
            return None
        since = [c for c in self._commands if self._still <= c[0] <= t1]
        if not since:
            return np.zeros(2), np.full(2, math.inf)
        first = since[0]
        ack = first[2]() if first[2] is not None else first[0]  # a link that does not tell: taken when sent
        arrival = now if ack is None else max(ack, first[0])
        self._run(now)
        if arrival + _first_power_stroke(first[1], self.limits) >= t0:
            # The first command after a stop is latched whole, from wherever the fin stopped: its first power stroke
            # from any angle of the servo range (of any command sent since: a lost one's successor may be the first
            # taken), then patterns in the box of the commands sent since (the rate rule moves each latched
            # pattern from one in the box towards a command, so never out of it).
            whole = np.stack([c[1] for c in since])
            first_rate, first_d = first_stroke(whole, self.limits)
            return np.maximum(box_rate(whole, self.limits), first_rate), np.minimum(box_half_stroke(whole), first_d)
        # A half-stroke in progress at t0 was latched up to its duration before, from a turning point of the pattern
        # run before it: the box reaches back by the longest half-stroke of a pattern in the box from t0 less a
        # round trip (without it, the robot's fins ran half-strokes faster and shorter than the box allowed:
        # tests/test_safety_blind.py).
        box = self._box(t0 - round_trip - 0.05, since)
        box = self._box(t0 - round_trip - 0.05 - float(longest_half_stroke(box).max()), since)
        return box_rate(box, self.limits), box_half_stroke(box)

    def _box(self, start: float, since: list) -> np.ndarray:
        """``(n, 2, 4)``: the replay's patterns from ``start`` [s] on, the commands since, the one followed then."""
        patterns = [p for t, p in self._latched if t >= start]
        patterns += [c[1] for c in since if c[0] >= start]
        older = [c for c in since if c[0] < start]
        if older:
            patterns.append(older[-1][1])  # the command the fins follow at the window's start
        return np.stack(patterns)


def ls_velocity(poses, noise: float) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """Least-squares velocity ``(vX, vY)`` [m/s] of ``(t, X, Y)`` poses and its standard errors, or ``None``.

    ``None`` with fewer than 3 poses or a span under 0.1 s. The standard error is the pose scatter over
    ``sqrt(sum (t - mean t)^2)``; the scatter is the residuals' (with at least 4 poses) but at least
    ``noise`` [m], the tracker's assumed position noise.
    """
    if len(poses) < _MIN_POSES:
        return None
    arr = np.asarray(poses, dtype=float)
    t = arr[:, 0] - arr[:, 0].mean()
    sxx = float(t @ t)
    if arr[-1, 0] - arr[0, 0] < _MIN_SPAN or sxx <= 0:
        return None
    xy = arr[:, 1:3] - arr[:, 1:3].mean(axis=0)
    slope = (t @ xy) / sxx
    resid = xy - np.outer(t, slope)
    scatter = np.sqrt((resid ** 2).sum(axis=0) / (len(arr) - 2)) if len(arr) > 3 else np.zeros(2)
    scatter = np.maximum(scatter, noise)
    err = scatter / math.sqrt(sxx)
    return (float(slope[0]), float(slope[1])), (float(err[0]), float(err[1]))


def unseen_reason(now: float, seen: float, last_read: float, read_since_sighting: bool, recent_reads: int,
                  frame_period: float, reaction_time: float, budget: str) -> str:
    """The blind rule's stop reason, saying what the camera did (times in experiment s).

    ``seen``: capture time of the last pose; ``last_read``: when the newest frame arrived; ``read_since_sighting``:
    whether frames arrived after that pose's; ``recent_reads``: frames that arrived in the last second. A gap
    longer than the reaction time is "no frames" (a run of dropped frames or a camera that stopped: the PC
    cannot tell which yet); a shorter one after a late frame says how late it came and how long nothing followed.
    """
    gap, old = now - last_read, now - seen
    counts = f"{recent_reads} frames arrived in the last second, one every {frame_period:.3f} s expected"
    if gap > reaction_time:
        return f"no frames from the camera for {gap:.2f} s ({gap / frame_period:.1f} frame periods; {counts}): " \
               f"the last pose is {old:.2f} s old, more than {budget}; the fastest motion the commanded fins allow " \
               "since could reach the stopping band"
    if not read_since_sighting:
        return f"camera frames arrive {last_read - seen:.2f} s after their capture and none came in the {gap:.2f} s " \
               f"since ({counts}): the last pose is {old:.2f} s old, more than {budget}; the fastest motion the " \
               "commanded fins allow since could reach the stopping band"
    return f"fish unseen for {old:.2f} s (more than {budget}; {counts}): the fastest motion the commanded fins " \
           "allow since could reach the stopping band"
