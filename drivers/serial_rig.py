"""The serial backend: the rig's interface board on a serial line (pyserial), sashil protocol.

The port is opened with ``serial.serial_for_url`` (a device path, or a pyserial URL such as
``loop://``, ``socket://host:port``, ``spy:///dev/ttyACM0``) and locked for exclusive use. Frames
are those of :mod:`sashil.drivers.serial_codec`; the session (handshake, pacing, safe stop) is
:class:`~sashil.drivers.link_rig.LinkRig`'s.
"""

from __future__ import annotations

import errno
import os
import select
from collections.abc import Mapping
from typing import Any, ClassVar

import serial

from sashil.config.parts import RigParts
from sashil.drivers import slcan_codec
from sashil.drivers.link_rig import LINK_READS, PROBE_S, LinkRig, LinkSettings, error_reason, read_raw
from sashil.drivers.messages import Message
from sashil.drivers.serial_codec import StreamDecoder, encode_frame
from sashil.errors import DriverError, DriverIOError, DriverTimeoutError

#: what opening a port that another process holds fails with: its lock (pyserial's ``exclusive=True``
#: flock: EAGAIN/EWOULDBLOCK) or the device refusing a second opener (EBUSY)
_IN_USE_ERRNOS = frozenset({errno.EAGAIN, errno.EWOULDBLOCK, errno.EBUSY})


def open_reason(err: BaseException, port: str) -> str:
    """Why a port did not open, in one line: "in use by another process" rather than the errno's text."""
    if getattr(err, "errno", None) in _IN_USE_ERRNOS:
        return f"{port} is in use by another process"
    return error_reason(err)


def request_low_latency(port: Any) -> str:
    """Ask a serial device for low-latency mode (the kernel's ASYNC_LOW_LATENCY, through pyserial's
    ``set_low_latency_mode``; Linux only): "on", or why it is not."""
    setter = getattr(port, "set_low_latency_mode", None)
    if setter is None or not isinstance(port, serial.Serial):
        return f"not available ({type(port).__module__.rsplit('.', 1)[-1]} port, not a local serial device)"
    if os.path.realpath(str(port.port)).startswith("/dev/pts/"):
        return "not available on a pseudo-terminal"
    try:
        setter(True)
    except NotImplementedError:
        return "not available on this platform"
    except (ValueError, OSError) as err:
        reason = (
            getattr(err, "strerror", None) or error_reason(err).rsplit("] ", 1)[-1]
        )  # pyserial: "... [Errno N] text"
        return f"not available on this device ({reason})"
    return "on"


class SerialRig(LinkRig):
    """The rig over a serial link (``driver.name: serial``)."""

    name = "serial"

    def __init__(self, settings: LinkSettings, baud: int = 1_000_000):
        super().__init__(settings)
        if not settings.port:
            raise DriverError("driver.port: the serial backend needs a port (--port PATH or a pyserial URL)")
        self.port_name = settings.port
        self.baud = int(baud)
        self.decoder = StreamDecoder()
        self._port: Any = None
        self._fd: int | None = None
        self._heard: bytearray | None = None  # the bytes received during the handshake (what answered)
        #: what asking the port for low-latency mode gave ("on", or why not), for the link summary
        self.low_latency = "not asked (port not open)"

    #: the config keys the backend is built from (:meth:`from_parts`)
    reads: ClassVar[Mapping[str, str]] = {**LINK_READS, "baud": "driver.baud"}

    @classmethod
    def from_parts(cls, parts: RigParts) -> SerialRig:
        return cls(LinkSettings(parts.values), baud=parts.values["baud"])

    def describe(self) -> str:
        return f"serial {self.port_name}"

    def codec_counters(self) -> dict[str, int]:
        return self.decoder.counters.as_dict()

    def link_stats(self) -> dict[str, Any]:
        return {**super().link_stats(), "low_latency": self.low_latency}

    # link ------------------------------------------------------------------------------------
    def _open(self) -> None:
        try:
            self._port = serial.serial_for_url(
                self.port_name,
                baudrate=self.baud,
                timeout=0,
                write_timeout=max(self.settings.sample_timeout_s, 0.05),
                exclusive=True,
            )
        except (serial.SerialException, ValueError, OSError) as err:
            raise DriverError(
                f"serial port {self.port_name}: cannot open ({open_reason(err, self.port_name)})"
            ) from None
        try:
            self._fd = self._port.fileno()
        except Exception:
            self._fd = None
        self.low_latency = request_low_latency(self._port)
        try:
            self._port.reset_input_buffer()
        except (serial.SerialException, OSError) as err:
            raise DriverError(f"serial port {self.port_name}: cannot use it ({error_reason(err)})") from None

    def _handshake(self) -> None:
        self._heard = bytearray()
        try:
            super()._handshake()
        finally:
            self._heard = None

    def _other_protocol(self) -> str | None:
        """An SLCAN adapter (the CAN driver's link) on this port: from what it sent during the
        handshake, or from its answer to :data:`slcan_codec.PROBE` (an adapter answers a line it
        cannot parse with BEL, and it sees no line in sashil frames until their bytes happen to hold a CR)."""
        heard = bytes(self._heard or b"")
        if not slcan_codec.adapter_answer(heard):
            try:
                self._port.write(slcan_codec.PROBE)
                heard = read_raw(self._port, PROBE_S, lambda data: data.endswith(slcan_codec.VERSION_REPLY))
            except (serial.SerialException, OSError):
                return None
        if slcan_codec.adapter_answer(heard):
            return "SLCAN, the ASCII lines of a CAN adapter, not sashil serial frames (use --driver can)"
        return None

    def _send(self, seq: int, msg: Message) -> None:
        try:
            self._port.write(encode_frame(msg, seq))
        except serial.SerialTimeoutException:
            raise DriverTimeoutError(f"{self.describe()}: write timed out (device not reading?)") from None
        except (serial.SerialException, OSError) as err:
            raise DriverIOError(f"{self.describe()}: link lost on write ({error_reason(err)})") from None

    def _receive(self, timeout_s: float) -> list[tuple[int, Message]]:
        port = self._port
        try:
            waiting = port.in_waiting
            if not waiting and timeout_s > 0:
                if self._fd is not None:
                    ready, _, _ = select.select([self._fd], [], [], timeout_s)
                    waiting = (port.in_waiting or 1) if ready else 0
                else:
                    port.timeout = timeout_s
                    data = port.read(1)
                    port.timeout = 0
                    return self.decoder.feed(data + port.read(port.in_waiting)) if data else []
            data = port.read(waiting) if waiting else b""
        except (serial.SerialException, OSError) as err:
            raise DriverIOError(f"{self.describe()}: link lost ({error_reason(err)})") from None
        if self._heard is not None and len(self._heard) < 256:
            self._heard += data
        return self.decoder.feed(data) if data else []

    def _close_link(self) -> None:
        if self._port is not None:
            port, self._port = self._port, None
            port.close()
