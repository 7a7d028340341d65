"""The tests' board port (tests/board_port.py): a wait consumes only up to the message it returns.

pyserial's ``loop://`` hands back what was written to it, so a write of two frames stands for a
board whose two messages a slowed host reads in one chunk; the frames are there before the first
read, so nothing here waits on the clock.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from board_port import Port

from sashil.drivers.messages import Sample, Status, Version
from sashil.drivers.serial_codec import encode_frame

DRIVEN = Sample(10_000, 0, 0, 0.5, 0)
TRIP = Status(0x01)


@pytest.fixture
def port() -> Iterator[Port]:
    port = Port("loop://")
    try:
        yield port
    finally:
        port.close()


def board_sends(port: Port, *messages: object) -> None:
    """The board's messages, written in one go: the next read returns them all in one chunk."""
    port.serial.write(b"".join(encode_frame(msg, seq) for seq, msg in enumerate(messages, 1)))  # type: ignore[arg-type]


def test_the_message_after_the_one_waited_for_in_the_same_chunk_is_kept_for_the_next_wait(port):
    board_sends(port, DRIVEN, TRIP)
    assert port.wait(Sample, 1.0) == DRIVEN
    assert port.unread == port.unread.__class__([TRIP])  # decoded in the first read, not yet consumed
    assert port.wait(Status, 0.0) == TRIP  # no time left to read: the wait finds it among the decoded


def test_a_wait_consumes_the_messages_before_the_kind_it_waits_for(port):
    board_sends(port, Version(2, 4096, 1.0), DRIVEN, TRIP, Sample(20_000, 0, 0, 0.0, 1))
    assert port.wait(Status, 1.0) == TRIP
    assert port.wait(Sample, 0.0) == Sample(20_000, 0, 0, 0.0, 1)  # the one after the Status, not DRIVEN
    assert port.got[:2] == [Version(2, 4096, 1.0), DRIVEN]  # read and kept for a failure's message
    with pytest.raises(AssertionError, match=r"no Version from the board within 0\.0 s"):
        port.wait(Version, 0.0)
