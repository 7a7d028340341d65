"""The serial backend: the rig's interface board on a serial line (pyserial), sashil protocol.

The port is opened with ``serial.serial_for_url`` (a device path, or a pyserial URL such as
``loop://``, ``socket://host:port``, ``spy:///dev/ttyACM0``) and locked for exclusive use. Frames
are those of :mod:`sashil.drivers.serial_codec`; the session (handshake, pacing, safe stop) is
:class:`~sashil.drivers.link_rig.LinkRig`'s.
"""

from __future__ import annotations

import select
from typing import Any

import serial

from sashil.drivers.link_rig import LinkRig, LinkSettings, error_reason
from sashil.drivers.messages import Message
from sashil.drivers.serial_codec import StreamDecoder, encode_frame
from sashil.errors import DriverError, DriverIOError, DriverTimeoutError


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

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> SerialRig:
        return cls(LinkSettings(config), baud=config["driver"]["baud"])

    def describe(self) -> str:
        return f"serial {self.port_name}"

    def codec_counters(self) -> dict[str, int]:
        return self.decoder.counters.as_dict()

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
            raise DriverError(f"serial port {self.port_name}: cannot open ({error_reason(err)})") from None
        try:
            self._fd = self._port.fileno()
        except Exception:
            self._fd = None
        try:
            self._port.reset_input_buffer()
        except (serial.SerialException, OSError) as err:
            raise DriverError(f"serial port {self.port_name}: cannot use it ({error_reason(err)})") from None

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
        return self.decoder.feed(data) if data else []

    def _close_link(self) -> None:
        if self._port is not None:
            port, self._port = self._port, None
            port.close()
