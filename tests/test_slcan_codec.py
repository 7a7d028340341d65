"""LAWICEL SLCAN adapter side: frame lines, the command set python-can uses, errors."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sashil.drivers.slcan_codec import ERROR, OK, SlcanAdapter, SlcanError, format_frame, parse_frame


def test_frame_lines():
    assert format_frame(0x111, bytes.fromhex("050040e201e80302")) == b"t1118050040E201E80302\r"
    assert format_frame(0x1F1, b"\x01") == b"t1F1101\r"
    assert format_frame(0x12345678, b"", extended=True) == b"T123456780\r"
    assert parse_frame(b"t1F1101") == (0x1F1, b"\x01", False)


@pytest.mark.parametrize("line", [b"t1F1201", b"t1F11", b"tZZZ0", b"x1230", b"t1239" + b"00" * 9, b"t8001" + b"00"])
def test_malformed_frame_lines(line):
    with pytest.raises(SlcanError):
        parse_frame(line)


@given(st.integers(0, 0x7FF), st.binary(max_size=8), st.booleans())
def test_frame_line_round_trip(can_id, data, extended):
    line = format_frame(can_id, data, extended)
    assert line.endswith(b"\r")
    assert parse_frame(line[:-1]) == (can_id, data, extended)


def test_python_can_open_sequence():
    """python-can's slcanBus(bitrate=1e6): C, S8, (empty), O, O — then frames are accepted."""
    adapter = SlcanAdapter()
    replies, frames = adapter.feed(b"C\rS8\r\rO\rO\r")
    assert replies == OK * 5 and frames == []
    assert adapter.is_open and adapter.bitrate == 1_000_000
    replies, frames = adapter.feed(b"t1F1101\rt10")  # second frame split over two reads
    assert replies == b"z\r" and frames == [(0x1F1, b"\x01", False)]
    replies, frames = adapter.feed(b"050000000000\r")
    assert replies == b"z\r" and frames == [(0x100, bytes(5), False)]
    assert adapter.feed(b"V\rN\rF\r")[0] == b"V1013\rNSASH\rF00\r"
    assert adapter.errors == 0


def test_adapter_refuses_what_a_lawicel_adapter_refuses():
    adapter = SlcanAdapter()
    assert adapter.feed(b"t1F1101\r") == (ERROR, [])  # channel closed
    assert adapter.feed(b"S9\r")[0] == ERROR  # no such bit-rate code here
    adapter.feed(b"O\r")
    assert adapter.feed(b"S6\r")[0] == ERROR  # bit rate only while closed
    assert adapter.feed(b"t1F12\r")[0] == ERROR  # malformed frame
    assert adapter.feed(b"Q\r")[0] == ERROR
    assert adapter.errors == 5
    adapter.feed(b"C\r")
    assert not adapter.is_open
    replies, _ = adapter.feed(b"G" * 40)  # garbage with no CR is dropped
    assert replies == ERROR
