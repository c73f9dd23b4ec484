"""The emulated robot's dsPIC on the C firmware: re-framing as the robot's XBee, the model's fins on the C fins."""

import math

import numpy as np
import pytest

from pectoral_gym.hardware.emulated_firmware import ROBOT_ADDRESS, CFirmwareAdapter, make_firmware
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.model.spec import FULL_REFERENCE


@pytest.fixture
def adapter():
    from pectoral_gym.hardware.radio.cfirmware import library_path

    try:
        library_path()
    except RuntimeError as err:  # no C compiler here
        pytest.skip(str(err))
    return CFirmwareAdapter(None, boot=0x1234)


def _beats(*rows):
    return tuple(v for b, a, p, r in rows for v in (math.radians(b), math.radians(a), p, r))


def _to_robot(msg):
    """What the PC writes to its XBee: a Transmit Request carrying ``msg``."""
    return xb.encode_frame(xb.tx_request(pr.encode_message(msg)))


def _decode(frames):
    out = []
    for frame in frames:
        data = xb.decode_frame(frame)
        assert data[0] == xb.RX_PACKET and int.from_bytes(data[1:9], "big") == ROBOT_ADDRESS
        out.append(pr.decode_message(xb.rf_data(data)))
    return out


def test_the_model_follows_the_c_fins_and_the_pc_gets_receive_packets(adapter):
    model = FULL_REFERENCE.build(1, None)
    session = 0xABCDEF
    commands = {0.1234: _beats((80, 25, 1.6, 4.3), (75, 10, 1.4, 1.8)),
                0.7037: _beats((100, 20, 1.0, 2.0), (95, 30, 0.9, 1.0)),
                1.3012: _beats((60, 30, 0.8, 1.0), (120, 30, 0.8, 1.0))}
    seq, heard, worst = 0, [], 0.0
    for k in range(1, 200):
        t = k / 100.0
        for when, fins in commands.items():
            if t - 0.01 < when <= t:
                heard += _decode(adapter.advance(model, when, None))
                seq += 1
                msg = pr.Message(pr.MsgType.SET_FINS, seq, session, fins=fins, command=seq, lease=1.0)
                replies, messages = adapter.receive(_to_robot(msg), when, model, lambda: True, None)
                heard += _decode(replies)
                assert messages == [pr.decode_message(pr.encode_message(msg))]
        if k == 180:  # a STOP: the model's fins hold where the C fins halted
            seq += 1
            replies, _ = adapter.receive(_to_robot(pr.Message(pr.MsgType.STOP, seq, session)), t, model,
                                         lambda: True, None)
            heard += _decode(replies)
        heard += _decode(adapter.advance(model, t, None))
        # After each call the model is at the core's time, and its fins where the C fins are.
        assert model.time == pytest.approx(round(t * 1000) / 1000.0, abs=1e-9)
        worst = max(worst, float(np.max(np.abs(model.fin_angles()[0][0] - adapter.core.fin_angles()))))
    assert worst < 1e-5  # float32 angles of the core against the model's float64
    statuses = [m for m in heard if m.type == pr.MsgType.STATUS]
    latches = [m for m in heard if m.type == pr.MsgType.LATCH]
    assert [s.status.ack_seq for s in statuses] == list(range(1, seq + 1))
    assert all(s.session == session for s in statuses)
    assert len(latches) >= 8 and adapter.state == pr.RobotState.STOPPED and not adapter.running
    rates = model.fin_angles()[1][0]
    assert np.all(rates == 0.0)  # halted: still


def test_frames_the_pc_xbee_would_not_send_never_reach_the_core(adapter):
    model = FULL_REFERENCE.build(1, None)
    good = _to_robot(pr.Message(pr.MsgType.HEARTBEAT, 1, 5))
    damaged = good[:-1] + bytes([good[-1] ^ 0xFF])  # the PC's serial line garbled the checksum
    rx_framed = xb.encode_frame(xb.rx_packet(pr.encode_message(pr.Message(pr.MsgType.HEARTBEAT, 2, 5))))
    replies, messages = adapter.receive(b"\x00\x13" + damaged + rx_framed + good, 0.05, model, lambda: True, None)
    assert [m.seq for m in messages] == [1] and [m.status.ack_seq for m in _decode(replies)] == [1]
    assert adapter.decoder.messages == 1 and adapter.decoder.checksum_errors == 0


def test_the_python_reference_stays_the_default():
    assert type(make_firmware("python", None, 7)).__name__ == "PythonFirmware"
    with pytest.raises(ValueError, match="firmware_impl"):
        make_firmware("rust", None, 7)
    with pytest.raises(ValueError, match="C firmware"):
        make_firmware("python", None, 7, variant="skip_crc")


def test_c_core_and_python_reference_on_the_same_ticks_move_the_fish_alike(adapter):
    # The same bytes at the same times to the C core and to the reference ticked on the same 10 ms grid: the fins
    # and the fish agree to float32's precision (the default reference ticks wherever the emulator wakes instead).
    from pectoral_gym.hardware.emulated_firmware import PythonFirmware

    reference = PythonFirmware(None, boot=0x1234, grid=True)
    models = [FULL_REFERENCE.build(1, None) for _ in range(2)]
    patterns = [_beats((80, 25, 1.6, 4.3), (75, 10, 1.4, 1.8)), _beats((100, 20, 1.0, 2.0), (95, 30, 0.9, 1.0)),
                _beats((60, 30, 0.8, 1.0), (120, 30, 0.8, 1.0))]
    worst_angle = worst_pose = 0.0
    for k in range(1, 300):
        t = k / 100.0
        for rules, model in zip((adapter, reference), models, strict=True):
            if k % 50 == 13:  # a new command every 0.5 s, 3.7 ms after a tick
                msg = pr.Message(pr.MsgType.SET_FINS, k, 77, fins=patterns[(k // 50) % 3], command=k, lease=1.0)
                rules.advance(model, t - 0.0063, None)
                rules.receive(_to_robot(msg), t - 0.0063, model, lambda: True, None)
            rules.advance(model, t, None)
        worst_angle = max(worst_angle, float(np.max(np.abs(models[0].fin_angles()[0][0] -
                                                           models[1].fin_angles()[0][0]))))
        worst_pose = max(worst_pose, float(np.max(np.abs(models[0].state[0, :3] - models[1].state[0, :3]))))
    assert worst_angle < 1e-4 and worst_pose < 1e-5, (worst_angle, worst_pose)
