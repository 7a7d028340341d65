"""CAN protocol: the DBC loads, frames are byte-exact, round trips, sample pairing, bus load."""

from __future__ import annotations

import message_strategies
from hypothesis import given
from hypothesis import strategies as st

from sashil.drivers import can_codec
from sashil.drivers.can_codec import CanDecoder, database, encode, frame_bits
from sashil.drivers.messages import Command, RoadSpeed, Sample


def test_dbc_loads_with_the_protocol_messages():
    db = database()
    names = {m.frame_id: (m.name, m.length) for m in db.messages}
    assert names == {
        0x100: ("Command", 5),
        0x110: ("SampleA", 8),
        0x111: ("SampleB", 8),
        0x112: ("SampleEdges", 5),
        0x120: ("RoadSpeed", 4),
        0x180: ("Status", 6),
        0x1F0: ("Configure", 5),
        0x1F1: ("Hello", 1),
        0x1F2: ("Version", 7),
    }
    assert db.get_message_by_name("SampleB").get_signal_by_name("CurrentMeas").unit == "A"
    assert db.get_message_by_name("SampleB").get_signal_by_name("CurrentMeas").scale == 0.0005


def test_sample_frames_bytes():
    frames = encode(Sample(123456, -57, 4097, 0.5, 2, 999, -1, 12, 1), seq=5)
    assert frames == [
        (0x110, bytes.fromhex("c7ffffff01100000")),  # arm -57, road 4097 (int32 LE)
        (0x112, bytes.fromhex("e7030c0002")),  # arm edge 999 us ago, road 12 us ago; bit 1: road went up
        (0x111, bytes.fromhex("050040e201e80302")),  # seq 5, time 0x01E240, current 1000 counts, flags 2
    ]


def test_command_frame_bytes_and_clamping():
    assert encode(Command(0.5, 1), seq=0x1234) == [(0x100, bytes.fromhex("3412e80301"))]
    assert encode(Command(-1.0, 1), seq=0) == [(0x100, bytes.fromhex("0000000001"))]  # never negative
    assert encode(Command(float("nan"), 1), seq=0) == [(0x100, bytes.fromhex("0000000001"))]


def test_dbc_decodes_what_the_codec_encodes_in_physical_units():
    db = database()
    frames = encode(Sample(10, 1, 2, -0.25, 0x82, 40, 1, 65535, 0), seq=9)
    frame_id, data = frames[1]
    assert db.decode_message(frame_id, data) == {"ArmEdgeAge": 40, "RoadEdgeAge": 65535, "EdgeDirs": 1}
    frame_id, data = frames[2]
    assert db.decode_message(frame_id, data) == {
        "SampleSeq": 9,
        "DeviceTimeUs": 10,
        "CurrentMeas": -0.25,
        "SampleFlags": 0x82,
    }
    frame_id, data = encode(RoadSpeed(-1.5))[0]
    assert abs(db.decode_message(frame_id, data)["RoadSpeedCmd"] + 1.5) < 1e-9


messages = message_strategies.messages(24)


@given(messages, st.integers(0, 65535))
def test_round_trip_through_the_dbc(msg, seq):
    decoder = CanDecoder()
    results = [decoder.feed(frame_id, data) for frame_id, data in encode(msg, seq)]
    assert results[:-1] == [None] * (len(results) - 1)
    got_seq, decoded = results[-1]
    if isinstance(msg, (Sample, Command)):
        assert got_seq == seq
    assert type(decoded) is type(msg)
    assert encode(decoded, seq) == encode(msg, seq)  # equal after quantisation
    assert decoder.counters.bad_frames == 0


def test_sample_b_without_a_is_counted_not_invented():
    decoder = CanDecoder()
    (a_id, a_data), (e_id, e_data), (b_id, b_data) = encode(Sample(1, 2, 3, 0.0, 0), seq=1)
    assert decoder.feed(b_id, b_data) is None
    assert decoder.feed(a_id, a_data) is None
    assert decoder.feed(a_id, a_data) is None  # a second A overwrites the first: one unpaired
    assert decoder.feed(e_id, e_data) is None
    assert decoder.feed(b_id, b_data) == (1, Sample(1, 2, 3, 0.0, 0))
    assert decoder.counters.unpaired == 2
    # the edges frame lost: the B that follows completes nothing
    assert decoder.feed(a_id, a_data) is None
    assert decoder.feed(b_id, b_data) is None
    assert decoder.feed(e_id, e_data) is None  # edges without their A
    assert decoder.counters.unpaired == 4
    assert decoder.feed(0x7FF, b"") is None and decoder.counters.unknown_id == 1
    assert decoder.feed(can_codec.ID_COMMAND, b"\x00") is None and decoder.counters.bad_length == 1


def test_frame_bits_by_hand():
    # 8 data bytes: 47 + 64 = 111 bits, worst-case stuffing floor((34 + 64 - 1) / 4) = 24 -> 135
    assert frame_bits(8, worst_case_stuffing=False) == 111
    assert frame_bits(8) == 135
    assert frame_bits(5) == 87 + 18
