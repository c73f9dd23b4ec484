"""Firmware rules (pure state machine) and the emulated robot (watchdog, transports, CLI)."""

import math
import socket
import time

import numpy as np
import pytest

from pectoral_gym.hardware.emulator import ROBOT_ADDRESS, EmulatedRobot, main
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.hardware.radio.firmware import Firmware
from pectoral_gym.hardware.radio.link import RadioLink
from pectoral_gym.model.finrules import FirmwareConfig, slew_at_latch
from pectoral_gym.model.servo import ServoLimits, clip_beats, peak_rates

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")  # no numba compile inside a timed loop

BEATS = np.array([[math.pi / 2, math.radians(20), 1.0, 3.0]] * 2)


def _set(seq, beats=BEATS, session=0, command=None, lease=1.0):
    return pr.Message(pr.MsgType.SET_FINS, seq, session, fins=tuple(np.ravel(beats)),
                      command=seq if command is None else command, lease=lease)


def test_watchdog_halts_after_timeout_only():
    fw = Firmware(FirmwareConfig(watchdog_timeout=0.5))
    assert fw.receive(_set(1, lease=1.0), 0.0).status.ack_seq == 1
    fw.tick(0.0)
    fw.tick(0.45)
    assert fw.running and not fw.halt
    fw.receive(pr.Message(pr.MsgType.HEARTBEAT, 2), 0.45)  # a new heartbeat feeds the watchdog (not the lease)
    fw.tick(0.9)
    assert fw.running
    fw.tick(0.96)  # 0.51 s after the last valid message, lease still running until 1.0
    assert fw.state == pr.RobotState.WATCHDOG and fw.halt and fw.tripped_at == 0.96


def test_lease_runs_from_first_copy_and_copies_never_extend_or_restart():
    fw = Firmware()
    fw.receive(_set(1, command=7, lease=0.8), 0.0)
    for k in range(2, 9):  # keep-alive copies every 0.1 s: new seq, same command identity
        fw.receive(_set(k, command=7, lease=0.8), 0.1 * (k - 1))
        fw.tick(0.1 * (k - 1))
    assert fw.running
    fw.tick(0.8)  # 0.8 s after the first copy, whatever the copies said
    assert fw.state == pr.RobotState.EXPIRED and fw.halt and fw.tripped_at == 0.8
    fw.halt = False
    fw.receive(_set(9, command=7, lease=0.8), 0.85)  # one more copy: no restart
    fw.receive(_set(10, command=6, lease=0.8), 0.86)  # an older command: no restart
    assert fw.state == pr.RobotState.EXPIRED and fw.ignored["copy"] == 9
    fw.receive(_set(11, command=8, lease=0.8), 0.9)  # a new command from step()
    assert fw.running and fw.lease_end == pytest.approx(1.7)


def test_lease_is_capped_and_zero_lease_ignored():
    fw = Firmware(FirmwareConfig(max_lease=0.6))
    fw.receive(_set(1, lease=0.9), 0.0)
    assert fw.state == pr.RobotState.IDLE and fw.ignored["bad_lease"] == 1
    fw.receive(_set(2, lease=0.5), 0.0)
    assert fw.running


def test_replays_and_duplicates_keep_nothing_alive():
    fw = Firmware()
    fw.receive(_set(1, session=11, lease=1.0), 0.0)
    for k in range(1, 20):  # one captured frame replayed every 0.05 s
        fw.receive(_set(1, session=11, lease=1.0), 0.05 * k)
        fw.tick(0.05 * k)
    assert fw.state == pr.RobotState.WATCHDOG and fw.tripped_at == pytest.approx(0.55)
    assert fw.ignored["duplicate"] == 19


def test_another_live_sessions_messages_are_refused_and_answered_but_its_stop_halts():
    fw = Firmware(boot=77)
    fw.receive(_set(1, session=11, lease=1.0), 0.0)
    reply = fw.receive(pr.Message(pr.MsgType.HEARTBEAT, 1, session=12), 0.1)  # a second client joins
    assert fw.running and fw.session == 11 and fw.ignored["refused"] == 1  # no silent takeover
    assert (reply.session, reply.status.served, reply.status.boot) == (12, 11, 77)  # it learns at once
    assert fw.receive(_set(2, session=12, command=5), 0.2).status.served == 11
    assert fw.running and np.allclose(fw.command, BEATS, atol=1e-3)
    fw.receive(pr.Message(pr.MsgType.STOP, 2, session=12), 0.3)  # a stop never needs authority
    assert fw.state == pr.RobotState.STOPPED and fw.halt and fw.session == 11
    fw.receive(_set(2, session=11, lease=1.0), 0.35)  # the served session goes on
    assert fw.running


def test_new_session_takes_over_only_from_a_silent_session_or_by_claim():
    fw = Firmware(FirmwareConfig(watchdog_timeout=0.5))
    fw.receive(_set(1, session=1), 0.0)
    fw.receive(pr.Message(pr.MsgType.HEARTBEAT, 1, session=2), 0.49)  # session 1 still live
    assert fw.session == 1
    fw.tick(0.5)
    fw.receive(pr.Message(pr.MsgType.HEARTBEAT, 2, session=2), 0.5)  # silent for the watchdog time: gone
    assert fw.session == 2 and fw.retired == [1]
    assert fw.receive(_set(2, session=1, command=99), 0.6).status.served == 2  # retired: answered, ignored
    assert fw.state != pr.RobotState.RUNNING and fw.ignored["retired"] == 1
    fw.receive(_set(3, session=2), 0.7)
    assert fw.running
    fw.receive(pr.Message(pr.MsgType.CLAIM, 1, session=3), 0.8)  # the operator's explicit takeover
    assert fw.session == 3 and fw.state == pr.RobotState.STOPPED and fw.halt  # the new PC commands anew
    assert fw.receive(pr.Message(pr.MsgType.CLAIM, 4, session=1), 0.9).status.served == 3  # never a retired one


def test_deadline_bounds_the_run_and_a_late_or_foreign_deadline_never_starts():
    fw = Firmware(boot=5, power_up=10.0)
    fw.receive(pr.Message(pr.MsgType.SET_FINS, 1, 0, fins=tuple(BEATS.ravel()), command=1, lease=0.8,
                          deadline=1300, boot=5), 11.0)  # uptime 1000 ms: the deadline is 0.3 s away
    assert fw.running and fw.lease_end == pytest.approx(11.3)
    fw.tick(11.3)
    assert fw.state == pr.RobotState.EXPIRED
    late = pr.Message(pr.MsgType.SET_FINS, 2, 0, fins=tuple(BEATS.ravel()), command=2, lease=0.8, deadline=1400,
                      boot=5)
    fw.receive(late, 11.45)  # a copy that arrives after its deadline: never starts
    assert fw.state == pr.RobotState.EXPIRED and fw.ignored["late"] == 1
    other = pr.Message(pr.MsgType.SET_FINS, 3, 0, fins=tuple(BEATS.ravel()), command=3, lease=0.8, deadline=9000,
                       boot=6)
    fw.receive(other, 11.5)  # a deadline on another boot's clock
    assert fw.state == pr.RobotState.EXPIRED and fw.ignored["boot"] == 1
    status = fw.receive(pr.Message(pr.MsgType.HEARTBEAT, 4), 11.75).status
    assert (status.uptime_ms, status.boot) == (1750, 5)  # robot clock since power-up, rounded down


def test_heartbeat_does_not_restart_but_new_command_does():
    fw = Firmware()
    fw.receive(_set(1), 0.0)
    fw.tick(0.0)
    fw.tick(0.6)
    assert fw.state == pr.RobotState.WATCHDOG
    fw.halt = False
    fw.receive(pr.Message(pr.MsgType.HEARTBEAT, 2), 0.7)
    assert fw.state == pr.RobotState.WATCHDOG
    fw.receive(_set(3), 0.8)
    assert fw.running


def test_watchdog_timeout_is_at_most_one_second():
    with pytest.raises(ValueError, match="watchdog"):
        FirmwareConfig(watchdog_timeout=1.5)
    assert FirmwareConfig().watchdog_timeout == 0.5


def test_stop_halts_at_once_and_acks():
    fw = Firmware()
    fw.receive(_set(1), 0.0)
    reply = fw.receive(pr.Message(pr.MsgType.STOP, 2), 0.1)
    assert fw.state == pr.RobotState.STOPPED and fw.halt
    assert reply.status.ack_seq == 2 and reply.status.state == pr.RobotState.STOPPED


def test_duplicates_acked_not_applied_stale_ignored():
    fw = Firmware()
    fw.receive(_set(5), 0.0)
    other = BEATS.copy()
    other[:, 0] = 1.0
    dup = fw.receive(_set(5, other), 0.1)  # same seq: a retry whose first copy arrived
    assert dup.status.ack_seq == 5 and np.allclose(fw.command, BEATS, atol=1e-3)
    assert fw.receive(_set(4, other, command=9), 0.2) is None  # older: ignored, no reply
    assert np.allclose(fw.command, BEATS, atol=1e-3)
    assert (fw.tracker.duplicates, fw.tracker.stale) == (1, 1)


def test_clipping_to_servo_limits_by_hand():
    lim = ServoLimits(angle_min=math.radians(10), angle_max=math.radians(170), period_min=0.4, period_max=4.0,
                      ratio_min=0.5, ratio_max=6.0, max_speed=13.0)
    beats = np.array([[math.radians(5), math.radians(30), 0.4, 5.0],     # bias too low; too fast
                      [math.radians(90), math.radians(100), 10.0, 9.0]])  # amplitude, period, ratio too big
    out, changed = clip_beats(beats, lim)
    assert changed
    assert out[0, 0] == pytest.approx(math.radians(40))  # bias - amplitude = 10 deg
    # peak power-stroke rate pi A (zeta + 1) / T = pi * 0.5236 * 6 / 0.4 = 24.7 rad/s > 13: T = pi * 0.5236 * 6 / 13
    assert out[0, 2] == pytest.approx(math.pi * math.radians(30) * 6 / 13.0)
    assert out[1, 1] == pytest.approx(math.radians(80)) and out[1, 0] == pytest.approx(math.radians(90))
    assert out[1, 2] == 4.0 and out[1, 3] == 6.0
    assert clip_beats(BEATS, lim)[1] is False  # peak pi * 0.349 * 4 / 1 = 4.4 rad/s: unchanged
    slow_recovery = np.array([[math.radians(90), math.radians(40), 0.4, 0.5]] * 2)
    # ratio 0.5: the recovery stroke is the faster one, peak pi A (zeta + 1) / (zeta T) = 16.45 rad/s
    assert clip_beats(slow_recovery, lim)[0][0, 2] == pytest.approx(math.pi * math.radians(40) * 1.5 / (0.5 * 13))


def test_the_setpoint_is_the_command_at_the_next_tick():
    fw = Firmware(FirmwareConfig(limits=ServoLimits(max_rate=(math.radians(180), 1.0, 4.0, 10.0))))
    target = np.array([[math.radians(135), math.radians(20), 1.0, 3.0]] * 2)
    fw.receive(_set(1, target), 0.0)
    fw.tick(0.01)
    # the rate rule acts where a fin latches (slew_at_latch), not on the setpoint: no slewing between ticks
    np.testing.assert_array_equal(fw.setpoint, fw.command)


def test_rate_limiting_at_the_latch():
    limits = ServoLimits(max_rate=(math.radians(180), 1.0, 4.0, 10.0))
    ran = np.array([[math.radians(90), 0.0, 1.0, 1.0]] * 2)
    command = np.array([[math.radians(135), math.radians(20), 1.0, 3.0]] * 2)
    out = slew_at_latch(command, ran, np.array([0.1, 0.1]), np.array([False, True]), limits)
    # moving fin, a 0.1 s half-stroke ends: bias 90 -> 108 deg (180 deg/s), amplitude 0 -> 0.1 rad (1 rad/s),
    # ratio 1 -> 2 (10 /s); period unchanged
    np.testing.assert_allclose(out[0], [math.radians(108), 0.1, 1.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(out[1], command[1], atol=1e-12)  # a still fin latches the command
    # a half-stroke long enough for every parameter: the command itself
    np.testing.assert_allclose(slew_at_latch(command, ran, np.array([0.5, 0.5]), np.array([False, False]), limits),
                               command, atol=1e-12)
    # a pattern part-way may outrun the servo where the amplitude grows faster than the period shrinks: clipped
    limits, rng, outran = ServoLimits(), np.random.default_rng(0), 0
    for _ in range(5000):
        ran, command = (clip_beats(b, limits)[0] for b in rng.uniform([0.8, 0, 0.4, 0.5], [2.3, 0.7, 4, 6], (2, 2, 4)))
        duration = rng.uniform(0.05, 1.0, 2)
        step = np.asarray(limits.max_rate) * duration[:, None]
        outran += bool(np.any(peak_rates(ran + np.clip(command - ran, -step, step)) > limits.max_speed))
        out = slew_at_latch(command, ran, duration, np.array([False, False]), limits)
        assert np.all(peak_rates(out) <= limits.max_speed * (1 + 1e-9))
    assert outran > 0  # the clip had something to do


def _raw_send(sock, msg):
    sock.sendall(xb.encode_frame(xb.tx_request(pr.encode_message(msg))))


def test_emulator_watchdog_stops_fins_in_time():
    speed = 2.0
    with EmulatedRobot(speed=speed) as robot:
        sock = socket.create_connection((robot.host, robot.port))
        try:
            for seq in range(1, 6):  # 5 commands, 0.05 s (wall) apart, then silence
                _raw_send(sock, _set(seq))
                time.sleep(0.05)
            assert np.any(robot.fin_rates() != 0.0)  # beating (exactly 0 only when held)
            deadline = time.monotonic() + 3.0
            while robot.firmware.state != pr.RobotState.WATCHDOG and time.monotonic() < deadline:
                time.sleep(0.01)
            time.sleep(0.05)
            fw = robot.firmware
            assert fw.state == pr.RobotState.WATCHDOG
            assert 0.5 <= fw.tripped_at - fw.last_valid <= 0.5 + 0.1  # emulated seconds
            assert np.all(robot.fin_rates() == 0.0)  # the fins hold still at once
            assert len(robot.received) == 5
        finally:
            sock.close()


def test_emulator_swims_forward_and_reports_status_over_a_pty():
    with EmulatedRobot(pty=True, speed=4.0, start_pose=(1.0, 0.5, 0.0)) as robot:
        link = RadioLink(robot.url, keepalive_period=0.025, ack_timeout=0.02, dest64=ROBOT_ADDRESS)
        try:
            link.lease_scale = 1 / 4.0
            seq = link.set_fins(BEATS)
            assert link.wait_ack(seq, 2.0)
            for _ in range(6):  # 2.4 emulated seconds of symmetric rowing, a new command every 0.4 s
                time.sleep(0.1)
                link.set_fins(BEATS)
            x, y, psi = robot.pose()
            assert x > 1.01 and abs(y - 0.5) < 1e-3 and abs(psi) < 1e-3  # straight ahead, symmetric fins
            assert link.health()["robot_state"] == "RUNNING"
        finally:
            link.close()
        time.sleep(0.05)
        assert robot.firmware.state == pr.RobotState.STOPPED


def test_emulator_loss_injection_and_cli(capsys):
    with EmulatedRobot(speed=1.0, loss=0.5, seed=3) as robot:
        # Half the frames lost each way: a round trip succeeds 1 time in 4, so 40 tries leave a command
        # unacknowledged with probability 0.75^40 ~ 1e-5, whatever the machine's load does to the timing.
        link = RadioLink(robot.url, keepalive_period=1.0, ack_timeout=0.03, max_retries=40)
        try:
            acked = [link.wait_ack(link.set_fins(BEATS), 10.0) for _ in range(6)]
            assert all(acked)
            assert robot.lost_messages > 0 and link.stats.retries > 0
        finally:
            link.close()
    assert main(["--port", "0", "--duration", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "listening on socket://127.0.0.1:" in out and "stopped at X=1.150 m" in out
