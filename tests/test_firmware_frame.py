"""The board's serial framing in C gives the same bytes as serial_codec.py."""

from __future__ import annotations

import ctypes

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from message_strategies import messages

from sashil.drivers import firmware
from sashil.drivers.serial_codec import StreamDecoder, encode_frame, encode_payload

if firmware.compiler() is None:  # pragma: no cover - the machine has no C compiler
    pytest.skip("no C compiler on this machine (install gcc or set CC)", allow_module_level=True)

LIB = firmware.load()
U8 = ctypes.c_uint8


def _buf(data: bytes) -> ctypes.Array:
    return (U8 * max(len(data), 1)).from_buffer_copy(data or b"\x00")


def c_encode(msg_type: int, seq: int, payload: bytes) -> bytes:
    out = (U8 * 64)()
    n = LIB.sashil_frame_encode(msg_type, seq, _buf(payload), len(payload), out, len(out))
    return bytes(out[:n])


def c_decode(cobs: bytes) -> tuple[int, int, int, bytes]:
    """(rc, type, seq, payload) of one frame's COBS bytes."""
    msg_type, seq, length, payload = U8(), ctypes.c_uint16(), U8(), (U8 * 32)()
    rc = LIB.sashil_frame_decode(
        _buf(cobs), len(cobs), ctypes.byref(msg_type), ctypes.byref(seq), payload, ctypes.byref(length)
    )
    return rc, msg_type.value, seq.value, bytes(payload[: length.value])


def test_crc_check_value():
    assert LIB.sashil_crc16(_buf(b"123456789"), 9) == 0x29B1  # CRC-16/CCITT-FALSE's check value


@settings(max_examples=300, deadline=None)
@given(msg=messages(32), seq=st.integers(0, 0xFFFF))
def test_c_frames_are_the_python_codecs_bytes_and_decode_back(msg, seq):
    msg_type, payload = encode_payload(msg)
    frame = c_encode(msg_type, seq, payload)
    assert frame == encode_frame(msg, seq)
    assert c_decode(frame[:-1]) == (0, msg_type, seq, payload)


def test_a_full_254_byte_cobs_run_matches_the_python_encoder():
    # a payload cannot reach 254 bytes, so exercise COBS directly on a long run without zeros
    from sashil.drivers.serial_codec import cobs_encode

    LIB.sashil_cobs_encode.argtypes = (ctypes.POINTER(U8), ctypes.c_size_t, ctypes.POINTER(U8), ctypes.c_size_t)
    LIB.sashil_cobs_encode.restype = ctypes.c_size_t
    for data in (bytes(range(1, 255)), bytes(range(1, 255)) + b"\x07", b"\x00" * 3, b"", bytes(300 * [5])):
        out = (U8 * 400)()
        n = LIB.sashil_cobs_encode(_buf(data), len(data), out, len(out))
        assert bytes(out[:n]) == cobs_encode(data)
        assert LIB.sashil_cobs_encode(_buf(data), len(data), out, max(n - 1, 0)) == 0  # too small: refused


@settings(max_examples=500, deadline=None)
@given(garbage=st.binary(max_size=120))
def test_any_bytes_are_a_frame_or_a_counted_error_never_more(garbage):
    rc, *_ = c_decode(garbage.replace(b"\x00", b"\x01"))
    assert rc in (0, -1, -2, -3, -4)


@settings(max_examples=200, deadline=None)
@given(pieces=st.lists(st.one_of(st.binary(max_size=60), messages(32).map(lambda m: encode_frame(m, 7))), max_size=8))
def test_the_c_stream_decoder_counts_as_the_python_one(pieces):
    stream = b"".join(pieces) + b"\x00"
    state = firmware.StreamState()
    LIB.sashil_stream_init(ctypes.byref(state))
    msg_type, seq, length, payload = U8(), ctypes.c_uint16(), U8(), (U8 * 32)()
    good = []
    for byte in stream:
        rc = LIB.sashil_stream_feed(
            ctypes.byref(state), byte, ctypes.byref(msg_type), ctypes.byref(seq), payload, ctypes.byref(length)
        )
        if rc == 1:
            good.append((msg_type.value, seq.value, bytes(payload[: length.value])))
    python = StreamDecoder()
    decoded = python.feed(stream)
    assert [(encode_payload(m)[0], s, encode_payload(m)[1]) for s, m in decoded] == good
    assert state.frames == python.counters.frames
    assert state.bad_frames == python.counters.bad_frames
