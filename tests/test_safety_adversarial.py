"""The first safety review, reproduced against the emulated robot and shown fixed: the fish stops whenever the
controller is not in control.

Times are measured on the emulator's own clock (its trace, one entry per 10 ms physics chunk) where the
rule is the robot's (leases); rules of the PC's supervisor thread get generous bounds. Long runs
(100 signal trials, big fuzz) are marked slow. Findings 5 and 6 (the servos' peak rates, the geofence at full
thrust): ``tests/test_safety_motion_limits.py``.
"""

import json
import math
import os
import random
import re
import signal
import socket
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from emulator_helpers import rig as _rig
from emulator_helpers import stopped_at as _stopped_at
from emulator_helpers import wait_for as _wait

from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.hardware.radio.link import RadioLink
from pectoral_gym.hardware.safety.rules import check_action
from pectoral_gym.hardware.vision.frames import Frame
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH, FishParams

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")  # no numba compile inside a timed loop

BEATS = np.array([[math.pi / 2, math.radians(20), 1.0, 3.0]] * 2)
FULL = np.array([0.0, 1.0, -1.0, 1.0] * 2, dtype=np.float32)  # bias 90 deg, largest amplitude, fastest beat
P = FishParams()


# ---------------------------------------------------------------- 1, 9: controller away, stalled, raising
@pytest.mark.parametrize("pause", [2.0, 8.0])
def test_pause_outside_step_stops_within_the_lease(pause):
    with _rig(speed=4.0, start=(1.85 - 0.099, 0.575, 0.0), tracking_timeout=1.5) as (robot, env):
        env.reset(seed=0)
        t_call = robot.now()
        env.step(FULL)
        time.sleep(pause / 4.0)  # the program is elsewhere (SB3 between rollouts, a breakpoint)
        fw = robot.firmware
        received = fw.lease_end - pr.DEFAULT_LEASE  # the robot's receipt of the last command from step()
        stopped = _stopped_at(robot, received)
        assert stopped is not None and fw.state != pr.RobotState.RUNNING
        assert stopped - received <= pr.DEFAULT_LEASE + 0.011  # exact on the emulated clock
        assert stopped - t_call <= 1.0
        nose = max(s[0] + 0.5 * P.body_length * math.cos(s[2]) for _, s, *_ in robot.trace)
        assert nose < TANK_LENGTH  # before the fix: 1.85 -> 3.45 m through the wall line at 2.30 m


def test_exception_out_of_step_stops_the_fins():
    with _rig(speed=4.0, tracking_timeout=1.5) as (robot, env):
        env.reset(seed=0)
        env.step(FULL)
        # A bug after the command went out: _observe runs at least once in every step, whatever the
        # camera delivered (patching the observer raised only when a frame happened to arrive).
        env._observe = lambda: (_ for _ in ()).throw(RuntimeError("a bug in the program"))
        with pytest.raises(RuntimeError, match="bug"):
            env.step(FULL)
        fw = robot.firmware
        received = fw.lease_end - pr.DEFAULT_LEASE
        assert _wait(lambda: not fw.running)
        time.sleep(0.1)
        assert _stopped_at(robot, received) - received <= pr.DEFAULT_LEASE + 0.011


def test_hung_process_with_a_live_keepalive_thread_stops_at_the_lease():
    with EmulatedRobot(speed=2.0) as robot:
        robot.trace = []
        link = RadioLink(robot.url, keepalive_period=0.02, ack_timeout=0.02)
        link.lease_scale = 100.0  # the PC's own lease bookkeeping disabled: copies forever, the robot's rule alone
        try:
            link.set_fins(BEATS, lease=0.8)
            time.sleep(1.0)  # 2 emulated s of keep-alive copies; the "controller" is hung
            copies = [m for m in robot.received if m.type == pr.MsgType.SET_FINS]
            assert len(copies) > 3 and len({m.command for m in copies}) == 1
            fw = robot.firmware
            assert fw.state == pr.RobotState.EXPIRED
            received = fw.lease_end - 0.8
            assert _stopped_at(robot, received) - received <= 0.8 + 0.011
        finally:
            link.close()


def test_stalled_link_thread_never_restarts_the_fins():
    # SIGSTOP in-process: the keep-alive thread is held (here: by its lock) past the lease, then resumes.
    with EmulatedRobot(speed=1.0) as robot:
        link = RadioLink(robot.url, keepalive_period=0.02, ack_timeout=0.02)
        try:
            assert link.wait_ack(link.set_fins(BEATS, lease=0.3), 2.0)
            with link._lock:
                assert _wait(lambda: robot.firmware.state == pr.RobotState.WATCHDOG or
                             robot.firmware.state == pr.RobotState.EXPIRED)
                n = len(robot.received)
            time.sleep(0.2)  # resumed: the thread must send STOP / HEARTBEAT, never the old command
            later = robot.received[n:]
            assert later and all(m.type != pr.MsgType.SET_FINS for m in later)
            assert not robot.firmware.running
        finally:
            link.close()


# ---------------------------------------------------------------- 2, 3: camera lies
class _LyingCamera:
    """An emulated camera that, once ``mode`` is set, stamps or repeats frames wrongly."""

    def __init__(self, robot):
        self.inner, self.mode, self.last = robot.camera(seed=1), None, None

    def read(self):
        if self.mode == "dead":
            return None
        if self.mode == "frozen" and self.last is not None:
            return Frame(self.last.image, time.monotonic())  # the old image, fresh stamps
        frame = self.inner.read()
        if frame is None:
            return None
        stamp = {None: frame.timestamp, "future": frame.timestamp + 100.0, "nan": math.nan, "inf": math.inf,
                 "backwards": frame.timestamp - 5.0}.get(self.mode, frame.timestamp)
        self.last = frame
        return Frame(frame.image, stamp)

    def close(self):
        self.inner.close()


@pytest.mark.parametrize(("mode", "reason"), [("future", "timestamp_future"), ("nan", "bad_timestamp"),
                                              ("inf", "bad_timestamp"), ("backwards", "timestamp_backwards"),
                                              ("frozen", "frozen_frame"), ("dead", "no frames from the camera")])
def test_camera_lies_stop_the_fish_with_the_reason(mode, reason):
    with _rig(speed=1.0, camera=_LyingCamera) as (robot, env):
        env.reset(seed=0)
        env.step(np.zeros(8, dtype=np.float32))
        t_bad = robot.now()
        env.camera.mode = mode
        for _ in range(6):
            _, _, _, truncated, info = env.step(np.zeros(8, dtype=np.float32))
            if truncated:
                break
        assert truncated and info["safety_stop"] == "tracking_lost"
        # A dead camera says for how long: the blind rule's "no frames from the camera for ..." (with counts) or,
        # with fins too gentle for it, the tracking timeout's with the frame grabber's "no frame from the camera ...".
        assert re.match(reason.replace("no frames", "no frames?"), info["tracking"]["reason"])
        stopped = _stopped_at(robot, t_bad)
        assert stopped is not None and stopped - t_bad <= 1.0  # timeout 0.5 s + polling + radio


# ---------------------------------------------------------------- 4: replays, duplicates, other sessions
def _frame(msg):
    return xb.encode_frame(xb.tx_request(pr.encode_message(msg)))


def _set(seq, session, command, lease=0.8):
    return _frame(pr.Message(pr.MsgType.SET_FINS, seq, session, fins=tuple(BEATS.ravel()), command=command,
                             lease=lease))


def test_replays_and_other_sessions_never_keep_or_restart_motion():
    with EmulatedRobot(speed=2.0) as robot:
        a = socket.create_connection((robot.host, robot.port))
        b = socket.create_connection((robot.host, robot.port))  # a second client: it must not drop the first
        fw = robot.firmware
        try:
            captured = _set(1, 0xA, command=1)
            for _ in range(15):  # 1.5 emulated s of one captured frame replayed every 0.1 s
                a.sendall(captured)
                time.sleep(0.05)
            # Replays feed neither the lease nor the watchdog: stopped 0.5 s after the first copy.
            assert fw.state == pr.RobotState.WATCHDOG and fw.ignored["duplicate"] >= 10
            assert fw.tripped_at - fw.last_valid <= 0.5 + 0.011
            a.sendall(_set(2, 0xA, command=2))  # the PC commands again ...
            assert _wait(lambda: fw.running)
            # ... another live session speaks up: refused (safety review, finding 2), the fins keep their controller
            b.sendall(_frame(pr.Message(pr.MsgType.HEARTBEAT, 1, 0xB)))
            assert _wait(lambda: fw.ignored["refused"] >= 1)
            assert fw.running and fw.session == 0xA
            b.sendall(_frame(pr.Message(pr.MsgType.CLAIM, 2, 0xB)))  # ... and takes over explicitly
            assert _wait(lambda: fw.state == pr.RobotState.STOPPED and fw.session == 0xB)
            for seq in range(3, 8):  # the old session's commands, new or replayed: all ignored
                a.sendall(_set(seq, 0xA, command=seq))
                a.sendall(captured)
            time.sleep(0.1)
            assert fw.state == pr.RobotState.STOPPED and fw.ignored["retired"] >= 10
        finally:
            a.close()
            b.close()


# ---------------------------------------------------------------- 7, 8, 10: signals, sessions, small ones
def test_signal_while_the_link_lock_is_held_still_sends_stop(default_signal_handlers):
    with _rig(speed=2.0, tracking_timeout=1.5) as (robot, env):
        env.reset(seed=0)
        env.step(FULL)
        with pytest.raises(KeyboardInterrupt):
            with env.link._lock, env.link._write_lock:  # the main thread is inside a write
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.5)  # the handler runs here; with a lock in it this would hang forever
        assert _wait(lambda: robot.firmware.state == pr.RobotState.STOPPED)
        assert env.supervisor.reason == "stop" or _wait(lambda: env.supervisor.reason == "stop")


def test_session_does_not_come_from_the_seeded_generator():
    random.seed(0)
    np.random.seed(0)
    a = RadioLink("loop://", keepalive_period=60.0)
    random.seed(0)
    np.random.seed(0)
    b = RadioLink("loop://", keepalive_period=60.0)
    try:
        assert a.session != b.session and 0 <= a.session < 2**32
    finally:
        a.close(stop_wait=0.01)
        b.close(stop_wait=0.01)


def test_unknown_robot_state_and_complex_actions():
    server = socket.create_server(("127.0.0.1", 0))
    link = RadioLink(f"socket://127.0.0.1:{server.getsockname()[1]}", keepalive_period=60.0)
    conn, _ = server.accept()
    try:
        status = pr.Message(pr.MsgType.STATUS, 1, link.session, status=pr.Status(0, 1, 7, served=link.session, boot=1))
        conn.sendall(xb.encode_frame(xb.rx_packet(pr.encode_message(status))))
        assert _wait(lambda: link.stats.received == 1)
        assert link.health()["robot_state"] == "UNKNOWN_7"
    finally:
        link.close(stop_wait=0.01)
        conn.close()
        server.close()
    with pytest.raises(ValueError, match="8 numbers"):
        check_action(np.full(8, 0.5 + 0.5j))


_SCRIPT = textwrap.dedent("""
    import sys, time
    import numpy as np
    from pectoral_gym.hardware.env import HardwareFishEnv
    from pectoral_gym.hardware.safety.rules import SafetyConfig
    env = HardwareFishEnv(sys.argv[1], sys.argv[2], safety=SafetyConfig(tracking_timeout=2.0, link_timeout=3.0))
    env.reset(seed=0)
    print("ready", flush=True)
    while True:
        env.step(np.array([0.0, 1.0, -1.0, 1.0] * 2, dtype=np.float32))
        if sys.argv[3] == "exit":
            sys.exit(0)  # no close(): the env's atexit hook must send STOP
""")


def _script_trial(robot, how, delay, python=sys.executable):
    before = sum(m.type == pr.MsgType.STOP for m in robot.received)
    env_vars = {**os.environ, "PYTHONPATH": os.getcwd()}
    robot.place(TANK_LENGTH / 2, TANK_WIDTH / 2, 0.0)
    proc = subprocess.Popen([python, "-c", _SCRIPT, robot.url, robot.camera_spec, str(how)], stdout=subprocess.PIPE,
                            env=env_vars, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        if how != "exit":
            _wait(lambda: robot.firmware.running, timeout=10.0)
            time.sleep(delay)
            proc.send_signal(how)
        code = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    stops = [m for m in robot.received if m.type == pr.MsgType.STOP][before:]
    return code, stops


def test_script_using_the_env_directly_sends_stop_on_exit_and_on_sigterm():
    with EmulatedRobot(speed=1.0, camera_port=0) as robot:
        code, stops = _script_trial(robot, "exit", 0.0)
        assert code == 0 and stops
        code, stops = _script_trial(robot, signal.SIGTERM, 0.3)
        assert code == 128 + signal.SIGTERM and stops
        assert _wait(lambda: not robot.firmware.running)


@pytest.mark.slow
def test_hundred_timed_signal_trials_every_stop_arrives():
    rng = np.random.default_rng(13)
    with EmulatedRobot(speed=1.0, camera_port=0) as robot:
        results = []
        for k in range(100):
            sig = signal.SIGINT if k % 2 else signal.SIGTERM
            code, stops = _script_trial(robot, sig, float(rng.uniform(0.0, 1.0)))
            results.append((code, len(stops)))
        assert all(n > 0 for _, n in results)  # STOP reached the robot every time
        assert all(code in (1, 128 + signal.SIGTERM, -signal.SIGINT, 130) for code, _ in results), results


@pytest.mark.slow
def test_fuzz_random_streams_and_bit_flips():
    rng = np.random.default_rng(5)
    dec = pr.StreamDecoder()
    for _ in range(20_000):  # random streams: no crash, nothing accepted that we did not send
        out = dec.feed(rng.integers(0, 256, int(rng.integers(1, 200)), dtype=np.uint8).tobytes())
        for msg in out:
            pr.encode_message(msg)  # whatever survives is well-formed
    sent = pr.Message(pr.MsgType.SET_FINS, 7, 0xDEAD, fins=tuple(BEATS.ravel()), command=3, lease=0.5)
    frame = bytearray(_frame(sent))
    expected = pr.decode_message(pr.encode_message(sent))  # the wire rounds the fins to mrad / ms
    accepted_bad = delivered = 0
    for _ in range(20_000):
        bad = bytearray(frame)
        bit = int(rng.integers(8, 8 * len(bad)))
        bad[bit // 8] ^= 1 << (bit % 8)
        dec = pr.StreamDecoder()
        for msg in dec.feed(bytes(bad) + bytes(frame)):
            accepted_bad += msg != expected
            delivered += msg == expected
    assert accepted_bad == 0 and delivered >= 20_000  # the good frame after the damaged one always gets through


def test_fish_moved_by_the_reset_hook_is_not_read_as_a_speed_towards_a_wall(tmp_path):
    # pectoral_gym.hardware.deploy --emulate puts the fish at a random start in its reset hook: the poses from before
    # the move, still in the supervisor's velocity window, made the jump read as ~1 m/s and tripped the geofence
    # on the first step of every episode, far from any wall (fins at rest, 0.36 m of clearance).
    from pectoral_gym.hardware.deploy import main as deploy

    assert deploy(["--controller", "hand", "--emulate", "--episodes", "2", "--max-episode-steps", "2", "--speed", "2",
                   "--no-prompt", "--no-progress", "--out", str(tmp_path)]) == 0
    episodes = json.loads((tmp_path / "summary.json").read_text())["episodes"]
    assert [e["safety_stop"] for e in episodes] == ["", ""] and [e["steps"] for e in episodes] == [2, 2]
