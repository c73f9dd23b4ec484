"""Wire protocol: XBee API mode 2 frames, CRC-16, messages, streaming decoder, sequence numbers."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb


def test_crc16_ccitt_false_check_value():
    # The catalogue check value of CRC-16/CCITT-FALSE for the ASCII string "123456789".
    assert pr.crc16(b"123456789") == 0x29B1
    assert pr.crc16(b"") == 0xFFFF  # init value, no final xor


def _crc16_bitwise(data: bytes) -> int:
    """CRC-16/CCITT-FALSE by its definition, one bit at a time."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


@given(st.binary(max_size=300))
@settings(max_examples=300, deadline=None)
def test_crc16_is_the_bitwise_definition(data):
    assert pr.crc16(data) == _crc16_bitwise(data)
    assert pr.crc16(bytearray(data)) == pr.crc16(memoryview(data)) == pr.crc16(data)


def test_digi_escaping_example():
    # Digi's API-mode-2 example: frame data 23 11; 0x11 (XON) is escaped as 7D 31; checksum 0xFF - 0x34 = 0xCB.
    raw = bytes([0x7E, 0x00, 0x02, 0x23, 0x7D, 0x31, 0xCB])
    assert xb.encode_frame(bytes([0x23, 0x11])) == raw
    assert xb.decode_frame(raw) == bytes([0x23, 0x11])


def test_digi_transmit_request_example():
    # Digi's Transmit Request (0x10) example with AP = 2: destination 0013A200400A0127, 16-bit FFFE, frame id 1,
    # RF data "TxData0A"; the 0x13 in the address and the checksum 0x13 both go out escaped as 7D 33.
    expected = bytes.fromhex("7E0016100100 7D33 A200400A0127FFFE0000 5478446174613041 7D33".replace(" ", ""))
    frame = xb.encode_frame(xb.tx_request(b"TxData0A", dest64=0x0013A200400A0127, frame_id=1))
    assert frame == expected
    assert xb.rf_data(xb.decode_frame(frame)) == b"TxData0A"


@pytest.mark.parametrize("value", range(256))
def test_frame_round_trip_every_byte_value(value):
    data = bytes([0x90, value, value, 0x00, value])
    raw = xb.encode_frame(data)
    assert xb.decode_frame(raw) == data
    # After the delimiter no raw special byte remains except 0x7D as an escape prefix.
    body = raw[1:]
    assert not any(b in (0x7E, 0x11, 0x13) for b in body)
    assert all(body[i + 1] in (0x5E, 0x5D, 0x31, 0x33) for i, b in enumerate(body) if b == 0x7D)
    assert pr.StreamDecoder().feed(raw) == []  # a valid frame but not a message: no output


def test_frame_of_all_byte_values_round_trips():
    data = bytes(range(255))
    assert xb.decode_frame(xb.encode_frame(data)) == data


def test_decode_frame_rejects_bad_frames():
    good = xb.encode_frame(b"\x23\x11")
    with pytest.raises(xb.ProtocolError, match="checksum"):
        xb.decode_frame(good[:-1] + bytes([good[-1] ^ 1]))
    with pytest.raises(xb.ProtocolError):
        xb.decode_frame(good[:-2])
    with pytest.raises(xb.ProtocolError, match="framing"):
        xb.decode_frame(b"\x00" + good[1:])


def _msg_frames(*messages, tx=True):
    wrap = xb.tx_request if tx else xb.rx_packet
    return b"".join(xb.encode_frame(wrap(pr.encode_message(m))) for m in messages)


FINS = (math.pi / 2, math.radians(20), 1.25, 3.0, 1.2, 0.0, 0.5, 1.0)


def test_message_round_trips():
    status = pr.Status(ack_seq=65535, ack_type=1, state=pr.RobotState.WATCHDOG, flags=3, crc_errors=7,
                       duplicates=2, stale=1, uptime_ms=123456789)
    msgs = [pr.Message(pr.MsgType.SET_FINS, 1, 9, fins=FINS), pr.Message(pr.MsgType.STOP, 2, 9),
            pr.Message(pr.MsgType.HEARTBEAT, 65535, 255), pr.Message(pr.MsgType.STATUS, 0, 0, status=status)]
    for m in msgs:
        back = pr.decode_message(pr.encode_message(m))
        assert (back.type, back.seq, back.session, back.status) == (m.type, m.seq, m.session, m.status)
    fins = pr.decode_message(pr.encode_message(msgs[0])).fins
    assert fins == pytest.approx(FINS, abs=0.5e-3)  # 1 mrad, 1 ms, 0.001 resolution


def test_set_fins_rejects_non_finite_and_out_of_range():
    with pytest.raises(ValueError, match="finite"):
        pr.encode_message(pr.Message(pr.MsgType.SET_FINS, 1, fins=(math.nan,) + FINS[1:]))
    with pytest.raises(ValueError, match="fit"):
        pr.encode_message(pr.Message(pr.MsgType.SET_FINS, 1, fins=(-0.1,) + FINS[1:]))


def test_every_single_bit_flip_is_caught_by_the_crc():
    payload = pr.encode_message(pr.Message(pr.MsgType.SET_FINS, 513, 4, fins=FINS))
    for i in range(len(payload)):
        for bit in range(8):
            bad = bytearray(payload)
            bad[i] ^= 1 << bit
            with pytest.raises(xb.ProtocolError):
                pr.decode_message(bytes(bad))


def test_stream_decoder_counts_crc_errors_with_a_good_xbee_checksum():
    payload = bytearray(pr.encode_message(pr.Message(pr.MsgType.STOP, 3)))
    payload[2] ^= 0x40  # damage the session byte; the XBee checksum is recomputed over the damaged data
    dec = pr.StreamDecoder()
    assert dec.feed(xb.encode_frame(xb.tx_request(bytes(payload)))) == []
    assert (dec.crc_errors, dec.frames, dec.messages) == (1, 1, 0)


def test_stream_decoder_resynchronises():
    a = pr.Message(pr.MsgType.HEARTBEAT, 1)
    b = pr.Message(pr.MsgType.SET_FINS, 2, fins=FINS)
    c = pr.Message(pr.MsgType.STOP, 3)
    fa, fb, fc = _msg_frames(a), _msg_frames(b, tx=False), _msg_frames(c)
    bad_checksum = fb[:-1] + bytes([fb[-1] ^ 0x01]) if fb[-1] not in (0x7E ^ 1, 0x7D ^ 1) else fb[:-2]
    stream = b"\x00\xffgarbage" + fa + fb[: len(fb) // 2] + bad_checksum + fc + b"\x7e\x00"
    dec = pr.StreamDecoder()
    out = []
    for byte in stream:  # byte by byte: frame boundaries need not align with reads
        out += dec.feed(bytes([byte]))
    assert [m.seq for m in out] == [1, 3]
    assert dec.truncated == 1 and dec.checksum_errors + dec.truncated >= 2 and dec.skipped_bytes == 9
    assert out[0].type == pr.MsgType.HEARTBEAT and out[1].type == pr.MsgType.STOP


def test_stream_decoder_rejects_impossible_length():
    dec = pr.StreamDecoder()
    assert dec.feed(b"\x7e\xff\xff" + _msg_frames(pr.Message(pr.MsgType.STOP, 5))) != []
    assert dec.framing_errors == 1


messages = st.builds(
    lambda kind, seq, session, fins: pr.Message(kind, seq, session, fins=fins if kind == pr.MsgType.SET_FINS
                                                else None),
    st.sampled_from([pr.MsgType.SET_FINS, pr.MsgType.STOP, pr.MsgType.HEARTBEAT]),
    st.integers(0, 0xFFFF), st.integers(0, 0xFF),
    st.tuples(*[st.floats(0.0, 65.0)] * 8),
)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=400))
def test_fuzz_decoder_never_crashes_and_yields_only_valid_messages(data):
    dec = pr.StreamDecoder()
    for msg in dec.feed(data):
        pr.decode_message(pr.encode_message(msg))  # re-encodes: a well-formed message
    assert dec.messages <= dec.frames


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(messages, st.binary(max_size=30)), min_size=1, max_size=6), st.data())
def test_fuzz_valid_frames_survive_garbage_and_corruption_is_never_delivered(items, data):
    # Garbage without a start delimiter between frames: every message comes through, in order.
    stream = b"".join(g.replace(b"\x7e", b"") + _msg_frames(m) for m, g in items)
    out = pr.StreamDecoder().feed(stream)
    assert [(m.type, m.seq, m.session) for m in out] == [(m.type, m.seq, m.session) for m, _ in items]
    # One damaged byte anywhere: whatever comes out is one of the messages sent, unchanged.
    i = data.draw(st.integers(0, len(stream) - 1))
    flip = data.draw(st.integers(1, 255))
    damaged = stream[:i] + bytes([stream[i] ^ flip]) + stream[i + 1:]
    sent = {pr.encode_message(m) for m, _ in items}
    for msg in pr.StreamDecoder().feed(damaged):
        assert pr.encode_message(msg) in sent


class _CheckEveryByte(pr.StreamDecoder):
    """The decoder as first written: the frame checked after every byte (the checks decide nothing in between)."""

    def feed(self, data):
        out = []
        for byte in data:
            self._need = 0  # every appended byte reaches _check
            out.extend(super().feed(bytes([byte])))
        return out


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(messages, st.binary(max_size=30)), min_size=1, max_size=6), st.data())
def test_decoder_decides_as_when_it_checked_every_byte(items, data):
    """Frames, garbage (delimiters and escapes included), cut frames and damaged bytes: the same out, same counts."""
    stream = bytearray(b"".join(g + _msg_frames(m) for m, g in items))
    for _ in range(data.draw(st.integers(0, 3))):
        i = data.draw(st.integers(0, len(stream) - 1))
        stream[i] ^= data.draw(st.integers(1, 255))
    cut = data.draw(st.integers(0, len(stream)))
    stream = bytes(stream[:cut] + b"\x7e" + stream[cut:])  # a frame cut short by a new one
    ours, reference = pr.StreamDecoder(), _CheckEveryByte()
    chunks = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=5)))
    got = [m for a, b in zip([0, *chunks], [*chunks, len(stream)], strict=True) for m in ours.feed(stream[a:b])]
    assert got == reference.feed(stream)
    assert ours.counters() == reference.counters()


def test_sequence_tracker_wraps_and_classifies():
    tr = pr.SequenceTracker()
    assert tr.check(65534) == pr.Verdict.NEW
    assert tr.check(65535) == pr.Verdict.NEW
    assert tr.check(0) == pr.Verdict.NEW  # wrap-around
    assert tr.check(0) == pr.Verdict.DUPLICATE
    assert tr.check(65535) == pr.Verdict.STALE  # older, across the wrap
    assert tr.check(3) == pr.Verdict.NEW  # 1 and 2 lost
    assert tr.check(2) == pr.Verdict.STALE  # late: reordered
    assert (tr.new, tr.duplicates, tr.stale, tr.lost) == (4, 1, 2, 2)
    assert tr.check(40000) == pr.Verdict.STALE  # (40000 - 3) mod 2**16 = 39997 >= 2**15: behind, not ahead


def test_sequence_tracker_half_range_and_session():
    tr = pr.SequenceTracker()
    tr.check(10)
    assert tr.check(10 + 0x7FFF) == pr.Verdict.NEW  # just under half the range ahead
    tr2 = pr.SequenceTracker()
    tr2.check(10)
    assert tr2.check(10 + 0x8000) == pr.Verdict.STALE  # half the range: treated as old
    assert tr2.check(10, session=1) == pr.Verdict.NEW  # a new session starts afresh
    tr2.reset()
    assert tr2.check(5, session=1) == pr.Verdict.NEW
