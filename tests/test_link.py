"""RadioLink: retries over loop://, loss/duplicate/reorder detection against a scripted robot, stop on close."""

import math
import socket
import time

import numpy as np
import pytest

from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.hardware.radio.link import RadioLink

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")  # no numba compile inside a timed loop

BEATS = np.array([[math.pi / 2, math.radians(20), 1.0, 3.0]] * 2)


def _wait(cond, timeout=2.0):
    deadline = time.monotonic() + timeout
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.01)
    return cond()


def test_retries_over_loop_then_gives_up():
    # loop:// echoes our own Transmit Requests: nobody acknowledges, so every retry is used.
    link = RadioLink("loop://", keepalive_period=60.0, ack_timeout=0.02, max_retries=3)
    try:
        link.set_fins(BEATS)
        assert _wait(lambda: link.stats.unacked == 1)
        assert (link.stats.retries, link.stats.sent, link.stats.received) == (3, 4, 0)
        assert link.decoder.messages == 4  # the echoes decode fine but are not STATUS messages
    finally:
        link.close(stop_wait=0.05)


def test_non_finite_command_is_rejected_before_sending():
    link = RadioLink("loop://", keepalive_period=60.0)
    try:
        with pytest.raises(ValueError, match="finite"):
            link.set_fins(np.full((2, 4), np.nan))
        time.sleep(0.05)
        assert link.stats.sent == 0 and link.command is None
    finally:
        link.close(stop_wait=0.01)


SESSION = 0x5E55
BOOT = 0xB007


def _status(seq, ack=0, state=pr.RobotState.RUNNING, session=SESSION):
    # A STATUS addressed to (and serving) the link's session (protocol v3).
    msg = pr.Message(pr.MsgType.STATUS, seq, session,
                     status=pr.Status(ack, 1, int(state), served=session, boot=BOOT))
    return xb.encode_frame(xb.rx_packet(pr.encode_message(msg)))


def test_loss_duplicates_reordering_and_corruption_are_counted():
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    link = RadioLink(f"socket://127.0.0.1:{port}", keepalive_period=60.0, session=SESSION)
    conn, _ = server.accept()
    try:
        bad_crc = bytearray(pr.encode_message(pr.Message(pr.MsgType.STATUS, 9, SESSION,
                                                         status=pr.Status(0, 1, 1, served=SESSION, boot=BOOT))))
        bad_crc[4] ^= 0x01  # seq byte damaged; XBee checksum recomputed below
        bad_checksum = bytearray(_status(10))
        bad_checksum[-1] ^= 0x01 if bad_checksum[-1] not in (0x7F, 0x7C) else 0x02
        # robot sequence: 1, 2, 2 (duplicate), 4 (3 lost), 3 (late), then damaged frames, then 5
        script = [_status(1), _status(2), _status(2), _status(4), _status(3),
                  xb.encode_frame(xb.rx_packet(bytes(bad_crc))), bytes(bad_checksum), b"noise", _status(5)]
        conn.sendall(b"".join(script))
        assert _wait(lambda: link.stats.received == 4)  # 1, 2, 4, 5
        s = link.stats
        assert (s.duplicates, s.stale, s.dropped, s.crc_errors, s.checksum_errors) == (1, 1, 1, 1, 1)
    finally:
        link.close(stop_wait=0.01)
        conn.close()
        server.close()


def test_acknowledged_at_is_the_arrival_of_the_first_status_answering_the_message_or_a_later_one():
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    link = RadioLink(f"socket://127.0.0.1:{port}", keepalive_period=60.0, session=SESSION)
    conn, _ = server.accept()
    try:
        seq = link.set_fins(BEATS)
        assert link.acknowledged_at(seq) is None
        conn.sendall(_status(1, ack=(seq - 1) & 0xFFFF))
        assert _wait(lambda: link.stats.received == 1)
        assert link.acknowledged_at(seq) is None  # an answer to an older message says nothing of this one
        before = time.monotonic()
        conn.sendall(_status(2, ack=(seq + 1) & 0xFFFF))  # a later message (a keep-alive copy) answered
        assert _wait(lambda: link.stats.received == 2)
        first = link.acknowledged_at(seq)
        assert first is not None and before <= first <= time.monotonic()
        conn.sendall(_status(3, ack=seq))  # its own answer, later still: the first one stands
        assert _wait(lambda: link.stats.received == 3)
        assert link.acknowledged_at(seq) == first
    finally:
        link.close(stop_wait=0.01)
        conn.close()
        server.close()


def test_acked_command_and_close_sends_stop_idempotently():
    with EmulatedRobot(speed=1.0) as robot:
        link = RadioLink(robot.url, keepalive_period=0.05, ack_timeout=0.05)
        seq = link.set_fins(BEATS)
        assert link.wait_ack(seq, 2.0)
        assert _wait(lambda: link.health()["robot_state"] == "RUNNING")
        link.close()
        link.close()  # harmless
        assert link.closed
        assert _wait(lambda: robot.firmware.state == pr.RobotState.STOPPED)
        assert any(m.type == pr.MsgType.STOP for m in robot.received)
        with pytest.raises(RuntimeError, match="closed"):
            link.set_fins(BEATS)


def test_keepalive_resends_the_current_command_at_a_fixed_rate():
    with EmulatedRobot(speed=1.0) as robot:
        link = RadioLink(robot.url, keepalive_period=0.05)
        try:
            link.set_fins(BEATS)
            time.sleep(0.5)
            n = sum(m.type == pr.MsgType.SET_FINS for m in robot.received)
            # 0.5 s at 20 Hz: ~10 keep-alives plus the command; a loaded machine may lose a few ticks
            assert 6 <= n <= 13
            assert robot.firmware.running  # fed well within the 0.5 s watchdog
        finally:
            link.close()
