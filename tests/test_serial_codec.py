"""Serial protocol: CRC and COBS vectors, byte-exact frames, round trips, the stream decoder."""

from __future__ import annotations

import binascii

import message_strategies
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sashil.drivers.messages import (
    CMD_ENABLE,
    CURRENT_LSB_A,
    ROAD_SPEED_LSB_RAD_S,
    Command,
    Hello,
    Sample,
)
from sashil.drivers.serial_codec import (
    MAX_FRAME,
    FrameError,
    StreamDecoder,
    cobs_decode,
    cobs_encode,
    crc16_ccitt,
    decode_frame,
    encode_frame,
)


# --- CRC-16/CCITT-FALSE ------------------------------------------------------------------------
@pytest.mark.parametrize(
    "data, crc",
    [
        (b"123456789", 0x29B1),
        (b"", 0xFFFF),
        (b"A", 0xB915),
        (bytes(range(256)), binascii.crc_hqx(bytes(range(256)), 0xFFFF)),
    ],
)
def test_crc16_ccitt_false_vectors(data, crc):
    assert crc16_ccitt(data) == crc


@given(st.binary(max_size=64))
def test_crc_matches_stdlib_crc_hqx(data):
    assert crc16_ccitt(data) == binascii.crc_hqx(data, 0xFFFF)


# --- COBS (Cheshire & Baker examples) ----------------------------------------------------------
@pytest.mark.parametrize(
    "raw, encoded",
    [
        ("00", "0101"),
        ("0000", "010101"),
        ("11220033", "0311220233"),
        ("11223344", "0511223344"),
        ("11000000", "0211010101"),
        ("", "01"),
    ],
)
def test_cobs_vectors(raw, encoded):
    assert cobs_encode(bytes.fromhex(raw)).hex() == encoded
    assert cobs_decode(bytes.fromhex(encoded)).hex() == raw


def test_cobs_long_runs():
    run = bytes(range(1, 255))  # 254 non-zero bytes: one full block, no trailing code
    assert cobs_encode(run) == b"\xff" + run
    assert cobs_encode(b"\x00" + run) == b"\x01\xff" + run
    assert cobs_encode(bytes(range(1, 256))) == b"\xff" + run + b"\x02\xff"


@given(st.binary(max_size=600))
def test_cobs_round_trip_and_no_zero(data):
    encoded = cobs_encode(data)
    assert 0 not in encoded
    assert cobs_decode(encoded) == data


def test_cobs_rejects_overrun_block():
    with pytest.raises(FrameError) as err:
        cobs_decode(b"\x05\x11\x22")
    assert err.value.kind == "cobs"


# --- byte-exact frames -------------------------------------------------------------------------
def test_command_frame_bytes():
    # body: type 02, seq 0001, len 03, current 1000 counts (0.5 A), flags 01; CRC 0x03B3 over it
    body = bytes.fromhex("02010003e80301")
    assert binascii.crc_hqx(body, 0xFFFF) == 0x03B3
    frame = encode_frame(Command(0.5, CMD_ENABLE), 1)
    assert frame.hex(" ") == "03 02 01 07 03 e8 03 01 b3 03 00"
    assert decode_frame(frame[:-1]) == (1, Command(0.5, CMD_ENABLE))


def test_sample_frame_bytes():
    sample = Sample(1000, -57, 0, 0.25, 2, arm_edge_age_us=300, arm_edge_dir=1)
    # type 01 seq 0007 len 14 | time e8030000 | arm c7ffffff | road 00000000 | current f401 | flags 02
    # | arm edge age 2c01 (300 us) | road edge age ffff (none) | directions 01 (arm up) | crc
    body = bytes.fromhex("01070014e8030000c7ffffff00000000f401022c01ffff01")
    assert binascii.crc_hqx(body, 0xFFFF) == 0x3BCA
    frame = encode_frame(sample, 7)
    assert frame.hex(" ") == "03 01 07 04 14 e8 03 01 05 c7 ff ff ff 01 01 01 0b f4 01 02 2c 01 ff ff 01 ca 3b 00"
    assert decode_frame(frame[:-1]) == (7, sample)
    assert len(frame) == 28  # the link budget's serial Sample (protocol.md)


def test_sample_edges_decode_direction_only_with_an_edge():
    # arm: an edge 0 us old, count went down (bit 0 clear); road: 65534 us old, up (bit 1 set)
    sample = Sample(1000, -57, 0, 0.25, 2, 0, -1, 65534, 1)
    assert decode_frame(encode_frame(sample, 7)[:-1]) == (7, sample)
    # no edge recently: the direction bits mean nothing and decode as 0; ages past the field saturate
    odd = Sample(5, 1, 2, 0.0, 0, 70000, 1, -3, -1)
    assert decode_frame(encode_frame(odd, 1)[:-1]) == (1, Sample(5, 1, 2, 0.0, 0))


def test_bad_crc_and_length_are_told_apart():
    frame = bytearray(encode_frame(Hello(1), 3)[:-1])
    body = cobs_decode(bytes(frame))
    with pytest.raises(FrameError) as err:
        decode_frame(cobs_encode(body[:-2] + bytes([body[-2] ^ 1, body[-1]])))
    assert err.value.kind == "crc"
    short = body[:4]
    with pytest.raises(FrameError) as err:
        decode_frame(cobs_encode(short + crc16_ccitt(short).to_bytes(2, "little")))
    assert err.value.kind == "length"
    wrong_type = bytes([0x7F, 0, 0, 0])
    with pytest.raises(FrameError) as err:
        decode_frame(cobs_encode(wrong_type + crc16_ccitt(wrong_type).to_bytes(2, "little")))
    assert err.value.kind == "unknown_type"


# --- round trips ------------------------------------------------------------------------------
messages = message_strategies.messages(32)


def assert_close(decoded, msg):
    assert type(decoded) is type(msg)
    for name in msg.__slots__:
        a, b = getattr(decoded, name), getattr(msg, name)
        if isinstance(b, float):
            lsb = ROAD_SPEED_LSB_RAD_S if name == "speed_rad_s" else CURRENT_LSB_A
            assert abs(a - b) <= lsb / 2 + 1e-12, name
        else:
            assert a == b, name


@given(messages, st.integers(0, 65535))
def test_frame_round_trip(msg, seq):
    frame = encode_frame(msg, seq)
    assert frame.endswith(b"\x00") and 0 not in frame[:-1] and len(frame) <= MAX_FRAME
    got_seq, decoded = decode_frame(frame[:-1])
    assert got_seq == seq
    assert_close(decoded, msg)
    assert encode_frame(decoded, seq) == frame  # quantised values encode to the same bytes


# --- stream decoder ---------------------------------------------------------------------------
@settings(max_examples=50)
@given(st.lists(messages, min_size=1, max_size=8), st.data())
def test_split_stream_decodes_every_frame(msgs, data):
    stream = b"".join(encode_frame(m, i) for i, m in enumerate(msgs))
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    decoder = StreamDecoder()
    got = []
    for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += decoder.feed(stream[a:b])
    assert [seq for seq, _ in got] == list(range(len(msgs)))
    assert decoder.counters.frames == len(msgs) and decoder.counters.bad_frames == 0


@settings(max_examples=50)
@given(
    st.lists(
        st.tuples(messages, st.binary(min_size=1, max_size=20).filter(lambda b: 0 not in b)), min_size=1, max_size=6
    )
)
def test_garbage_before_frames_costs_nothing_but_is_counted(items):
    """Garbage ended by a delimiter is one bad frame; the frame after it still decodes."""
    stream = b"".join(garbage + b"\x00" + encode_frame(m, i) for i, (m, garbage) in enumerate(items))
    decoder = StreamDecoder()
    got = decoder.feed(stream)
    assert [seq for seq, _ in got] == list(range(len(items)))
    assert decoder.counters.bad_frames == len(items)


def test_garbage_glued_to_a_frame_costs_that_frame_only():
    good = [encode_frame(Hello(1), i) for i in range(3)]
    decoder = StreamDecoder()
    got = decoder.feed(good[0] + b"\x13\x37" + good[1] + good[2])
    assert [seq for seq, _ in got] == [0, 2]
    assert decoder.counters.bad_frames == 1


def test_bad_crc_in_stream_is_counted_and_skipped():
    frames = [encode_frame(Command(0.1 * i), i) for i in range(5)]
    bad = bytearray(frames[2])
    bad[5] ^= 0x40  # a flipped bit inside the payload
    decoder = StreamDecoder()
    got = decoder.feed(b"".join(frames[:2]) + bytes(bad) + b"".join(frames[3:]))
    assert [seq for seq, _ in got] == [0, 1, 3, 4]
    assert decoder.counters.crc + decoder.counters.cobs == 1


def test_overlong_run_without_delimiter_is_dropped_then_resyncs():
    decoder = StreamDecoder()
    assert decoder.feed(b"\x11" * (MAX_FRAME + 5)) == []
    assert decoder.counters.overflow == 1
    got = decoder.feed(b"\x22" * 3 + b"\x00" + encode_frame(Hello(1), 9))
    assert got == [(9, Hello(1))]
    assert decoder.counters.discarded_bytes == MAX_FRAME + 5 + 4
