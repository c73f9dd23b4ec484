"""XBee API frames (mode 2, escaped): the outer layer of the wire protocol between the PC and the robotic fish.

``0x7E``, length (2 bytes, big endian), frame data, checksum ``0xFF - (sum of frame data & 0xFF)``. Every byte after
the start delimiter that is ``0x7E``, ``0x7D``, ``0x11`` or ``0x13`` goes out as ``0x7D, byte ^ 0x20``; length and
checksum count unescaped bytes. The PC sends *Transmit Request* frames (``0x10``, 64-bit destination); the robot's
XBee delivers them to the dsPIC as *Receive Packet* frames (``0x90``) and vice versa. The messages these frames carry
are :mod:`pectoral_gym.hardware.radio.protocol`'s; byte layouts, timing and rules in ``docs/protocol.md``.
"""

from __future__ import annotations

import struct

__all__ = [
    "START", "ESCAPE", "XON", "XOFF", "TX_REQUEST", "RX_PACKET", "BROADCAST", "MAX_FRAME_DATA", "ProtocolError",
    "checksum", "escape", "unescape", "encode_frame", "decode_frame", "tx_request", "rx_packet", "rf_data",
]

START, ESCAPE, XON, XOFF = 0x7E, 0x7D, 0x11, 0x13
_SPECIAL = frozenset((START, ESCAPE, XON, XOFF))
TX_REQUEST = 0x10  # XBee Transmit Request (64-bit destination)
RX_PACKET = 0x90  # XBee Receive Packet
BROADCAST = 0x000000000000FFFF  # 64-bit broadcast address
MAX_FRAME_DATA = 255  # longest frame data we accept; our frames are far shorter


class ProtocolError(ValueError):
    """A frame or message that cannot be decoded; ``reason`` is a short machine-readable tag."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


def checksum(frame_data: bytes) -> int:
    """XBee API checksum: ``0xFF`` minus the low byte of the sum of the frame data."""
    return 0xFF - (sum(frame_data) & 0xFF)


# ---------------------------------------------------------------- XBee frames
def escape(data: bytes) -> bytes:
    """API mode 2 escaping: ``0x7E 0x7D 0x11 0x13`` -> ``0x7D, byte ^ 0x20``."""
    out = bytearray()
    for byte in data:
        if byte in _SPECIAL:
            out += bytes((ESCAPE, byte ^ 0x20))
        else:
            out.append(byte)
    return bytes(out)


def unescape(data: bytes) -> bytes:
    """Undo :func:`escape`; raises :class:`ProtocolError` on a dangling escape or a raw ``0x7E``."""
    out = bytearray()
    it = iter(data)
    for byte in it:
        if byte == START:
            raise ProtocolError("framing", "unescaped 0x7E inside a frame")
        if byte == ESCAPE:
            nxt = next(it, None)
            if nxt is None:
                raise ProtocolError("framing", "frame ends with an escape byte")
            byte = nxt ^ 0x20
        out.append(byte)
    return bytes(out)


def encode_frame(frame_data: bytes) -> bytes:
    """One escaped API frame around ``frame_data`` (frame type byte first)."""
    if not 1 <= len(frame_data) <= MAX_FRAME_DATA:
        raise ValueError(f"frame data must be 1..{MAX_FRAME_DATA} bytes, got {len(frame_data)}")
    body = struct.pack(">H", len(frame_data)) + frame_data + bytes((checksum(frame_data),))
    return bytes((START,)) + escape(body)


def decode_frame(raw: bytes) -> bytes:
    """Frame data of exactly one escaped API frame; :class:`ProtocolError` if it is not one."""
    if not raw or raw[0] != START:
        raise ProtocolError("framing", "a frame starts with 0x7E")
    body = unescape(raw[1:])
    if len(body) < 4:
        raise ProtocolError("truncated", f"{len(body)} bytes after the delimiter")
    length = (body[0] << 8) | body[1]
    if len(body) != length + 3:
        raise ProtocolError("length", f"length field {length}, got {len(body) - 3} data bytes")
    data, cs = body[2:-1], body[-1]
    if checksum(data) != cs:
        raise ProtocolError("checksum", f"expected 0x{checksum(data):02X}, got 0x{cs:02X}")
    return data


def tx_request(payload: bytes, dest64: int = BROADCAST, frame_id: int = 0) -> bytes:
    """Frame data of a Transmit Request (0x10); ``frame_id`` 0 asks the XBee for no Transmit Status."""
    return struct.pack(">BBQHBB", TX_REQUEST, frame_id, dest64, 0xFFFE, 0, 0) + payload


def rx_packet(payload: bytes, src64: int = 0, src16: int = 0xFFFE, options: int = 0x01) -> bytes:
    """Frame data of a Receive Packet (0x90) as the receiving XBee hands it over (options 0x01 = acked)."""
    return struct.pack(">BQHB", RX_PACKET, src64, src16, options) + payload


def rf_data(frame_data: bytes) -> bytes | None:
    """The RF data of a Transmit Request or Receive Packet; ``None`` for any other frame type."""
    if frame_data[0] == TX_REQUEST and len(frame_data) >= 14:
        return frame_data[14:]
    if frame_data[0] == RX_PACKET and len(frame_data) >= 12:
        return frame_data[12:]
    return None
