"""The sashil serial protocol: COBS-framed binary frames with a CRC-16 (see ``protocol.md``).

One frame on the wire::

    COBS( type:u8 | seq:u16 | len:u8 | payload[len] | crc:u16 ) 0x00

All integers little-endian. ``crc`` is CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no
reflection, no final xor; check value 0x29B1 for b"123456789") over type..payload. COBS
(Cheshire & Baker 1999) removes every 0x00 from the frame, so 0x00 alone marks a frame's end and a
receiver resynchronises at the next 0x00 after garbage, a lost byte or a bad CRC.

Pure functions and a pure stream decoder; no I/O here.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from sashil.drivers.messages import (
    CURRENT_LSB_A,
    EDGE_ARM_UP,
    EDGE_ROAD_UP,
    ROAD_SPEED_LSB_RAD_S,
    Command,
    Configure,
    Hello,
    Message,
    RoadSpeed,
    Sample,
    Status,
    Version,
    current_to_wire,
    edge_age_to_wire,
    edge_dirs_to_wire,
    edge_from_wire,
    road_speed_to_wire,
)

# message type codes
TYPE_SAMPLE = 0x01
TYPE_COMMAND = 0x02
TYPE_ROAD_SPEED = 0x03
TYPE_STATUS = 0x04
TYPE_HELLO = 0x05
TYPE_VERSION = 0x06
TYPE_CONFIGURE = 0x07

HEADER = struct.Struct("<BHB")  # type, seq, payload length
CRC = struct.Struct("<H")
MAX_PAYLOAD = 32
#: longest encoded frame (header + payload + crc, COBS overhead, delimiter)
MAX_FRAME = HEADER.size + MAX_PAYLOAD + CRC.size + 2

_SAMPLE = struct.Struct("<IiihBHHB")  # ..., flags, arm edge age, road edge age, edge directions
_COMMAND = struct.Struct("<HB")
_ROAD_SPEED = struct.Struct("<i")
_STATUS = struct.Struct("<BBHH")
_HELLO = struct.Struct("<B")
_VERSION = struct.Struct("<BIH")
_CONFIGURE = struct.Struct("<HHB")


class FrameError(ValueError):
    """A frame that cannot be decoded; ``kind`` says which counter it belongs to."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind


# --- CRC-16/CCITT-FALSE ------------------------------------------------------------------------
def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16_ccitt(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (poly 0x1021, init 0xFFFF, MSB first, no final xor)."""
    table = _CRC_TABLE
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ byte]
    return crc


# --- COBS ------------------------------------------------------------------------------------------
def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: ``data`` without any 0x00 (delimiter not included)."""
    out = bytearray()
    block = bytearray()
    full = False  # the last block was a full 254-byte run (code 0xFF, no implied zero)
    for byte in data:
        full = False
        if byte == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out.append(255)
                out += block
                block.clear()
                full = True
    if not full:
        out.append(len(block) + 1)
        out += block
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises FrameError('cobs') for an impossible code sequence."""
    out = bytearray()
    i = 0
    n = len(data)
    while i < n:
        code = data[i]
        if code == 0:
            raise FrameError("cobs", "COBS: 0x00 inside a frame")
        end = i + code
        if end > n:
            raise FrameError("cobs", "COBS: block runs past the end of the frame")
        block = data[i + 1 : end]
        if 0 in block:
            raise FrameError("cobs", "COBS: 0x00 inside a frame")
        out += block
        i = end
        if code != 255 and i < n:
            out.append(0)
    return bytes(out)


# --- messages <-> payload ----------------------------------------------------------------------
def encode_payload(msg: Message) -> tuple[int, bytes]:
    """(type code, payload bytes) of a message, quantised to the wire units."""
    if isinstance(msg, Sample):
        return TYPE_SAMPLE, _SAMPLE.pack(
            msg.device_time_us & 0xFFFFFFFF,
            msg.arm_counts,
            msg.road_counts,
            current_to_wire(msg.current_a, signed=True),
            msg.flags & 0xFF,
            edge_age_to_wire(msg.arm_edge_age_us),
            edge_age_to_wire(msg.road_edge_age_us),
            edge_dirs_to_wire(msg.arm_edge_dir, msg.road_edge_dir),
        )
    if isinstance(msg, Command):
        return TYPE_COMMAND, _COMMAND.pack(current_to_wire(msg.current_a, signed=False), msg.flags & 0xFF)
    if isinstance(msg, RoadSpeed):
        return TYPE_ROAD_SPEED, _ROAD_SPEED.pack(road_speed_to_wire(msg.speed_rad_s))
    if isinstance(msg, Status):
        return TYPE_STATUS, _STATUS.pack(
            msg.flags & 0xFF, msg.fault_code & 0xFF, msg.bad_frames & 0xFFFF, msg.watchdog_trips & 0xFFFF
        )
    if isinstance(msg, Hello):
        return TYPE_HELLO, _HELLO.pack(msg.protocol_version & 0xFF)
    if isinstance(msg, Version):
        return TYPE_VERSION, _VERSION.pack(
            msg.protocol_version & 0xFF, msg.counts_per_rev, current_to_wire(msg.current_max_a, signed=False)
        )
    if isinstance(msg, Configure):
        return TYPE_CONFIGURE, _CONFIGURE.pack(msg.rate_hz, msg.watchdog_ms, msg.pacing)
    raise TypeError(f"not a sashil message: {msg!r}")


def decode_payload(msg_type: int, payload: bytes) -> Message:
    """The message of type ``msg_type`` in ``payload``; FrameError for a wrong type or length."""
    try:
        if msg_type == TYPE_SAMPLE:
            t_us, arm, road, cur, flags, arm_age, road_age, dirs = _SAMPLE.unpack(payload)
            return Sample(
                t_us,
                arm,
                road,
                cur * CURRENT_LSB_A,
                flags,
                *edge_from_wire(arm_age, dirs, EDGE_ARM_UP),
                *edge_from_wire(road_age, dirs, EDGE_ROAD_UP),
            )
        if msg_type == TYPE_COMMAND:
            cur, flags = _COMMAND.unpack(payload)
            return Command(cur * CURRENT_LSB_A, flags)
        if msg_type == TYPE_ROAD_SPEED:
            (speed,) = _ROAD_SPEED.unpack(payload)
            return RoadSpeed(speed * ROAD_SPEED_LSB_RAD_S)
        if msg_type == TYPE_STATUS:
            return Status(*_STATUS.unpack(payload))
        if msg_type == TYPE_HELLO:
            return Hello(*_HELLO.unpack(payload))
        if msg_type == TYPE_VERSION:
            version, cpr, imax = _VERSION.unpack(payload)
            return Version(version, cpr, imax * CURRENT_LSB_A)
        if msg_type == TYPE_CONFIGURE:
            return Configure(*_CONFIGURE.unpack(payload))
    except struct.error:
        raise FrameError(
            "length", f"message type 0x{msg_type:02x}: payload of {len(payload)} bytes has the wrong length"
        ) from None
    raise FrameError("unknown_type", f"unknown message type 0x{msg_type:02x}")


# --- frames ------------------------------------------------------------------------------------
def encode_frame(msg: Message, seq: int) -> bytes:
    """The complete wire frame of ``msg`` with sequence number ``seq`` (mod 2**16), 0x00 included."""
    msg_type, payload = encode_payload(msg)
    body = HEADER.pack(msg_type, seq & 0xFFFF, len(payload)) + payload
    body += CRC.pack(crc16_ccitt(body))
    return cobs_encode(body) + b"\x00"


def decode_frame(encoded: bytes) -> tuple[int, Message]:
    """(seq, message) of one frame's COBS bytes (without the 0x00 delimiter); FrameError if bad."""
    body = cobs_decode(encoded)
    if len(body) < HEADER.size + CRC.size:
        raise FrameError("length", f"frame of {len(body)} bytes is shorter than header + CRC")
    (crc,) = CRC.unpack_from(body, len(body) - CRC.size)
    if crc16_ccitt(body[: -CRC.size]) != crc:
        raise FrameError("crc", "bad CRC")
    msg_type, seq, length = HEADER.unpack_from(body)
    payload = body[HEADER.size : -CRC.size]
    if length != len(payload):
        raise FrameError("length", f"length field {length} but {len(payload)} payload bytes")
    return seq, decode_payload(msg_type, payload)


@dataclass
class DecoderCounters:
    """What the stream decoder saw (each error kind counted separately)."""

    frames: int = 0  # good frames decoded
    crc: int = 0  # frames with a bad CRC
    cobs: int = 0  # impossible COBS code sequences (garbage, lost bytes)
    length: int = 0  # too short, or length field disagrees
    unknown_type: int = 0
    overflow: int = 0  # more than MAX_FRAME bytes without a delimiter (discarded)
    discarded_bytes: int = 0  # bytes thrown away with the bad frames

    @property
    def bad_frames(self) -> int:
        return self.crc + self.cobs + self.length + self.unknown_type + self.overflow

    def as_dict(self) -> dict[str, int]:
        return {
            "frames": self.frames,
            "bad_frames": self.bad_frames,
            "crc": self.crc,
            "cobs": self.cobs,
            "length": self.length,
            "unknown_type": self.unknown_type,
            "overflow": self.overflow,
            "discarded_bytes": self.discarded_bytes,
        }


@dataclass
class StreamDecoder:
    """Cuts a byte stream into frames at 0x00, decodes them, and counts what it throws away.

    Bytes may arrive in any pieces: a frame split over several ``feed`` calls is joined; garbage,
    a lost byte or a bad CRC costs the frame it touches and the decoder is in sync again at the
    next delimiter.
    """

    counters: DecoderCounters = field(default_factory=DecoderCounters)
    _buffer: bytearray = field(default_factory=bytearray)
    _skipping: bool = False  # inside an overlong run: drop bytes up to the next delimiter

    def feed(self, data: bytes) -> list[tuple[int, Message]]:
        """Decode every frame completed by ``data``; returns [(seq, message), ...] in order."""
        out: list[tuple[int, Message]] = []
        counters = self.counters
        start = 0
        while True:
            end = data.find(b"\x00", start)
            if end < 0:
                self._take(data[start:])
                return out
            chunk = data[start:end]
            start = end + 1
            if self._skipping:
                counters.discarded_bytes += len(chunk) + 1
                self._skipping = False
                self._buffer.clear()
                continue
            if self._buffer:
                self._buffer += chunk
                chunk = bytes(self._buffer)
                self._buffer.clear()
            if not chunk:
                continue  # idle delimiters between frames
            try:
                out.append(decode_frame(chunk))
                counters.frames += 1
            except FrameError as err:
                setattr(counters, err.kind, getattr(counters, err.kind) + 1)
                counters.discarded_bytes += len(chunk) + 1

    def _take(self, rest: bytes) -> None:
        if self._skipping:
            self.counters.discarded_bytes += len(rest)
            return
        self._buffer += rest
        if len(self._buffer) > MAX_FRAME:
            self.counters.overflow += 1
            self.counters.discarded_bytes += len(self._buffer)
            self._buffer.clear()
            self._skipping = True
