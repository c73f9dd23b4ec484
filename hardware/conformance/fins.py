"""Scenarios judged from the fins' LATCH reports: clipping, the rate rule at the latch, latches at turning points.

With the fins free (no camera), what the fins did is what the robot reports: every LATCH carries the uptime of
a turning point, the fin, the pattern latched there (as the fin runs it, the transition's stretch included),
the angle and the kind of the half-stroke that starts (``docs/protocol.md`` section 2). Consecutive reports of
a fin are compared only where the LATCH numbering shows none lost between them (a lossy radio).

Quantisation: the wire carries mrad, ms and 1/1000, so pattern values are compared within :data:`_Q` (two
quanta) and times within :data:`_LATCH_MS` (a tick, where a firmware's fins turn on its tick, plus 2 ms of
flooring).
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.hardware.conformance.judge import MOVING, TICK, Broken, beats, claim, expect, expect_state
from pectoral_gym.hardware.conformance.probe import Probe, Session
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.model.servo import ServoLimits

__all__ = ["clipping", "rate_at_latch", "turning_points"]

S = pr.RobotState
_Q = 0.002  # two wire quanta: 2 mrad, 2 ms, 0.002 of ratio
_LATCH_MS = 1000 * TICK + 2
_QUIET_MS = 400  # commands received further apart than this: the watchdog (500 ms) may have halted the fins
_SPEED_SLACK = 1.01  # peak rates from quantised patterns: 1 % above max_speed is rounding, not a breach
LIMITS = ServoLimits()  # the protocol's default servo limits (section 5, "Clipping")

SLOW = beats((90.0, 15.0, 0.4, 1.0))  # 0.2 s half-strokes: the rate rule then lets through 36 deg of bias
FAR = beats((130.0, 30.0, 1.6, 3.5), (50.0, 35.0, 1.2, 0.5))  # beyond one half-stroke's reach in every value


def _run(probe: Probe, session: Session, fins: np.ndarray, seconds: float) -> list[pr.Message]:
    """Run ``fins`` for ``seconds`` as a controller does: a new command every 0.25 s (lease 1 s), not waiting.

    Returns the commands sent; :func:`_answers` collects their answers afterwards (waiting for them between
    runs would let the watchdog halt the fins over a slow radio).
    """
    sent = []
    end = probe.now() + seconds / probe.speed
    while probe.now() < end:
        sent.append(session.post(session.set_fins(fins, lease=1.0)))
        probe.wait(min(0.25, (end - probe.now()) * probe.speed))
    return sent


def _answers(probe: Probe, sent: list[pr.Message]) -> list[pr.Status]:
    """The STATUS answering ``sent`` (a lossy radio may lose some); every one must report the fins RUNNING."""
    answers = [a for a in (probe.answer_to(msg) for msg in sent) if a is not None]
    if not answers:
        raise Broken(f"none of {len(sent)} SET_FINS was answered")
    return [expect_state(a, "a SET_FINS", S.RUNNING) for a in answers]


def _pairs(latches: list[pr.Message], quiet: list[tuple[int, int]]) -> list[tuple[pr.Latch, pr.Latch]]:
    """Consecutive reports of each fin with no LATCH lost between them (their numbering without a gap).

    A pair across a ``quiet`` interval ``(from_ms, to_ms)`` is left out: the fins may have halted there (the
    watchdog, when the probe's commands stalled or were lost) and restarted from rest, legitimately anywhere.
    """
    pairs: list[tuple[pr.Latch, pr.Latch]] = []
    last: dict[int, int] = {}
    for i, msg in enumerate(latches):
        j = last.get(msg.latch.fin)
        if j is not None and all((latches[k + 1].seq - latches[k].seq) & 0xFFFF == 1 for k in range(j, i)):
            prev, cur = latches[j].latch, msg.latch
            if not any(prev.uptime_ms < end and start < cur.uptime_ms for start, end in quiet):
                pairs.append((prev, cur))
        last[msg.latch.fin] = i
    return pairs


def _quiet(statuses: list[pr.Status]) -> list[tuple[int, int]]:
    """Intervals [ms of uptime] between commands the robot received more than :data:`_QUIET_MS` apart."""
    times = sorted(s.uptime_ms for s in statuses)
    return [(a, b) for a, b in zip(times, times[1:], strict=False) if b - a > _QUIET_MS]


def _duration(latch: pr.Latch) -> float:
    """Duration [s] of the half-stroke a report starts: ``T / (zeta + 1)`` power, ``zeta T / (zeta + 1)`` recovery."""
    _, _, period, ratio = latch.beat
    return (1.0 if latch.power else ratio) * period / (ratio + 1.0)  # eq. (21)


def _slew(probe: Probe) -> dict:
    """One run for both latch rules (cached on the probe): :data:`SLOW`, then :data:`FAR` for 4 s."""
    if "slew" in probe.cache:
        return probe.cache["slew"]
    session, status = claim(probe)
    slow = _run(probe, session, SLOW, 1.2)
    far = _run(probe, session, FAR, 4.0)
    expect(session.send(session.message(pr.MsgType.STOP)), "a STOP")
    statuses = _answers(probe, far)
    quiet = _quiet(_answers(probe, slow) + statuses)
    run = {"latches": probe.latches(status.uptime_ms, status.boot), "statuses": statuses, "quiet": quiet}
    probe.cache["slew"] = run
    return run


def rate_at_latch(probe: Probe) -> dict:
    """A moving fin's latched pattern moves at most ``max_rate`` x the half-stroke it ends; the command is reached."""
    run = _slew(probe)
    pairs = _pairs(run["latches"], run["quiet"])
    if len(pairs) < 6:
        raise Broken(f"only {len(pairs)} consecutive LATCH pairs reported in 5 s of beating (expected >= 6)")
    rate = np.asarray(LIMITS.max_rate)
    held, worst = 0, 0.0
    for prev, cur in pairs:
        d = _duration(prev)
        change = np.subtract(cur.beat, prev.beat)
        reach = rate * d + _Q
        for k, name in ((0, "bias"), (1, "amplitude"), (3, "ratio")):
            if abs(change[k]) > reach[k]:
                raise Broken(f"fin {cur.fin} at uptime {cur.uptime_ms} ms: {name} moved {change[k]:+.3f} after a "
                             f"{d:.3f} s half-stroke, more than max_rate x duration = {reach[k] - _Q:.3f}")
            worst = max(worst, abs(change[k]) / (reach[k] - _Q))
        if -change[2] > reach[2]:  # the period may grow beyond the rate (clipping, the transition's stretch)
            raise Broken(f"fin {cur.fin} at uptime {cur.uptime_ms} ms: period fell {-change[2]:.3f} s after a "
                         f"{d:.3f} s half-stroke, more than 4 s/s x duration")
        held += bool(np.any(np.abs(np.subtract(cur.beat, FAR[cur.fin])[[0, 1, 3]]) > _Q))
    for fin in (0, 1):
        last = [m.latch for m in run["latches"] if m.latch.fin == fin][-1]
        if np.any(np.abs(np.subtract(last.beat, FAR[fin])[[0, 1, 3]]) > _Q):
            raise Broken(f"fin {fin} never latched the command: its last report runs {np.round(last.beat, 3)}")
    flagged = [bool(s.flags & pr.StatusFlag.RATE_LIMITED) for s in run["statuses"]]
    if not any(flagged):
        raise Broken("no STATUS set the RATE_LIMITED flag while the rate rule held the fins back")
    if flagged[-1]:
        raise Broken("the RATE_LIMITED flag stayed set after both fins latched the command")
    return {"pairs": len(pairs), "held_back": held, "largest_change_of_reach": round(worst, 3),
            "quiet_intervals": len(run["quiet"])}


def turning_points(probe: Probe) -> dict:
    """Fins latch only at turning points: a half-stroke duration after the last latch, at its end angle."""
    run = _slew(probe)
    pairs = _pairs(run["latches"], run["quiet"])
    if len(pairs) < 6:
        raise Broken(f"only {len(pairs)} consecutive LATCH pairs reported in 5 s of beating (expected >= 6)")
    worst_ms = worst_mrad = 0.0
    for prev, cur in pairs:
        gap_ms, due_ms = cur.uptime_ms - prev.uptime_ms, 1000.0 * _duration(prev)
        bias, amplitude = prev.beat[0], prev.beat[1]
        end = bias + amplitude if prev.power else bias - amplitude
        if abs(gap_ms - due_ms) > _LATCH_MS:
            raise Broken(f"fin {cur.fin} latched at uptime {cur.uptime_ms} ms, {gap_ms} ms after its previous latch; "
                         f"the half-stroke lasts {due_ms:.0f} ms (mid-stroke?)")
        if abs(cur.turn - end) > _Q or cur.power == prev.power:
            raise Broken(f"fin {cur.fin} latched at {math.degrees(cur.turn):.1f} deg (power {cur.power}) at "
                         f"uptime {cur.uptime_ms} ms; its half-stroke ends at {math.degrees(end):.1f} deg: not a "
                         "turning point")
        worst_ms, worst_mrad = max(worst_ms, abs(gap_ms - due_ms)), max(worst_mrad, 1000 * abs(cur.turn - end))
    return {"pairs": len(pairs), "largest_time_error_ms": round(worst_ms, 1),
            "largest_angle_error_mrad": round(worst_mrad, 1)}


def _peak(latch: pr.Latch) -> tuple[float, float, float]:
    """Peak fin rates [rad/s]: power and recovery half-strokes of the pattern, and the half-stroke this one starts."""
    bias, amplitude, period, ratio = latch.beat
    power = math.pi * amplitude * (ratio + 1.0) / period  # eq. (21), section 5 "Clipping"
    end = bias + amplitude if latch.power else bias - amplitude
    return power, power / ratio, math.pi * abs(end - latch.turn) / (2.0 * max(_duration(latch), 1e-9))


def clipping(probe: Probe) -> dict:
    """A command outside the servo limits is clipped (STATUS CLIPPED) and every latched pattern is within them."""
    session, status = claim(probe)
    over = beats((175.0, 30.0, 0.2, 8.0), (90.0, 20.0, 0.8, 1.0))
    first = expect_state(session.send(session.set_fins(over, lease=1.0)), "an out-of-limits SET_FINS", S.RUNNING)
    if not first.flags & pr.StatusFlag.CLIPPED:
        raise Broken("the STATUS answering an out-of-limits SET_FINS does not set CLIPPED")
    _answers(probe, _run(probe, session, over, 2.4))
    inside = expect(session.send(session.set_fins(MOVING, lease=0.2)), "a SET_FINS within limits")
    if inside.flags & pr.StatusFlag.CLIPPED:
        raise Broken("the STATUS answering a SET_FINS within the limits sets CLIPPED")
    latches = [m.latch for m in probe.latches(status.uptime_ms, status.boot)]
    if sum(lt.fin == 0 for lt in latches) < 3:
        raise Broken(f"only {sum(lt.fin == 0 for lt in latches)} LATCH reports of the clipped fin in 2.4 s")
    lo, hi = LIMITS.angle_min - _Q, LIMITS.angle_max + _Q
    for lt in latches:
        bias, amplitude, period, ratio = lt.beat
        where = f"fin {lt.fin} at uptime {lt.uptime_ms} ms latched {np.round(lt.beat, 3)}"
        if bias - amplitude < lo or bias + amplitude > hi:
            raise Broken(f"{where}: its stroke leaves [{math.degrees(LIMITS.angle_min):.0f}, "
                         f"{math.degrees(LIMITS.angle_max):.0f}] deg")
        if not LIMITS.period_min - _Q <= period <= LIMITS.period_max + _Q:
            raise Broken(f"{where}: period outside [{LIMITS.period_min}, {LIMITS.period_max}] s")
        if not LIMITS.ratio_min - _Q <= ratio <= LIMITS.ratio_max + _Q:
            raise Broken(f"{where}: ratio outside [{LIMITS.ratio_min}, {LIMITS.ratio_max}]")
        peaks = _peak(lt)
        if max(peaks) > LIMITS.max_speed * _SPEED_SLACK:
            raise Broken(f"{where}: a half-stroke peaks at {max(peaks):.2f} rad/s > {LIMITS.max_speed:.1f} rad/s")
    return {"latches": len(latches), "fastest_rad_s": round(max(max(_peak(lt)) for lt in latches), 2)}
