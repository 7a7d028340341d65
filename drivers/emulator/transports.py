"""The emulator's links, device side: sashil serial frames or SLCAN on a pty, or a python-can bus.

Each transport moves :mod:`sashil.drivers.messages` between the device logic and the host:
``receive(timeout_s)`` -> [(seq, message)], ``send(seq, message, corrupt)``, ``close()``.
``corrupt`` asks for a damaged frame: on serial one byte is flipped so the host's CRC check
rejects it; on CAN a frame with a bad CRC never leaves the bus controllers (they discard it and
retransmit or drop it), so the frame is not delivered and the host sees a missing sample.
"""

from __future__ import annotations

import errno
import os
import select
import tty
from abc import ABC, abstractmethod
from collections.abc import Iterable
from dataclasses import dataclass

import can

from sashil.drivers import can_codec
from sashil.drivers.emulator.wire import Payload, WireBytes, WireCan
from sashil.drivers.serial_codec import StreamDecoder, encode_frame
from sashil.drivers.slcan_codec import SlcanAdapter, format_frame
from sashil.errors import DriverError


def check_link_free(link: str) -> None:
    """Raise DriverError unless ``link`` is free: absent, or a symlink whose pty is gone."""
    if os.path.islink(link):
        target = os.readlink(link)
        if os.path.exists(link):  # the pty it names is alive: another emulator serves it
            raise DriverError(
                f"--link {link}: in use (it points to {target}, a live pty); stop that emulator or choose another"
            )
        return
    if os.path.exists(link):
        raise DriverError(f"--link {link}: a file is there that is not an emulator's link; choose another path")


@dataclass
class Pty:
    """A pseudo-terminal: the emulator keeps the master; the host opens ``path`` (the slave)."""

    master_fd: int
    slave_fd: int  # held open so the master never sees a hang-up between host sessions
    path: str
    link: str | None = None

    @classmethod
    def open(cls, link: str | None = None) -> Pty:
        """A new pty; ``link``: a symlink to it. A link that points to a live pty (another emulator's)
        is refused; a stale one (its pty gone) is replaced; any other file there is refused."""
        if link:
            check_link_free(link)
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line editing: bytes pass unchanged
        os.set_blocking(master, False)
        path = os.ttyname(slave)
        if link:
            if os.path.islink(link):
                os.unlink(link)
            os.symlink(path, link)
        return cls(master, slave, path, link)

    def close(self) -> None:
        for fd in (self.master_fd, self.slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass
        self.master_fd = self.slave_fd = -1
        if self.link and os.path.islink(self.link):
            try:
                os.unlink(self.link)
            except OSError:
                pass


class DeviceTransport(ABC):
    """One link of the emulated device."""

    description = "link"

    def __init__(self, raw: bool = False) -> None:
        self.raw = raw  # hand the board the wire (WireBytes/WireCan) instead of decoded messages
        self.tx_frames = 0
        self.tx_dropped = 0  # frames the link could not take (host not reading, channel closed)
        self.tx_corrupted = 0

    @property
    @abstractmethod
    def bad_frames(self) -> int:
        """Frames from the host that could not be decoded."""

    @abstractmethod
    def receive(self, timeout_s: float) -> list[tuple[int, Payload]]: ...

    @abstractmethod
    def send(self, seq: int, msg: Payload, corrupt: bool = False) -> None: ...

    @abstractmethod
    def close(self) -> None: ...


class _PtyTransport(DeviceTransport):
    def __init__(self, pty: Pty, raw: bool = False):
        super().__init__(raw)
        self.pty = pty
        self.description = pty.path

    def _read(self, timeout_s: float) -> bytes:
        fd = self.pty.master_fd
        if fd < 0:
            return b""
        ready, _, _ = select.select([fd], [], [], max(timeout_s, 0.0))
        if not ready:
            return b""
        try:
            return os.read(fd, 4096)
        except BlockingIOError:
            return b""
        except OSError as err:
            if err.errno == errno.EIO:  # no slave side open (cannot happen while we hold it)
                return b""
            raise

    def _write(self, data: bytes) -> bool:
        try:
            os.write(self.pty.master_fd, data)
            return True
        except BlockingIOError:  # the host is not reading: the frame is lost, as on a real UART
            self.tx_dropped += 1
            return False

    def close(self) -> None:
        self.pty.close()


class SerialPtyTransport(_PtyTransport):
    """sashil serial frames (serial_codec) on a pty."""

    def __init__(self, pty: Pty, raw: bool = False):
        super().__init__(pty, raw)
        self.decoder = StreamDecoder()

    @property
    def bad_frames(self) -> int:
        return self.decoder.counters.bad_frames

    def receive(self, timeout_s: float) -> list[tuple[int, Payload]]:
        data = self._read(timeout_s)
        if not data:
            return []
        if self.raw:
            return [(0, WireBytes(data))]
        return list(self.decoder.feed(data))

    def send(self, seq: int, msg: Payload, corrupt: bool = False) -> None:
        if isinstance(msg, WireCan):
            raise TypeError("a serial link carries no CAN frames")
        frame = msg.data if isinstance(msg, WireBytes) else encode_frame(msg, seq)
        if corrupt:
            frame = corrupt_frame(frame)
            self.tx_corrupted += 1
        if self._write(frame):
            self.tx_frames += 1


def corrupt_frame(frame: bytes) -> bytes:
    """``frame`` with one byte in its middle changed (never into the 0x00 delimiter)."""
    damaged = bytearray(frame)
    index = (len(frame) - 1) // 2
    flipped = damaged[index] ^ 0x5A
    damaged[index] = flipped if flipped else damaged[index] ^ 0xA5
    return bytes(damaged)


def can_frames(msg: Payload, seq: int) -> list[tuple[int, bytes]]:
    """The CAN frames carrying ``msg`` (a board's own frame passes unchanged)."""
    if isinstance(msg, WireCan):
        return [(msg.can_id, msg.data)]
    if isinstance(msg, WireBytes):
        raise TypeError("a CAN link carries no serial bytes")
    return can_codec.encode(msg, seq)


class _CanSide:
    """What a CAN transport does with the frames on the bus: decode them, or hand them over raw."""

    raw: bool
    decoder: can_codec.CanDecoder

    def _on_bus(self, frames: Iterable[tuple[int, bytes]]) -> list[tuple[int, Payload]]:
        if self.raw:
            return [(0, WireCan(can_id, data)) for can_id, data in frames]
        out: list[tuple[int, Payload]] = []
        for can_id, data in frames:
            got = self.decoder.feed(can_id, data)
            if got is not None:
                out.append(got)
        return out


class SlcanPtyTransport(_CanSide, _PtyTransport):
    """An SLCAN (LAWICEL) adapter on a pty with the rig on its CAN bus."""

    def __init__(self, pty: Pty, raw: bool = False):
        super().__init__(pty, raw)
        self.adapter = SlcanAdapter()
        self.decoder = can_codec.CanDecoder()

    @property
    def bad_frames(self) -> int:
        return self.decoder.counters.bad_frames + self.adapter.errors

    def receive(self, timeout_s: float) -> list[tuple[int, Payload]]:
        data = self._read(timeout_s)
        if not data:
            return []
        replies, frames = self.adapter.feed(data)
        if replies:
            self._write(replies)
        return self._on_bus(((can_id, payload) for can_id, payload, extended in frames if not extended))

    def send(self, seq: int, msg: Payload, corrupt: bool = False) -> None:
        if corrupt:
            self.tx_corrupted += 1
            return  # a bad-CRC frame never reaches the host's CAN controller
        if not self.adapter.is_open:
            self.tx_dropped += 1  # adapter channel closed: bus traffic is not forwarded
            return
        lines = b"".join(format_frame(can_id, data) for can_id, data in can_frames(msg, seq))
        if self._write(lines):
            self.tx_frames += 1


class VirtualCanTransport(_CanSide, DeviceTransport):
    """The rig as a node on python-can's in-process ``virtual`` bus (tests)."""

    def __init__(self, channel: str, raw: bool = False):
        super().__init__(raw)
        self.channel = channel
        self.description = f"virtual:{channel}"
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.decoder = can_codec.CanDecoder()

    @property
    def bad_frames(self) -> int:
        return self.decoder.counters.bad_frames

    def receive(self, timeout_s: float) -> list[tuple[int, Payload]]:
        frames = []
        frame = self.bus.recv(max(timeout_s, 0.0))
        while frame is not None:
            if not frame.is_extended_id:
                frames.append((frame.arbitration_id, bytes(frame.data)))
            frame = self.bus.recv(0.0)
        return self._on_bus(frames)

    def send(self, seq: int, msg: Payload, corrupt: bool = False) -> None:
        if corrupt:
            self.tx_corrupted += 1
            return
        for can_id, data in can_frames(msg, seq):
            self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        self.tx_frames += 1

    def close(self) -> None:
        self.bus.shutdown()
