"""What the conformance scenarios share: verdicts, tolerances, fin patterns and the checks they repeat.

**Tolerances, and why the radio's latency is not in them.** Every time a scenario judges is read on the
robot's own clock: a STATUS carries ``uptime_ms`` read when it is built (after the message it answers has
arrived), a LATCH the uptime of its turning point. A rule's moment is *bracketed* between the uptime of the
last answer that still showed the fins running and the first that showed them halted; the radio's delay and
jitter only widen or narrow how often the probe asks, never shift the bracket. What remains is the robot's
granularity: its rules run every firmware tick (:data:`TICK`, 10 ms, ``docs/protocol.md`` section 5: a halt
is due at the first tick at or after its moment), a receipt may be stamped up to a tick after the bytes came
in (a firmware that reads its UART at its tick), and uptimes are whole milliseconds (floored):
:data:`TOLERANCE_MS` = 2 ticks + 2 ms on either side. The radio's latency enters only how long the probe
waits for an answer (three times the slowest round trip measured at the start, plus 0.1 s) and the margin of
a deadline set ahead of the robot's clock (:data:`DEADLINE_AHEAD_MS` plus that round trip).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pectoral_gym.hardware.conformance.probe import Answer, Probe, Session
from pectoral_gym.hardware.radio import protocol as pr

__all__ = ["Broken", "Unchecked", "Result", "TICK", "TOLERANCE_MS", "DEADLINE_AHEAD_MS", "MOVING", "beats", "claim",
           "expect", "expect_state", "poll_until_halted", "bracket"]

TICK = 0.010  # the firmware's tick [s]: its rules (lease, watchdog, deadline) act at the first tick after their time
TOLERANCE_MS = 2 * 1000 * TICK + 2  # a tick late to act, a tick late to stamp a receipt, 2 ms of flooring
DEADLINE_AHEAD_MS = 400.0  # a deadline set this far ahead of the robot's estimated clock (plus the round trip)
POLL = 0.05  # the probe asks how the robot is this often while a rule's moment approaches [robot s]


class Broken(Exception):  # noqa: N818 (a verdict, raised as one)
    """A scenario found the robot breaking its rule (the message says how)."""


class Unchecked(Exception):  # noqa: N818 (a verdict, raised as one)
    """A scenario cannot run on this transport (the message says why)."""


@dataclass
class Result:
    """One rule's verdict: ``PASS``, ``FAIL`` or ``SKIP``, with the reason and the measured figures."""

    rule: str
    verdict: str
    reason: str
    details: dict = field(default_factory=dict)


def beats(*fins: tuple[float, float, float, float]) -> np.ndarray:
    """``(2, 4)`` patterns from ``(bias [deg], amplitude [deg], period [s], ratio)`` per fin (one: both fins)."""
    rows = [fins[0], fins[0]] if len(fins) == 1 else list(fins)
    return np.array([[math.radians(b), math.radians(a), p, r] for b, a, p, r in rows])


MOVING = beats((90.0, 20.0, 0.8, 1.0))  # a plain beat well inside the servo limits (0.4 s half-strokes)


def expect(answer: Answer | None, what: str) -> pr.Status:
    """The STATUS of ``answer``; :class:`Broken` naming ``what`` went unanswered if there is none."""
    if answer is None:
        raise Broken(f"no STATUS answered {what}")
    return answer.status


def expect_state(answer: Answer | None, what: str, *states: pr.RobotState) -> pr.Status:
    """The STATUS answering ``what``, which must report one of ``states`` (:class:`Broken` otherwise)."""
    status = expect(answer, what)
    if status.state not in [int(s) for s in states]:
        names = " or ".join(s.name for s in states)
        raise Broken(f"after {what} the robot reports {pr.state_name(status.state)}, expected {names}")
    return status


def claim(probe: Probe) -> tuple[Session, pr.Status]:
    """A fresh session that takes the robot over with CLAIM (a clean start for a scenario), fins halted."""
    session = probe.session()
    status = expect(session.send(session.message(pr.MsgType.CLAIM)), "a CLAIM")
    if status.served != session.id:
        raise Broken(f"a CLAIM from a fresh session left the robot serving {status.served:#010x}")
    if status.state == pr.RobotState.RUNNING:
        raise Broken("a CLAIM (a takeover) left the fins running")
    return session, status


def poll_until_halted(probe: Probe, session: Session, ask: Callable[[], object], limit: float, what: str,
                      start: pr.Status) -> list[tuple[int, int]]:
    """Ask (``ask()`` sends, never waits) every :data:`POLL` s until an answer shows the fins halted.

    Returns ``(uptime_ms, state)`` of ``start`` (the answer that started the fins) and of every answer addressed
    to ``session`` since, in uptime order. The asks do not wait for their answers: over a slow radio the
    answers come a round trip late but each carries the uptime it was built at, so the bracket stays as narrow
    as :data:`POLL`. :class:`Broken` if nothing answers, or the fins still run ``limit`` robot seconds on.
    """
    first = len(probe.answers)
    end = probe.now() + limit / probe.speed

    def seen() -> list[tuple[int, int]]:
        return [(a.status.uptime_ms, a.status.state) for a in probe.answers[first:]
                if a.msg.type == pr.MsgType.STATUS and a.msg.session == session.id]

    while not any(state != pr.RobotState.RUNNING for _, state in seen()):
        if probe.now() >= end:
            if not seen():
                raise Broken(f"no STATUS answered {what}")
            raise Broken(f"the fins still ran {limit:.1f} s after the start ({what} answered RUNNING)")
        ask()
        probe.wait(POLL)
    return sorted([(start.uptime_ms, start.state), *seen()])


def bracket(polls: list[tuple[int, int]], expected_ms: float, what: str) -> dict:
    """Check that the halt seen in ``polls`` is consistent with ``expected_ms`` on the robot's clock.

    The halt happened after the last RUNNING answer's uptime and no later than the first halted answer's:
    consistent if that interval meets ``expected_ms +- TOLERANCE_MS``. Returns the figures for the report.
    """
    running = [u for u, s in polls if s == pr.RobotState.RUNNING]
    halted = [u for u, s in polls if s != pr.RobotState.RUNNING]
    if not running or not halted:
        raise Broken(f"{what}: the polls never saw the fins running and then halted")
    last_running, first_halted = running[-1], halted[0]
    figures = {"expected_ms": round(expected_ms, 1), "last_running_ms": last_running, "first_halted_ms": first_halted,
               "tolerance_ms": TOLERANCE_MS}
    if first_halted < expected_ms - TOLERANCE_MS:
        raise Broken(f"{what}: halted by uptime {first_halted} ms, {expected_ms - first_halted:.0f} ms before "
                     f"its time {expected_ms:.0f} ms (tolerance {TOLERANCE_MS:.0f} ms)")
    if last_running > expected_ms + TOLERANCE_MS:
        raise Broken(f"{what}: still running at uptime {last_running} ms, {last_running - expected_ms:.0f} ms after "
                     f"its time {expected_ms:.0f} ms (tolerance {TOLERANCE_MS:.0f} ms)")
    return figures
