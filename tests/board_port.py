"""The host's end of a board's serial port, for tests that talk to a board message by message.

A read can bring several messages at once (a host slowed by a busy machine reads a board's Sample
and the Status after it in one chunk), so every decoded message waits in ``unread`` until a wait
consumes it: a wait looks at what was already decoded before it reads again.
"""

from __future__ import annotations

import time
from collections import deque
from pathlib import Path

import serial

from sashil.drivers.messages import Message
from sashil.drivers.serial_codec import StreamDecoder, encode_frame


class Port:
    """A serial port (a path or a pyserial URL) with the project's codec: send messages, wait for a
    kind of answer."""

    def __init__(self, url: str | Path, read_timeout_s: float = 0.02):
        self.serial = serial.serial_for_url(str(url), timeout=read_timeout_s)
        self.decoder = StreamDecoder()
        self.seq = 0
        self.got: list[Message] = []  # every message decoded, in order (for a failure's message)
        self.unread: deque[Message] = deque()  # decoded, not yet consumed by a wait

    def send(self, *messages: Message) -> None:
        for msg in messages:
            self.seq += 1
            self.serial.write(encode_frame(msg, self.seq))

    def wait(self, kind: type, timeout_s: float, resend: tuple[Message, ...] = ()) -> Message:
        """The next ``kind`` not yet consumed; the messages before it are consumed, those after it
        stay for the next wait. ``resend`` goes out again after each read that brought nothing."""
        deadline = time.monotonic() + timeout_s
        while True:
            while self.unread:
                msg = self.unread.popleft()
                if isinstance(msg, kind):
                    return msg
            if time.monotonic() >= deadline:
                raise AssertionError(f"no {kind.__name__} from the board within {timeout_s} s; got {self.got[-5:]}")
            data = self.serial.read(4096)
            if not data and resend:
                self.send(*resend)
            for _, msg in self.decoder.feed(data):
                self.got.append(msg)
                self.unread.append(msg)

    def close(self) -> None:
        self.serial.close()
