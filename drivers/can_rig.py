"""The CAN backend: the rig's interface board on a CAN bus (python-can), frames of ``sashil.dbc``.

The bus is opened with ``can.Bus(interface=driver.can_interface, channel=driver.port,
bitrate=driver.can_bitrate, **driver.can_options)``, so socketcan, pcan, kvaser, slcan (a serial
USB-CAN adapter or the emulator's pty) and virtual all work from the config. For ``slcan`` the
adapter's reset pause ``sleep_after_open`` defaults to 0 s here (python-can's 2 s is for adapters
that reboot when the port opens; set ``driver.can_options: {sleep_after_open: 2}`` for those).
"""

from __future__ import annotations

import fcntl
import os
import select
import time
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import can

from sashil.config.parts import RigParts
from sashil.drivers.can_codec import RIG_IDS, CanDecoder, encode
from sashil.drivers.link_rig import LINK_READS, PROBE_S, LinkRig, LinkSettings, error_reason, read_raw
from sashil.drivers.messages import PROTOCOL_VERSION, Hello, Message, Version
from sashil.drivers.serial_codec import StreamDecoder, encode_frame
from sashil.errors import DriverError, DriverIOError


class BufferedPort:
    """A pyserial port whose ``read`` is served from one bulk read of everything waiting.

    python-can's slcan backend reads a line with one ``read(1)`` per byte (a system call each);
    this keeps its protocol code and halves the receive cost of a 2-frame sample. Everything else
    is the port's own.
    """

    def __init__(self, port: Any):
        self._port = port
        self._data = bytearray()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._port, name)

    def __setattr__(self, name: str, value: Any) -> None:
        if name in ("_port", "_data"):
            object.__setattr__(self, name, value)
        else:
            setattr(self._port, name, value)

    @property
    def in_waiting(self) -> int:
        return len(self._data) + self._port.in_waiting

    def read(self, size: int = 1) -> bytes:
        if len(self._data) < size:
            waiting = self._port.in_waiting
            if waiting:
                self._data += self._port.read(waiting)
        if len(self._data) < size and self._port.timeout != 0:
            self._data += self._port.read(size - len(self._data))
        out = bytes(self._data[:size])
        del self._data[:size]
        return out

    def reset_input_buffer(self) -> None:
        self._data.clear()
        self._port.reset_input_buffer()


class CanRig(LinkRig):
    """The rig over CAN (``driver.name: can``)."""

    name = "can"
    carries_can_frames = True
    device_time_bits = 24

    def __init__(
        self,
        settings: LinkSettings,
        interface: str = "slcan",
        bitrate: int = 1_000_000,
        options: dict[str, Any] | None = None,
    ):
        super().__init__(settings)
        if not settings.port:
            raise DriverError("driver.port: the can backend needs a channel (--port, e.g. can0 or a slcan tty)")
        self.interface = interface
        self.bitrate = int(bitrate)
        self.options = dict(options or {})
        if interface == "slcan":
            self.options.setdefault("sleep_after_open", 0)
        self.decoder = CanDecoder()
        #: frame trace (``sashil.recording.can_trace.CanTrace.put``): gets every frame sent and received
        self.frame_sink: Callable[[can.Message], None] | None = None
        self._bus: Any = None
        self._lock_fd: int | None = None  # the SLCAN tty, locked for this process (_lock_tty)
        self._fd: int | None = None

    #: the config keys the backend is built from (:meth:`from_parts`)
    reads: ClassVar[Mapping[str, str]] = {
        **LINK_READS,
        "can_interface": "driver.can_interface",
        "can_bitrate": "driver.can_bitrate",
        "can_options": "driver.can_options",
    }

    @classmethod
    def from_parts(cls, parts: RigParts) -> CanRig:
        values = parts.values
        return cls(LinkSettings(values), values["can_interface"], values["can_bitrate"], dict(values["can_options"]))

    def describe(self) -> str:
        return f"can {self.interface}:{self.settings.port}"

    def codec_counters(self) -> dict[str, int]:
        return self.decoder.counters.as_dict()

    # link ------------------------------------------------------------------------------------
    def _lock_tty(self) -> None:
        """Take the SLCAN adapter's tty for this process alone before the bus opens it (python-can's
        slcan sends the adapter its open commands, which would disturb a host already using it): an
        advisory exclusive lock, the one pyserial's ``exclusive=True`` takes, so that a second sashil
        on the same port, serial or CAN, is refused with one line."""
        port = self.settings.port
        if self.interface != "slcan" or not port or not os.path.exists(port):
            return
        try:
            fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return  # python-can reports what is wrong with the port
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise DriverError(
                f"{self.describe()}: cannot open the CAN bus ({port} is in use by another process)"
            ) from None
        self._lock_fd = fd

    def _unlock_tty(self) -> None:
        fd, self._lock_fd = self._lock_fd, None
        if fd is not None:
            os.close(fd)

    def _open(self) -> None:
        filters = [{"can_id": can_id, "can_mask": 0x7FF, "extended": False} for can_id in RIG_IDS]
        self._lock_tty()
        try:
            self._bus = can.Bus(
                interface=self.interface,
                channel=self.settings.port,
                bitrate=self.bitrate,
                can_filters=filters,
                **self.options,
            )
        except can.CanInterfaceNotImplementedError as err:
            self._unlock_tty()
            raise DriverError(
                f"driver.can_interface: {self.interface!r} is not available ({error_reason(err)})"
            ) from None
        except (can.CanError, ValueError, TypeError, OSError, ImportError) as err:
            self._unlock_tty()
            raise DriverError(f"{self.describe()}: cannot open the CAN bus ({error_reason(err)})") from None
        self._fd = None
        port = getattr(self._bus, "serialPortOrig", None)
        if self.interface == "slcan" and port is not None:
            # python-can's slcan reads byte by byte with the port's 1 ms timeout, so recv(0) blocks
            # up to 1 ms on an empty port; with timeout 0 it returns at once and this backend waits
            # in select() on the port instead (measured: round trip p50 1.5 ms -> see bench_link).
            # Its one read(1) system call per byte is served from a buffer filled in one read.
            port.timeout = 0
            self._bus.serialPortOrig = BufferedPort(port)
            self._fd = self._bus.fileno()

    def _other_protocol(self) -> str | None:
        """A board that speaks sashil serial frames on the SLCAN adapter's tty (the serial driver's
        link): it stays silent to SLCAN lines, so it is asked a Hello in a serial frame and answers
        Version in one."""
        port = getattr(self._bus, "serialPortOrig", None)
        if self.interface != "slcan" or port is None:
            return None

        def answered(data: bytes) -> bool:
            return any(isinstance(msg, Version) for _, msg in StreamDecoder().feed(data))

        try:
            port.write(b"\x00" + encode_frame(Hello(PROTOCOL_VERSION), 0))  # 0x00 first: a frame of its own
            heard = read_raw(port, PROBE_S, answered)
        except (OSError, ValueError):
            return None
        if answered(heard):
            return "sashil serial frames, not the SLCAN lines of a CAN adapter (use --driver serial)"
        return None

    def _send(self, seq: int, msg: Message) -> None:
        sink = self.frame_sink
        try:
            for frame_id, data in encode(msg, seq):
                frame = can.Message(arbitration_id=frame_id, data=data, is_extended_id=False)
                self._bus.send(frame)
                if sink is not None:
                    frame.timestamp, frame.is_rx = time.time(), False
                    sink(frame)
        except (can.CanError, OSError, ValueError) as err:
            raise DriverIOError(f"{self.describe()}: link lost on send ({error_reason(err)})") from None

    def _receive(self, timeout_s: float) -> list[tuple[int, Message]]:
        out: list[tuple[int, Message]] = []
        decoder = self.decoder
        sink = self.frame_sink
        try:
            if self._fd is not None:
                frame = self._recv_waiting()
                if frame is None and timeout_s > 0:
                    ready, _, _ = select.select([self._fd], [], [], timeout_s)
                    frame = self._recv_waiting() if ready else None
            else:
                frame = self._recv(timeout_s)
            while frame is not None:
                if sink is not None:
                    sink(frame)
                if not frame.is_error_frame and not frame.is_remote_frame:
                    got = decoder.feed(frame.arbitration_id, bytes(frame.data))
                    if got is not None:
                        out.append(got)
                frame = self._recv_waiting() if self._fd is not None else self._recv(0.0)
        except (can.CanError, OSError) as err:
            raise DriverIOError(f"{self.describe()}: link lost ({error_reason(err)})") from None
        return out

    def _recv(self, timeout_s: float) -> can.Message | None:
        """``bus.recv``; a line the interface cannot parse (an SLCAN line garbled on the wire, which
        python-can has already dropped from its buffer) is counted as ``bad_lines`` and skipped."""
        try:
            return self._bus.recv(timeout_s)
        except ValueError:
            self.decoder.counters.bad_lines += 1
            return None

    def _recv_waiting(self) -> can.Message | None:
        """The next frame among the bytes already received (SLCAN lines that are not frames,
        such as the adapter's transmit acknowledgements, are skipped), or None."""
        frame = self._recv(0.0)
        while frame is None and self._bus.serialPortOrig.in_waiting:
            frame = self._recv(0.0)
        return frame

    def _close_link(self) -> None:
        try:
            if self._bus is not None:
                bus, self._bus = self._bus, None
                bus.shutdown()
        finally:
            self._unlock_tty()
