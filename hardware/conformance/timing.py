"""Scenarios of the rules that end a command in time: lease, deadline, watchdog, copies, boot id.

Each takes a :class:`~pectoral_gym.hardware.conformance.probe.Probe`, starts from a fresh session that CLAIMs the
robot, and returns the figures it measured, or raises
:class:`~pectoral_gym.hardware.conformance.judge.Broken` / :class:`~pectoral_gym.hardware.conformance.judge.Unchecked`.
Times are judged on the robot's clock (:mod:`pectoral_gym.hardware.conformance.judge`).
"""

from __future__ import annotations

from pectoral_gym.hardware.conformance.judge import (
    DEADLINE_AHEAD_MS,
    MOVING,
    TOLERANCE_MS,
    Broken,
    Unchecked,
    beats,
    bracket,
    claim,
    expect,
    expect_state,
    poll_until_halted,
)
from pectoral_gym.hardware.conformance.probe import Probe, Session
from pectoral_gym.hardware.radio import protocol as pr

__all__ = ["lease", "deadline", "watchdog", "copies", "deadline_never_starts", "reboot"]

S = pr.RobotState
_HALTED = (S.STOPPED, S.WATCHDOG, S.EXPIRED, S.IDLE)


def _ahead_ms(probe: Probe) -> int:
    """A robot uptime [ms] :data:`DEADLINE_AHEAD_MS` after the robot's receipt of a message sent now.

    The estimate of the robot's clock lags it by the newest STATUS's return trip, and the message takes its
    outward trip: one slowest round trip covers both.
    """
    return int(probe.robot_uptime_ms() + DEADLINE_AHEAD_MS + 1000.0 * probe.rtt_max)


def _heartbeat(session: Session):
    """An ask for :func:`poll_until_halted`: a new HEARTBEAT (it feeds the watchdog, never the lease)."""
    return lambda: session.post(session.message(pr.MsgType.HEARTBEAT))


def lease(probe: Probe) -> dict:
    """A SET_FINS runs until its lease, counted from its receipt, then EXPIRED; silence does not change that."""
    session, _ = claim(probe)
    start = expect_state(session.send(session.set_fins(MOVING, lease=0.4)), "a SET_FINS (lease 0.4 s)", S.RUNNING)
    polls = poll_until_halted(probe, session, _heartbeat(session), 1.5, "a HEARTBEAT", start)
    if polls[-1][1] != S.EXPIRED:
        raise Broken(f"a lease of 0.4 s ended in {pr.state_name(polls[-1][1])}, expected EXPIRED")
    figures = bracket(polls, start.uptime_ms + 400.0, "the 0.4 s lease")
    # Silence: a lease shorter than the watchdog ends the fins EXPIRED, and no latch follows its end.
    quiet = expect_state(session.send(session.set_fins(MOVING, lease=0.3)), "a SET_FINS (lease 0.3 s)", S.RUNNING)
    probe.wait(0.8)
    after = expect(session.heartbeat(), "a HEARTBEAT after 0.8 s of silence")
    if after.state != S.EXPIRED:
        raise Broken(f"0.8 s after a SET_FINS with a 0.3 s lease and silence the robot reports "
                     f"{pr.state_name(after.state)}, expected EXPIRED (the lease ends before the watchdog)")
    late = [m.latch.uptime_ms for m in probe.latches(quiet.uptime_ms + 300 + int(TOLERANCE_MS) + 1, quiet.boot)]
    if late:
        raise Broken(f"a fin latched at uptime {late[0]} ms, after the 0.3 s lease ended ({quiet.uptime_ms + 300} ms)")
    return {**figures, "silent_lease_state": pr.state_name(after.state)}


def deadline(probe: Probe) -> dict:
    """A deadline before the lease's end stops the fins at the deadline (EXPIRED)."""
    session, status = claim(probe)
    due = _ahead_ms(probe)
    start = expect_state(session.send(session.set_fins(MOVING, lease=1.0, deadline=due, boot=status.boot)),
                         "a SET_FINS with a deadline", S.RUNNING)
    if not 100 <= due - start.uptime_ms <= 1000 - 100:
        raise Broken(f"the deadline fell {due - start.uptime_ms} ms after the receipt, not inside the lease's 1 s "
                     "with 0.1 s to spare: the radio's round trip is too uneven for this scenario")
    polls = poll_until_halted(probe, session, _heartbeat(session), 1.5, "a HEARTBEAT", start)
    if polls[-1][1] != S.EXPIRED:
        raise Broken(f"the deadline ended the command in {pr.state_name(polls[-1][1])}, expected EXPIRED")
    figures = bracket(polls, float(due), "the deadline")
    return {**figures, "deadline_before_lease_end_ms": start.uptime_ms + 1000 - due}


def watchdog(probe: Probe) -> dict:
    """No new valid message for 0.5 s (duplicates do not count) -> WATCHDOG; only a new command restarts."""
    session, _ = claim(probe)
    start = expect_state(session.send(session.set_fins(MOVING, lease=1.0)), "a SET_FINS (lease 1 s)", S.RUNNING)
    # Asking by duplicates of that SET_FINS: answered, but no liveness (protocol section 3).
    polls = poll_until_halted(probe, session, lambda: probe.exchange(session.last, expect=False), 1.5,
                              "a duplicate SET_FINS", start)
    if polls[-1][1] != S.WATCHDOG:
        raise Broken(f"silence (duplicates only) for {(polls[-1][0] - start.uptime_ms) / 1000:.2f} s ended in "
                     f"{pr.state_name(polls[-1][1])}, expected WATCHDOG at 0.5 s")
    figures = bracket(polls, start.uptime_ms + 500.0, "the 0.5 s watchdog")
    after = expect(session.heartbeat(), "a HEARTBEAT after the watchdog")
    if after.state == S.RUNNING:
        raise Broken("a HEARTBEAT restarted the fins after the watchdog (only a new SET_FINS command may)")
    expect_state(session.send(session.set_fins(MOVING, lease=0.2)), "a new SET_FINS after the watchdog", S.RUNNING)
    return figures


def copies(probe: Probe) -> dict:
    """A copy (same command identity) neither extends the lease, nor changes the pattern, nor restarts."""
    session, _ = claim(probe)
    first = session.post(session.set_fins(MOVING, lease=0.4))
    probe.wait(0.15)  # not waiting for the answer: over a slow radio the lease would end before the copy came
    other = beats((60.0, 30.0, 1.2, 2.0))
    copy = expect(session.send(session.set_fins(other, lease=1.0, command=first.command)),
                  "a copy with another pattern and a 1 s lease")
    start = expect_state(probe.answer_to(first), "a SET_FINS (lease 0.4 s)", S.RUNNING)
    if copy.state != S.RUNNING or copy.uptime_ms - start.uptime_ms >= 400:
        raise Broken(f"the copy, {copy.uptime_ms - start.uptime_ms} ms after the first, found the robot "
                     f"{pr.state_name(copy.state)}: expected RUNNING within the first's 0.4 s lease")
    polls = poll_until_halted(probe, session, _heartbeat(session), 1.5, "a HEARTBEAT", copy)
    figures = bracket(polls, start.uptime_ms + 400.0, "the first copy's 0.4 s lease (a copy must not extend it)")
    for msg in probe.latches(start.uptime_ms, start.boot):
        bias, amplitude, _, ratio = msg.latch.beat
        want = MOVING[msg.latch.fin]
        if abs(bias - want[0]) > 0.002 or abs(amplitude - want[1]) > 0.002 or abs(ratio - want[3]) > 0.002:
            raise Broken(f"fin {msg.latch.fin} latched bias {bias:.3f} rad, amplitude {amplitude:.3f} rad, ratio "
                         f"{ratio:.3f}: the copy's pattern, not the command's")
    for command, what in ((first.command, "a copy after the lease ended"),
                          ((first.command - 1) & 0xFFFF, "an older command")):
        status = expect(session.send(session.set_fins(MOVING, lease=1.0, command=command)), what)
        if status.state == S.RUNNING:
            raise Broken(f"{what} restarted the fins")
    return figures


def deadline_never_starts(probe: Probe) -> dict:
    """A deadline already past, or one for another boot, never starts the fins; a past one stops running fins."""
    session, status = claim(probe)
    boot = status.boot
    past = int(probe.robot_uptime_ms() - 200.0)
    if past <= 0:
        probe.wait(0.3)
        past = int(probe.robot_uptime_ms() - 200.0)
    other_boot = (boot ^ 0x5A5A5A5A) or 1
    cases = ((lambda: session.set_fins(MOVING, deadline=past, boot=boot), "a SET_FINS whose deadline is past"),
             (lambda: session.set_fins(MOVING, deadline=_ahead_ms(probe), boot=other_boot),
              "a SET_FINS with a deadline for another boot"))
    for make, what in cases:
        answer = expect(session.send(make()), what)
        probe.wait(0.1)
        later = expect(session.heartbeat(), f"a HEARTBEAT after {what}")
        if S.RUNNING in (answer.state, later.state):
            raise Broken(f"{what} started the fins")
    expect_state(session.send(session.set_fins(MOVING, deadline=_ahead_ms(probe) + 300, boot=boot)),
                 "a SET_FINS with a deadline ahead (the control case)", S.RUNNING)
    stop = expect(session.send(session.set_fins(MOVING, deadline=int(probe.robot_uptime_ms() - 200.0), boot=boot)),
                  "a newer SET_FINS whose deadline is past, while running")
    if stop.state != S.EXPIRED:
        raise Broken(f"a newer command with a past deadline left the robot {pr.state_name(stop.state)}, "
                     "expected EXPIRED (it stops the running one)")
    return {"boot": f"{boot:#010x}"}


def reboot(probe: Probe) -> dict:
    """Boot id nonzero and steady within a boot, new after a power-up, uptime from 0; old-boot deadlines refused."""
    boots = {a.status.boot for a in probe.statuses()}
    if 0 in boots:
        raise Broken("a STATUS carried boot id 0 (it must be nonzero)")
    if len(boots) > 1:
        raise Broken(f"the boot id changed without a power-up: {sorted(f'{b:#010x}' for b in boots)}")
    if probe.reboot_robot is None:
        raise Unchecked(f"boot id {next(iter(boots), 0):#010x} steady over {len(probe.statuses())} STATUS; a reboot "
                        "needs a power cycle this transport cannot make (run with --emulate)")
    session, status = claim(probe)
    expect_state(session.send(session.set_fins(MOVING, lease=1.0)), "a SET_FINS", S.RUNNING)
    old_boot, rebooted = status.boot, probe.now()
    probe.reboot_robot()
    fresh = expect(session.heartbeat(), "a HEARTBEAT after the power-up")
    since_ms = 1000.0 * (probe.now() - rebooted) * probe.speed
    if fresh.boot in (0, old_boot):
        raise Broken(f"after a power-up the boot id is {fresh.boot:#010x} (before {old_boot:#010x}): it must be new "
                     "and nonzero")
    if fresh.uptime_ms > since_ms + TOLERANCE_MS:
        raise Broken(f"uptime {fresh.uptime_ms} ms {since_ms:.0f} ms after a power-up: it must count from it")
    if fresh.state != S.IDLE or fresh.served != session.id:
        raise Broken(f"after a power-up the first message found {pr.state_name(fresh.state)}, serving "
                     f"{fresh.served:#010x}: expected IDLE, and an unserved robot taken by the message")
    stale = expect(session.send(session.set_fins(MOVING, deadline=fresh.uptime_ms + 600, boot=old_boot)),
                   "a SET_FINS with the old boot's id")
    if stale.state == S.RUNNING:
        raise Broken("a command carrying the previous boot's id started the fins")
    return {"old_boot": f"{old_boot:#010x}", "new_boot": f"{fresh.boot:#010x}", "uptime_after_ms": fresh.uptime_ms}
