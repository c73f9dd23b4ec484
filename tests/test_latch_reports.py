"""The robot's latch reports (LATCH, docs/protocol.md): wire format, firmware, PC side, run log, replay.

Through the whole robot env: ``tests/test_latch_reports_robot_env.py``.
"""

import io
import json
import math
import re

import numpy as np
import pytest

from pectoral_gym.agents.controllers.turning import SPIN_CYCLE
from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.hardware.radio.firmware import Firmware
from pectoral_gym.hardware.radio.link import RadioLink
from pectoral_gym.model import strokes
from pectoral_gym.model.finrules import CHUNK, FirmwareConfig
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.spec import FULL_REFERENCE
from pectoral_gym.runlog import RunLogError, RunLogWriter, dumps_example, read_run_log
from pectoral_gym.scaling.calibration.replay import replay_fins, simulate

LATCH = pr.Latch(uptime_ms=123456, boot=0xCAFE01, fin=1, power=False, turn=1.9,
                 beat=(1.5708, 0.5236, 1.25, 2.5))


def _frame(msg: pr.Message) -> bytes:
    return xb.encode_frame(xb.rx_packet(pr.encode_message(msg), 0x0013A20000000001))


# ------------------------------------------------------------------ wire format
def test_latch_round_trips_quantised_with_its_crc():
    msg = pr.Message(pr.MsgType.LATCH, 7, 0xDEADBEEF, latch=LATCH)
    raw = pr.encode_message(msg)
    assert len(raw) == 8 + 20 + 2  # header, body, CRC
    assert int.from_bytes(raw[-2:], "big") == pr.crc16(raw[:-2])
    back = pr.decode_message(raw)
    assert (back.type, back.seq, back.session) == (pr.MsgType.LATCH, 7, 0xDEADBEEF)
    assert back.latch == pr.Latch(123456, 0xCAFE01, 1, False, 1.9, (1.571, 0.524, 1.25, 2.5))  # mrad, ms, 1/1000
    for i in range(len(raw) - 2):  # every corrupted byte is caught
        bad = bytearray(raw)
        bad[i] ^= 0x10
        with pytest.raises(xb.ProtocolError):
            pr.decode_message(bytes(bad))
    assert pr.StreamDecoder().feed(b"\x00garbage" + _frame(msg))[0].latch == back.latch


def test_latch_of_a_third_fin_or_an_impossible_angle_is_refused():
    raw = bytearray(pr.encode_message(pr.Message(pr.MsgType.LATCH, 1, 1, latch=LATCH)))
    raw[8 + 8] = 2  # fin byte
    raw[-2:] = pr.crc16(bytes(raw[:-2])).to_bytes(2, "big")
    with pytest.raises(xb.ProtocolError, match="field"):
        pr.decode_message(bytes(raw))
    with pytest.raises(ValueError, match="turn"):
        pr.encode_message(pr.Message(pr.MsgType.LATCH, 1, 1, latch=pr.Latch(0, 1, 0, True, -0.1, LATCH.beat)))


def test_the_robot_ignores_latch_messages_even_of_another_session():
    fw = Firmware(boot=5)
    fw.receive(pr.Message(pr.MsgType.HEARTBEAT, 1, session=11), 0.0)
    assert fw.receive(pr.Message(pr.MsgType.LATCH, 1, session=22, latch=LATCH), 2.0) is None
    assert fw.session == 11 and fw.ignored["refused"] == 0  # no takeover, not even counted as a refusal


# ------------------------------------------------------------------ firmware
def test_firmware_reports_while_running_numbered_on_their_own():
    fw = Firmware(boot=9, power_up=0.5)
    assert fw.latch_report(1.0, 0, np.array([1.5, 0.3, 1.0, 2.0]), 1.2, True) is None  # idle: nothing to report
    beats = tuple(float(v) for v in np.tile([1.5708, 0.3491, 1.0, 1.0], 2))
    status = fw.receive(pr.Message(pr.MsgType.SET_FINS, 1, 77, fins=beats, command=1), 0.6)
    report = fw.latch_report(1.2345, 1, np.array([1.5708, 0.0314, 1.0, 1.0]), math.pi / 2, True)
    assert report.type == pr.MsgType.LATCH and report.session == 77 and report.seq == 1
    assert report.latch.uptime_ms == 734  # floor(1000 * (1.2345 - 0.5))
    assert report.latch.boot == 9 and report.latch.fin == 1 and report.latch.power
    assert fw.latch_report(1.3, 0, np.array([1.5708, 0.0314, 1.0, 1.0]), 1.6, False).seq == 2
    assert fw.receive(pr.Message(pr.MsgType.HEARTBEAT, 2, 77), 0.7).seq == status.seq + 1  # STATUS keep theirs


# ------------------------------------------------------------------ the emulator, driven by hand
class _Sink:
    """The robot's end of the radio in a single-threaded test: what it writes is kept."""

    is_open = True

    def __init__(self):
        self.data = b""

    def write(self, raw: bytes) -> None:
        self.data += raw

    def close(self) -> None:
        pass


class _HandDriven:
    """An :class:`EmulatedRobot` driven in this thread: messages arrive at chosen robot times, no radio, no threads."""

    def __init__(self, params: FishParams | None = None):
        self.sink = _Sink()
        self.robot = EmulatedRobot(params=params, seed=0, stream=self.sink, start_pose=(1.15, 0.575, 0.0))
        self.robot.trace = []
        self.t = 0.0
        self.robot.now = lambda: self.t
        self.seq = 0

    def send(self, t: float, msg_type: pr.MsgType, **fields) -> None:
        """The robot hears a message at robot time ``t``."""
        self.robot._advance(t)
        self.t = t
        self.seq += 1
        self.robot._handle(xb.encode_frame(xb.tx_request(pr.encode_message(
            pr.Message(msg_type, self.seq, 0xABCD, **fields)), 0)))

    def run_to(self, t: float) -> None:
        self.robot._advance(t)
        self.t = t

    def reports(self) -> list[pr.Latch]:
        return [m.latch for m in pr.StreamDecoder().feed(self.sink.data) if m.type == pr.MsgType.LATCH]


def test_emulator_reports_the_latch_the_firmware_rules_give_by_hand():
    # From rest at 90 deg, (90 deg, 20 deg, 1 s, 1) heard at 0.105 s, between two 10 ms ticks. Still fins latch
    # the command at once, at the next advance (slew_at_latch: no pattern in motion to slew from): a power stroke
    # from 90 deg to 110 deg in T / (zeta + 1) = 0.5 s, its peak pi 20 deg / (2 * 0.5 s) = 0.63 rad/s far below
    # the servo's 13. At 0.605 s the recovery latches the same pattern from 110 deg.
    rig = _HandDriven()
    beats = tuple(float(v) for v in np.tile(FinBeat.from_degrees(90, 20, 1.0, 1.0).as_array(), 2))
    rig.send(0.105, pr.MsgType.SET_FINS, fins=beats, command=1)
    for t in (0.3, 0.5):  # keep-alive copies feed the watchdog
        rig.send(t, pr.MsgType.SET_FINS, fins=beats, command=1)
    rig.run_to(0.65)
    reports = rig.reports()
    assert [(r.uptime_ms, r.fin, r.power) for r in reports] == [(105, 0, True), (105, 1, True), (605, 0, False),
                                                               (605, 1, False)]
    first, second = reports[0], reports[2]
    assert first.turn == pytest.approx(math.pi / 2, abs=1e-3)
    assert first.beat == pytest.approx((math.pi / 2, math.radians(20), 1.0, 1.0), abs=1e-3)
    assert second.turn == pytest.approx(math.pi / 2 + math.radians(20), abs=1e-3)
    assert second.beat == pytest.approx((math.pi / 2, math.radians(20), 1.0, 1.0), abs=1e-3)
    with rig.robot._lock:  # and it is what the emulated fin runs
        fin = rig.robot.model.fins[0, 0]
        assert fin[strokes.AMPLITUDE] == pytest.approx(second.beat[1], abs=1e-3)
        assert fin[strokes.ANGLE_FROM] == pytest.approx(second.turn, abs=1e-3)


def test_what_a_turning_point_latches_does_not_depend_on_when_the_command_arrived():
    # (90 deg, 20 deg, 0.4 s, 1) from rest at 0.105 s: half-strokes of 0.2 s, turning points at 0.305, 0.505 s.
    # (140 deg, ...) heard anywhere in the recovery: the power stroke at 0.505 s latches the bias moved by
    # max_rate x 0.2 s = 36 deg, 126 deg, whatever the milliseconds between its arrival and the firmware's tick.
    latched = []
    for heard in (0.401, 0.404, 0.4075, 0.46):
        rig = _HandDriven()
        first = np.tile(FinBeat.from_degrees(90, 20, 0.4, 1.0).as_array(), 2)
        second = np.tile(FinBeat.from_degrees(140, 20, 0.4, 1.0).as_array(), 2)
        rig.send(0.105, pr.MsgType.SET_FINS, fins=tuple(first.tolist()), command=1)
        rig.send(heard, pr.MsgType.SET_FINS, fins=tuple(second.tolist()), command=2)
        rig.run_to(0.55)
        power = [r for r in rig.reports() if r.uptime_ms == 505]
        assert [r.fin for r in power] == [0, 1] and all(r.power for r in power)
        latched.append([r.beat for r in power])
        rig.send(0.55, pr.MsgType.HEARTBEAT)  # the STATUS says the rule held the fins back
        statuses = [m.status for m in pr.StreamDecoder().feed(rig.sink.data) if m.type == pr.MsgType.STATUS]
        assert statuses[-1].flags & pr.StatusFlag.RATE_LIMITED and not statuses[0].flags & pr.StatusFlag.RATE_LIMITED
    assert np.degrees(latched[0][0][0]) == pytest.approx(126.0, abs=0.1)
    assert all(b == latched[0] for b in latched)


def _spin(params: FishParams, delay_seed: int, seconds: float = 12.0):
    """The emulated fish spinning on the spot (SPIN_CYCLE); each command heard 0-9 ms after the PC sent it.

    Returns the rig and a run log (text) of what the PC knows: commands at their send times and the reports.
    """
    rig = _HandDriven(params)
    rng = np.random.default_rng(delay_seed)
    log_text = io.StringIO()
    log = RunLogWriter(log_text, "emulator", 0.5, FirmwareConfig())
    log.episode(0, 0.0)
    log.pose(0.0, 1.15, 0.575, 0.0, 1.0)
    steps = int(seconds / 0.5)
    for k in range(steps):
        amp_r, amp_l, bias_r, bias_l = SPIN_CYCLE[k % len(SPIN_CYCLE)]
        beats = np.array([[bias_r, amp_r, 0.5, 5.0], [bias_l, amp_l, 0.5, 5.0]])
        t_sent = 0.5 * k + 0.05
        log.command(t_sent, beats)
        heard = t_sent + float(rng.uniform(0.0, 0.009))
        for t in (heard, heard + 0.1, heard + 0.2, heard + 0.3, heard + 0.4):  # the command, then its copies
            rig.send(t, pr.MsgType.SET_FINS, fins=tuple(beats.ravel().tolist()), command=k + 1, lease=0.8)
    rig.run_to(0.5 * steps + 0.05)
    return rig, log_text, rig.reports()


def _replayed(log_text, reports, keep, params, trace):
    """Replay the fins (with the reports in ``keep``) and the body under them, sampled at the trace's times."""
    text = log_text.getvalue()
    lines = text.splitlines()
    latch_lines = [json.dumps({"type": "latch", "t": r.uptime_ms / 1000.0, "fin": r.fin, "beat": list(r.beat),
                               "turn": r.turn, "power": r.power, "uptime_ms": r.uptime_ms, "boot": r.boot})
                   for i, r in enumerate(reports) if keep(i)]
    records = [json.loads(line) for line in lines[2:]] + [json.loads(line) for line in latch_lines]
    body = sorted(records, key=lambda r: (r["t"], r["type"] != "pose"))
    run = read_run_log(io.StringIO("\n".join([lines[0], lines[1], *map(json.dumps, body)]) + "\n"))
    track = replay_fins(run)
    t = np.array([row[0] for row in trace])
    return simulate(track, [params], np.array([0.0]), np.array([[[1.15, 0.575, 0.0, 0.0, 0.0, 0.0]]]), t,
                    FULL_REFERENCE)[0]


def test_replay_with_reports_follows_the_emulated_spin_where_the_inference_drifts():
    params = FishParams()
    rig, log_text, reports = _spin(params, delay_seed=3)
    trace = rig.robot.trace
    truth_psi = np.unwrap(np.array([row[1][2] for row in trace]))
    truth_xy = np.array([row[1][:2] for row in trace])
    path = float(np.sum(np.hypot(*np.diff(truth_xy, axis=0).T)))
    errors = {}
    for name, keep in (("all", lambda i: True), ("none", lambda i: False), ("half", lambda i: i % 2 == 0)):
        sim = _replayed(log_text, reports, keep, params, trace)
        errors[name] = (float(np.max(np.abs(np.degrees(sim[:, 2] - truth_psi)))),
                        float(np.max(np.hypot(*(sim[:, :2] - truth_xy).T))))
    assert len(reports) > 40  # the spin latches a new pattern about every half-stroke of the right fin
    # with every report: the robot's heading within the wire's quantisation (mrad, ms), its position within 1 %
    # of the path (the quantised half-strokes' small force errors add up along it; the calibration's yardstick)
    assert errors["all"][0] < 0.5 and errors["all"][1] < 0.01 * path, (errors, path)
    # without: the inferred latches drift (the 0-9 ms the PC's log does not see decide which pattern latches)
    assert errors["none"][0] > 5 * max(errors["all"][0], 0.1), errors
    # every second report lost: each report resynchronises its half-stroke whole (angle, kind, pattern)
    assert errors["half"][0] < errors["none"][0], errors


# ------------------------------------------------------------------ PC side
def test_link_places_reports_on_its_clock_counts_lost_ones_and_ignores_foreign_ones():
    link = RadioLink("loop://", session=0xABCD, keepalive_period=10.0)
    try:
        link._stop.set()  # no threads racing the hand-fed frames
        now = link.clock.monotonic()
        latch = pr.Latch(5000, 42, 0, True, 1.6, (1.6, 0.2, 1.0, 2.0))
        link._receive(_frame(pr.Message(pr.MsgType.LATCH, 1, 0xABCD, latch=latch)))
        assert link.stats.latches_unplaced == 1 and not link.drain_latches()  # the robot's clock is not known yet
        status = pr.Status(1, int(pr.MsgType.HEARTBEAT), int(pr.RobotState.RUNNING), uptime_ms=6000, served=0xABCD,
                           boot=42)
        link._receive(_frame(pr.Message(pr.MsgType.STATUS, 1, 0xABCD, status=status)))
        t_status = link.last_status_time
        for seq, uptime in ((2, 6100), (4, 6300)):  # seq 3 lost
            link._receive(_frame(pr.Message(pr.MsgType.LATCH, seq, 0xABCD,
                                            latch=pr.Latch(uptime, 42, 1, False, 1.6, (1.6, 0.2, 1.0, 2.0)))))
        link._receive(_frame(pr.Message(pr.MsgType.LATCH, 5, 0x1234, latch=latch)))  # another PC's fins
        drained = link.drain_latches()
        assert [lt.uptime_ms for _, lt in drained] == [6100, 6300]
        assert drained[0][0] == pytest.approx(t_status + 0.1) and drained[1][0] == pytest.approx(t_status + 0.3)
        assert link.stats.latches == 2 and link.stats.latches_lost == 1
        assert now <= t_status
    finally:
        link.close(stop_wait=0.0)


@pytest.mark.parametrize("up, down", [(0.1, 0.1), (0.03, 0.03), (0.02, 0.12)])
def test_robot_clock_places_an_uptime_between_the_answered_messages_bounds(up, down):
    # The robot's clock reads u at PC time u + offset. A message sent at t reaches it at t + up; its answer leaves
    # then (uptime read) and arrives at t + up + down. Unanswered STATUS messages bound the offset from above only.
    from pectoral_gym.hardware.radio.linkclock import RobotClock

    offset = 12.345
    answered, unanswered = RobotClock(), RobotClock()
    for k in range(5):
        t_sent = 100.0 + 0.25 * k
        read = t_sent + up  # PC time at which the robot read its clock
        uptime_ms = round((read - offset) * 1000.0)
        read = uptime_ms / 1000.0 + offset  # on the ms the wire carries
        answered.add(7, uptime_ms, read + down, t_sent)
        unanswered.add(7, uptime_ms, read + down)
    uptime_ms = round((100.6 - offset) * 1000.0)
    truth = uptime_ms / 1000.0 + offset
    # NTP's midpoint: exact for a symmetric radio, off by half the asymmetry otherwise
    assert answered.pc_time(7, uptime_ms) == pytest.approx(truth + (down - up) / 2.0, abs=1e-9)
    assert unanswered.pc_time(7, uptime_ms) == pytest.approx(truth + down, abs=1e-9)  # late by the return trip
    assert answered.pc_time(8, uptime_ms) is None  # another boot's clock is not known


# ------------------------------------------------------------------ run log
def test_run_log_latch_records_read_back_and_old_versions_still_read(tmp_path):
    run = read_run_log(io.StringIO(dumps_example()))
    ep = run.episodes[0]
    assert ep.latch_t.tolist() == [0.434] and ep.latch_fin.tolist() == [0]
    assert ep.latch_beat.tolist() == [[1.5708, 0.5236, 1.0, 2.0]] and ep.latch_power.tolist() == [0.0]
    old = [line for line in dumps_example().splitlines() if '"latch"' not in line]
    old[0] = old[0].replace('"version": 2', '"version": 1')
    assert len(read_run_log(io.StringIO("\n".join(old))).episodes[0].latch_t) == 0  # a version-1 log
    with pytest.raises(RunLogError, match=r"<stream>:6: a latch record in a version-1 log"):
        lines = dumps_example().splitlines()
        lines[0] = lines[0].replace('"version": 2', '"version": 1')
        read_run_log(io.StringIO("\n".join(lines)))


@pytest.mark.parametrize(("change", "message"), [
    ({"fin": 2}, "fin must be 0 (right) or 1 (left)"),
    ({"fin": True}, "fin must be an integer"),
    ({"power": "yes"}, "power must be true"),
    ({"uptime_ms": -1}, "uptime_ms must be the robot's u32 clock"),
    ({"uptime_ms": 1.5}, "uptime_ms must be an integer"),
    ({"beat": [1.5, 0.2, 1.0]}, "beat must be 4 finite numbers"),
    ({"beat": [3.0, 0.5, 1.0, 2.0]}, "right fin beat outside the envelope"),
    ({"turn": 4.0}, "turn must be a fin angle"),
    ({"boot": "x"}, "boot must be an integer"),
])
def test_bad_latch_record_is_named_by_its_line(change, message):
    lines = dumps_example().splitlines()
    index = next(i for i, line in enumerate(lines) if '"latch"' in line)
    rec = json.loads(lines[index])
    rec.update(change)
    lines[index] = json.dumps(rec)
    with pytest.raises(RunLogError, match=rf"<stream>:{index + 1}: .*{re.escape(message)}"):
        read_run_log(io.StringIO("\n".join(lines)))
    missing = json.loads(dumps_example().splitlines()[index])
    del missing["uptime_ms"]
    lines[index] = json.dumps(missing)
    with pytest.raises(RunLogError, match=rf"<stream>:{index + 1}: latch record lacks field\(s\) \['uptime_ms'\]"):
        read_run_log(io.StringIO("\n".join(lines)))


def test_unknown_log_version_is_refused():
    lines = dumps_example().splitlines()
    lines[0] = lines[0].replace('"version": 2', '"version": 3')
    with pytest.raises(RunLogError, match=r"<stream>:1: header: version 3 is not supported"):
        read_run_log(io.StringIO("\n".join(lines)))


def test_chunk_is_shorter_than_any_half_stroke():
    # latched() relies on at most one latch per fin and tick
    limits = FirmwareConfig().limits
    assert limits.period_min / (limits.ratio_max + 1.0) > CHUNK
