"""Scenarios of the rules about who may command the robot, and which messages count.

STOP from a retired or an unknown session, CLAIM, refusal, stale and duplicate sequence numbers, the CRC-16
check (``docs/protocol.md`` sections 2, 3 and 5). Same conventions as
:mod:`pectoral_gym.hardware.conformance.timing`.
"""

from __future__ import annotations

from pectoral_gym.hardware.conformance.judge import MOVING, Broken, claim, expect, expect_state
from pectoral_gym.hardware.conformance.probe import Probe, Session, with_seq
from pectoral_gym.hardware.radio import protocol as pr

__all__ = ["stop_retired", "stop_unknown", "claim_takes_over", "refused", "stale_duplicate", "crc"]

S = pr.RobotState


def _served(status: pr.Status, session: int, what: str) -> None:
    if status.served != session:
        raise Broken(f"after {what} the robot serves {status.served:#010x}, expected {session:#010x}")


def _live(owner: Session) -> None:
    """A HEARTBEAT from the served session, not waited for, just before another session's message.

    Over a slow radio the round trips a scenario waits for would otherwise let the served session fall silent
    for the watchdog's 0.5 s, and a silent session may be taken over by anyone (a different rule).
    """
    owner.post(owner.message(pr.MsgType.HEARTBEAT))


def stop_retired(probe: Probe) -> dict:
    """A STOP from a retired session halts the fins (a stop never needs authority), and takes no control."""
    old, _ = claim(probe)
    expect_state(old.send(old.set_fins(MOVING)), "a SET_FINS", S.RUNNING)
    new, _ = claim(probe)  # retires the old session
    expect_state(new.send(new.set_fins(MOVING)), "the new session's SET_FINS", S.RUNNING)
    answer = old.send(old.message(pr.MsgType.STOP))
    status = expect(answer, "a STOP from the retired session")
    if answer.msg.session != old.id:
        raise Broken(f"the STATUS answering the retired session's STOP is addressed to {answer.msg.session:#010x}")
    if status.state != S.STOPPED:
        raise Broken(f"a STOP from a retired session left the robot {pr.state_name(status.state)}, expected STOPPED")
    _served(status, new.id, "a STOP from the retired session")
    expect_state(new.heartbeat(), "the serving session's HEARTBEAT after that STOP", S.STOPPED)
    return {}


def stop_unknown(probe: Probe) -> dict:
    """A STOP from a session never seen halts the fins, is answered, and takes no control."""
    owner, _ = claim(probe)
    expect_state(owner.send(owner.set_fins(MOVING)), "a SET_FINS", S.RUNNING)
    stranger = probe.session()
    _live(owner)
    answer = stranger.send(stranger.message(pr.MsgType.STOP))
    status = expect(answer, "a STOP from an unknown session")
    if answer.msg.session != stranger.id:
        raise Broken("the STATUS answering an unknown session's STOP is not addressed to it")
    if status.state != S.STOPPED:
        raise Broken(f"a STOP from an unknown session left the robot {pr.state_name(status.state)}, expected STOPPED")
    _served(status, owner.id, "a STOP from an unknown session")
    _served(expect_state(owner.heartbeat(), "the owner's HEARTBEAT", S.STOPPED), owner.id, "the owner's HEARTBEAT")
    expect_state(owner.send(owner.set_fins(MOVING)), "the owner's next SET_FINS", S.RUNNING)
    return {}


def claim_takes_over(probe: Probe) -> dict:
    """CLAIM takes a live robot over, halts its fins and retires the old session for good."""
    old, _ = claim(probe)
    expect_state(old.send(old.set_fins(MOVING)), "a SET_FINS", S.RUNNING)
    new = probe.session()
    answer = new.send(new.message(pr.MsgType.CLAIM))
    status = expect(answer, "a CLAIM from another session")
    if answer.msg.session != new.id:
        raise Broken("the STATUS answering a CLAIM is not addressed to the claiming session")
    _served(status, new.id, "a CLAIM")
    if status.state == S.RUNNING:
        raise Broken("a CLAIM left the fins of the old session running (a takeover halts them)")
    for send, what in ((old.heartbeat, "the retired session's HEARTBEAT"),
                       (lambda: old.send(old.message(pr.MsgType.CLAIM)), "the retired session's CLAIM")):
        _served(expect(send(), what), new.id, what)
    probe.wait(0.7)  # the serving session falls silent: a silent session may be taken over, but not by the retired
    _served(expect(old.heartbeat(), "the retired session's HEARTBEAT after 0.7 s of silence"), new.id,
            "the retired session's HEARTBEAT after 0.7 s of silence")
    third = probe.session()
    _served(expect(third.heartbeat(), "a fresh session's HEARTBEAT"), third.id,
            "a fresh session's HEARTBEAT while the served one has been silent 0.7 s")
    return {}


def refused(probe: Probe) -> dict:
    """Another session's messages, while the served one is live, are refused but answered, naming the served one."""
    owner, _ = claim(probe)
    expect_state(owner.send(owner.set_fins(MOVING)), "a SET_FINS", S.RUNNING)
    expect_state(owner.send(owner.message(pr.MsgType.STOP)), "a STOP", S.STOPPED)
    other = probe.session()
    for send, what in ((other.heartbeat, "another session's HEARTBEAT"),
                       (lambda: other.send(other.set_fins(MOVING)), "another session's SET_FINS")):
        _live(owner)
        answer = send()
        status = expect(answer, f"{what} (a refused message must be answered)")
        if answer.msg.session != other.id:
            raise Broken(f"the STATUS answering {what} is not addressed to it")
        _served(status, owner.id, what)
        if status.state == S.RUNNING:
            raise Broken(f"{what} was acted on: the fins run")
    _served(expect_state(owner.heartbeat(), "the owner's HEARTBEAT", S.STOPPED), owner.id, "the refusals")
    return {}


def stale_duplicate(probe: Probe) -> dict:
    """A duplicate is acknowledged and nothing else; a stale number is ignored, unanswered, and counted."""
    session, _ = claim(probe)
    first = expect(session.heartbeat(), "a HEARTBEAT")
    resent = probe.resent
    again = expect(session.repeat(), "a duplicate HEARTBEAT")
    if again.duplicates != first.duplicates + 1 + (probe.resent - resent):
        raise Broken(f"a duplicate moved the STATUS duplicates count from {first.duplicates} to {again.duplicates}")
    fins = session.post(session.set_fins(MOVING))  # not waited for: the session stays live for the STOP below
    stranger = probe.session()  # stops the fins without touching this session's numbering
    expect_state(stranger.send(stranger.message(pr.MsgType.STOP)), "an unknown session's STOP", S.STOPPED)
    expect_state(probe.answer_to(fins), "a SET_FINS", S.RUNNING)
    dup = expect(session.repeat(), "a duplicate of the SET_FINS after a STOP")
    if dup.state != S.STOPPED:
        raise Broken(f"a duplicate SET_FINS after a STOP left the robot {pr.state_name(dup.state)}: it was re-applied")
    stale = with_seq(session.set_fins(MOVING), session.seq - 3)  # a newer command under an old number
    if not probe.silent_after(stale):
        raise Broken("a message with a stale sequence number was answered")
    after = expect_state(session.heartbeat(), "a HEARTBEAT after the stale SET_FINS", S.STOPPED)
    if after.stale != first.stale + 1:
        raise Broken(f"a stale message moved the STATUS stale count from {first.stale} to {after.stale}")
    return {"duplicates": after.duplicates, "stale": after.stale}


def crc(probe: Probe) -> dict:
    """A frame whose CRC-16 is wrong under a good XBee checksum is dropped unanswered and counted in crc_errors."""
    session, _ = claim(probe)
    before = expect(session.heartbeat(), "a HEARTBEAT")
    if not probe.silent_after(session.set_fins(MOVING), corrupt_crc=True):
        raise Broken("a SET_FINS whose CRC-16 is wrong was answered (so acted on)")
    after = expect(session.heartbeat(), "a HEARTBEAT after the bad frame")
    if after.state == S.RUNNING:
        raise Broken("a SET_FINS whose CRC-16 is wrong started the fins")
    if after.crc_errors != before.crc_errors + 1:
        raise Broken(f"one bad CRC-16 moved the STATUS crc_errors from {before.crc_errors} to {after.crc_errors}")
    return {"crc_errors": after.crc_errors}
