"""The emulated RT-DAC/USB2 at the USB layer: a pyusb backend that serves the board's transfers.

:class:`EmulatedUsbBackend` implements pyusb's own backend interface (``usb.backend.IBackend``):
enumeration, descriptors, the manufacturer and serial strings, open, claim and the bulk
transfers. A host that opens the board through ``usb.core.find(backend=...)`` runs the real pyusb
core and sashil's ``rtdac`` backend end to end; only libusb and the wire are replaced.

The backend reaches the board through a port:

* :class:`BoardServer` runs an :class:`~sashil.drivers.emulator.rtdac_board.RtdacBoard` in its
  own process (``sashil emulate --transport rtdac --link PATH``) on a Unix socket, so the board
  outlives a host that dies, as a real one does; :class:`SocketPort` is the host's side of it
  (``driver.port: emulated:PATH``);
* :class:`DirectPort` calls a board in the same process, on a clock the caller gives (tests).

One request, one reply, each a packet that starts with a 2-byte tag the reply echoes: a reply to a
request the host has given up on (its transfer timed out) is dropped on arrival, as libusb never
hands a cancelled transfer's completion to a later one. After the tag: ``O`` open, ``C`` claim, ``L`` release, ``I`` the board's
identity (JSON), ``U`` its USB side (speed, packet size, endpoints: JSON), ``W`` + endpoint + data,
``R`` + endpoint + size, ``H`` + endpoint clear halt, ``X`` reset. A reply starts with ``0`` (ok)
or ``1`` + errno + text (libusb's errors: 5 I/O error, 13 access denied, 16 busy, 19 no such
device, 32 pipe error: a halted endpoint); a read the board leaves unanswered times out on the
host's side, as a USB transfer does.

The USB side's faults (:class:`UsbFaults`, held by :class:`UsbSide`) are the ones a host meets at
first contact and on the stop path: the board enumerated at full speed, an endpoint missing, frames
an earlier host asked for left waiting on endpoint 4, an endpoint that halts until the host clears
it, and a transfer error that only a reset or a reopen cures.
"""

from __future__ import annotations

import array
import errno
import json
import os
import select
import socket
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import usb.backend
import usb.core

from sashil.drivers.emulator.rtdac_board import BoardIdentity, RtdacBoard, TransferError, TransferTimeout
from sashil.drivers.rtdac_codec import ENDPOINT_IN, ENDPOINT_OUT, FRAME_WORDS

OK, FAIL = b"\x00", b"\x01"
#: the packet size the socket carries (a frame plus its header and tag)
PACKET = 1024
#: how many tags there are (2 bytes): a reply is matched to its request by its tag
TAGS = 1 << 16
EMULATED_PREFIX = "emulated:"


def _fail(code: int, text: str) -> bytes:
    return FAIL + bytes((code,)) + text.encode()


#: the board's bulk endpoints: FPGA out and in, JTAG out and in (RTDACUSB2.cs lines 74-81)
ENDPOINTS = (ENDPOINT_OUT, ENDPOINT_IN, 0x06, 0x88)
#: libusb's speed codes: full (12 Mbit/s) and high (480 Mbit/s) speed
FULL_SPEED, HIGH_SPEED = 2, 3


@dataclass
class UsbFaults:
    """The board's USB side at fault; times count from the host's claim."""

    #: the board enumerates at full speed (12 Mbit/s, 64-byte bulk packets), as behind a USB 1.1 hub
    full_speed: bool = False
    #: this endpoint is missing from the interface (0x02 or 0x84: a board with other firmware)
    missing_endpoint: int | None = None
    #: frames an earlier host asked for and never read, waiting on endpoint 4 when a host opens the board
    stale_frames: int = 0
    #: then ``halt_endpoint`` stalls every transfer (a pipe error) until the host clears its halt; once
    halt_after_s: float | None = None
    halt_endpoint: int = ENDPOINT_OUT
    #: then every transfer fails (an I/O error) until the host resets the device or claims it again; once
    wedge_after_s: float | None = None


class UsbSide:
    """The state of the board's USB side under :class:`UsbFaults`."""

    def __init__(self, board: RtdacBoard, faults: UsbFaults | None = None):
        self.board = board
        self.faults = faults or UsbFaults()
        words = struct.pack(f"<{FRAME_WORDS}H", *board.words)  # the registers an earlier host latched
        self.stale = [words] * self.faults.stale_frames
        self.halted: set[int] = set()
        self.wedged = False
        self._halt_spent = self._wedge_spent = False
        self.clear_halts = 0
        self.resets = 0

    def describe(self) -> dict[str, Any]:
        """What the host's backend builds its descriptors from (``U``)."""
        f = self.faults
        return {
            "speed": FULL_SPEED if f.full_speed else HIGH_SPEED,
            "max_packet": 64 if f.full_speed else 512,
            "endpoints": [ep for ep in ENDPOINTS if ep != f.missing_endpoint],
        }

    def _after(self, now_ns: int, after_s: float | None) -> bool:
        start = self.board.session_start_ns
        return after_s is not None and start is not None and (now_ns - start) * 1e-9 >= after_s

    def check(self, endpoint: int, now_ns: int) -> None:
        """A transfer on ``endpoint``: TransferError when the side is halted there or wedged."""
        f = self.faults
        if not self._halt_spent and self._after(now_ns, f.halt_after_s):
            self._halt_spent = True
            self.halted.add(f.halt_endpoint)
        if not self._wedge_spent and self._after(now_ns, f.wedge_after_s):
            self._wedge_spent = True
            self.wedged = True
        if self.wedged:
            raise TransferError(errno.EIO, "Input/Output Error (the board's FIFO is stuck)")
        if endpoint in self.halted:
            raise TransferError(errno.EPIPE, f"Pipe error (endpoint 0x{endpoint:02x} halted)")

    def clear_halt(self, endpoint: int) -> None:
        self.clear_halts += 1
        self.halted.discard(endpoint)

    def reset(self) -> None:
        """A reset (or a new claim): the FIFOs and the endpoints start afresh."""
        self.resets += 1
        self.wedged = False
        self.halted.clear()


class BoardPort:
    """The host's way to the board: one request, its reply (or None: no answer in time)."""

    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        raise NotImplementedError

    def close(self) -> None:
        pass


def serve(board: RtdacBoard, request: bytes, now_ns: int, holder: object, state: dict[str, object]) -> bytes | None:
    """The board's reply to one request from ``holder`` (a connection); ``state['holder']`` is who
    has claimed the board. None: the board leaves it unanswered."""
    op = request[:1]
    side = state.get("usb")
    side = side if isinstance(side, UsbSide) else None
    try:
        if op == b"I":
            ident = board.identity
            return OK + json.dumps(ident.__dict__).encode()
        if op == b"U":
            return OK + json.dumps((side or UsbSide(board)).describe()).encode()
        if op == b"O":
            board.open()
            return OK
        if op == b"C":
            if state.get("holder") not in (None, holder):
                return _fail(errno.EBUSY, "Resource busy (another program has claimed the board)")
            state["holder"] = holder
            board.claim(now_ns)
            if side is not None and side.wedged:
                side.reset()
            return OK
        if op == b"L":
            if state.get("holder") is holder:
                state["holder"] = None
                board.release()
            return OK
        if op == b"X":
            if side is not None:
                side.reset()
            return OK
        if state.get("holder") is not holder:
            return _fail(errno.EBUSY, "Resource busy (the interface is not claimed)")
        if op == b"H":
            if side is not None:
                side.clear_halt(request[1])
            return OK
        if side is not None and op in (b"W", b"R"):
            side.check(request[1], now_ns)
        if op == b"W":
            return OK + board.bulk_write(request[1], request[2:], now_ns).to_bytes(2, "little")
        if op == b"R":
            size = int.from_bytes(request[2:4], "little")
            if side is not None and side.stale and request[1] == ENDPOINT_IN:
                return OK + side.stale.pop(0)[:size]
            return OK + board.bulk_read(request[1], size, now_ns)
    except TransferError as err:
        return _fail(err.errno, str(err))
    except TransferTimeout:
        return None
    return _fail(errno.EINVAL, f"unknown request {op!r}")


class DirectPort(BoardPort):
    """A board in this process, on the clock ``clock`` (nanoseconds)."""

    def __init__(
        self, board: RtdacBoard, clock: Callable[[], int] = time.monotonic_ns, usb_faults: UsbFaults | None = None
    ):
        self.board = board
        self.clock = clock
        self.usb = UsbSide(board, usb_faults)
        self.state: dict[str, object] = {"usb": self.usb}

    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        return serve(self.board, request, self.clock(), self, self.state)


#: how long the host's side of the emulated wire polls for the board's answer before it sleeps on it:
#: a USB host controller polls its bus; a process asleep on a socket wakes a VM's idle CPU late (an
#: exchange of three transfers took 0.45 ms in the median, 1 ms at p99, on an idle 2-core VM)
POLL_S = 0.002


def _poll(sock: socket.socket, timeout_s: float) -> bytes:
    """The next packet on the non-blocking ``sock``: polled for up to :data:`POLL_S`, then waited for
    until ``timeout_s`` from the start; TimeoutError when none comes."""
    start = time.monotonic()
    end_poll = start + min(POLL_S, timeout_s)
    while True:
        try:
            return sock.recv(PACKET)
        except BlockingIOError:
            if time.monotonic() >= end_poll:
                break
    remaining = timeout_s - (time.monotonic() - start)
    if remaining <= 0.0:
        raise TimeoutError
    ready, _, _ = select.select([sock], [], [], remaining)
    if not ready:
        raise TimeoutError
    return sock.recv(PACKET)


class SocketPort(BoardPort):
    """A board served by :class:`BoardServer` at ``path``."""

    def __init__(self, path: str):
        self.path = path
        self._sock: socket.socket | None = None
        #: the tag of the last request sent (each request's is the next, modulo 2**16)
        self._tag = 0

    def _connect(self) -> socket.socket:
        if self._sock is None:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            try:
                sock.connect(self.path)
            except OSError:
                sock.close()
                raise
            self._sock = sock
        return self._sock

    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        self._tag = (self._tag + 1) % TAGS
        tag = self._tag.to_bytes(2, "little")
        deadline = time.monotonic() + timeout_s
        try:
            sock = self._connect()
            sock.setblocking(False)
            sock.send(tag + request)
            while True:  # replies to requests that timed out arrive first, in order: dropped
                reply = _poll(sock, max(deadline - time.monotonic(), 0.0))
                if not reply or reply[:2] == tag:
                    break
        except TimeoutError:
            return None
        except OSError as err:
            return _fail(errno.ENODEV, f"No such device ({err.strerror or err})")
        if not reply:  # the board's process ended: the device is gone
            self.close()
            return _fail(errno.ENODEV, "No such device (it may have been disconnected)")
        return reply[2:]

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def _raise(reply: bytes | None, timeout_ms: float) -> bytes:
    """The reply's payload, or the error pyusb's libusb backend would raise for it."""
    if reply is None:
        raise usb.core.USBTimeoutError(f"Operation timed out ({timeout_ms:g} ms)", -7, errno.ETIMEDOUT)
    if reply[:1] == OK:
        return reply[1:]
    code = reply[1]
    libusb_code = {errno.EIO: -1, errno.EACCES: -3, errno.ENODEV: -4, errno.EBUSY: -6, errno.EPIPE: -9}.get(code, -99)
    raise usb.core.USBError(reply[2:].decode(errors="replace"), libusb_code, code)


class EmulatedUsbBackend(usb.backend.IBackend):
    """pyusb's backend interface over a :class:`BoardPort` (module docstring)."""

    def __init__(self, port: BoardPort):
        super().__init__()
        self.port = port
        self._identity: BoardIdentity | None = None
        #: the board's USB side (``U``): speed, packet size, endpoints
        self._usb: dict[str, Any] = {}

    def _call(self, request: bytes, timeout_ms: float = 1000.0) -> bytes:
        return _raise(self.port.call(request, timeout_ms * 1e-3), timeout_ms)

    # enumeration and descriptors ---------------------------------------------------------------
    def enumerate_devices(self) -> Any:
        try:
            payload = self._call(b"I")
        except usb.core.USBError:
            return iter(())  # no board there
        self._identity = BoardIdentity(**json.loads(payload))
        self._usb = json.loads(self._call(b"U"))
        return iter((0,))

    def _side(self) -> dict[str, Any]:
        return self._usb or {"speed": HIGH_SPEED, "max_packet": 512, "endpoints": list(ENDPOINTS)}

    def get_device_descriptor(self, dev: Any) -> Any:
        ident = self._identity or BoardIdentity()
        return SimpleNamespace(
            bLength=18,
            bDescriptorType=1,
            bcdUSB=0x0200,
            bDeviceClass=0xFF,
            bDeviceSubClass=0,
            bDeviceProtocol=0,
            bMaxPacketSize0=64,
            idVendor=ident.vendor_id,
            idProduct=ident.product_id,
            bcdDevice=0x0001,
            iManufacturer=1,
            iProduct=2,
            iSerialNumber=3,
            bNumConfigurations=1,
            address=2,
            bus=1,
            port_number=1,
            port_numbers=(1,),
            speed=self._side()["speed"],
        )

    def get_configuration_descriptor(self, dev: Any, config: int) -> Any:
        return SimpleNamespace(
            bLength=9,
            bDescriptorType=2,
            wTotalLength=9 + 9 + 7 * len(self._side()["endpoints"]),
            bNumInterfaces=1,
            bConfigurationValue=1,
            iConfiguration=0,
            bmAttributes=0x80,
            bMaxPower=50,
            extra_descriptors=[],
        )

    def get_interface_descriptor(self, dev: Any, intf: int, alt: int, config: int) -> Any:
        if intf != 0 or alt != 0:
            raise IndexError("no such interface")
        return SimpleNamespace(
            bLength=9,
            bDescriptorType=4,
            bInterfaceNumber=0,
            bAlternateSetting=0,
            bNumEndpoints=len(self._side()["endpoints"]),
            bInterfaceClass=0xFF,
            bInterfaceSubClass=0,
            bInterfaceProtocol=0,
            iInterface=0,
            extra_descriptors=[],
        )

    def get_endpoint_descriptor(self, dev: Any, ep: int, intf: int, alt: int, config: int) -> Any:
        side = self._side()
        if ep >= len(side["endpoints"]):
            raise IndexError("no such endpoint")
        return SimpleNamespace(
            bLength=7,
            bDescriptorType=5,
            bEndpointAddress=side["endpoints"][ep],
            bmAttributes=0x02,
            wMaxPacketSize=side["max_packet"],
            bInterval=0,
            bRefresh=0,
            bSynchAddress=0,
            extra_descriptors=[],
        )

    # handles ------------------------------------------------------------------------------------
    def open_device(self, dev: Any) -> Any:
        self._call(b"O")
        return SimpleNamespace(configuration=1)

    def close_device(self, dev_handle: Any) -> None:
        try:
            self._call(b"L")
        except usb.core.USBError:
            pass
        self.port.close()

    def set_configuration(self, dev_handle: Any, config_value: int) -> None:
        dev_handle.configuration = config_value

    def get_configuration(self, dev_handle: Any) -> int:
        return int(dev_handle.configuration)

    def set_interface_altsetting(self, dev_handle: Any, intf: int, altsetting: int) -> None:
        pass

    def claim_interface(self, dev_handle: Any, intf: int) -> None:
        self._call(b"C")

    def release_interface(self, dev_handle: Any, intf: int) -> None:
        self._call(b"L")

    def is_kernel_driver_active(self, dev_handle: Any, intf: int) -> bool:
        return False

    def reset_device(self, dev_handle: Any) -> None:
        self._call(b"X")

    def clear_halt(self, dev_handle: Any, ep: int) -> None:
        self._call(b"H" + bytes((ep,)))

    # transfers ----------------------------------------------------------------------------------
    def bulk_write(self, dev_handle: Any, ep: int, intf: int, data: Any, timeout: int) -> int:
        return int.from_bytes(self._call(b"W" + bytes((ep,)) + bytes(data), timeout), "little")

    def bulk_read(self, dev_handle: Any, ep: int, intf: int, buff: Any, timeout: int) -> int:
        size = len(buff) * buff.itemsize
        payload = self._call(b"R" + bytes((ep,)) + size.to_bytes(2, "little"), timeout)
        buff[: len(payload)] = array.array("B", payload)
        return len(payload)

    def ctrl_transfer(
        self, dev_handle: Any, bmRequestType: int, bRequest: int, wValue: int, wIndex: int, data: Any, timeout: int
    ) -> Any:
        """GET_DESCRIPTOR of a string: the language list, the manufacturer, product and serial."""
        if bRequest != 6 or wValue >> 8 != 3:
            raise usb.core.USBError("Pipe error (request not supported)", -9, errno.EPIPE)
        ident = self._identity or BoardIdentity()
        index = wValue & 0xFF
        if index == 0:
            body = (0x0409).to_bytes(2, "little")
        else:
            text = {1: ident.manufacturer, 2: ident.product, 3: ident.serial}.get(index, "")
            body = text.encode("utf-16-le")
        desc = bytes((2 + len(body), 3)) + body
        n = min(len(desc), len(data))
        data[:n] = array.array("B", desc[:n])
        return n


def backend_for(port: str) -> EmulatedUsbBackend:
    """The backend that reaches the emulated board ``driver.port`` names (``emulated:PATH``)."""
    path = port[len(EMULATED_PREFIX) :] if port.startswith(EMULATED_PREFIX) else port
    return EmulatedUsbBackend(SocketPort(path))


class BoardServer:
    """Serves a board on a Unix socket at ``path`` until stopped (``sashil emulate --transport rtdac``)."""

    def __init__(
        self,
        board: RtdacBoard,
        path: str,
        clock: Callable[[], int] = time.monotonic_ns,
        usb_faults: UsbFaults | None = None,
    ):
        self.board = board
        self.path = path
        self.clock = clock
        self.usb = UsbSide(board, usb_faults)
        if os.path.exists(path):
            os.unlink(path)
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.listener.bind(path)
        self.listener.listen(4)
        self.state: dict[str, object] = {"usb": self.usb}
        self._stop_r, self._stop_w = os.pipe()
        self.connections: list[socket.socket] = []

    def stop(self) -> None:
        os.write(self._stop_w, b"x")

    def run(self, duration_s: float | None = None) -> str:
        end = None if duration_s is None else time.monotonic() + duration_s
        try:
            while True:
                wait = 0.5 if end is None else max(0.0, min(0.5, end - time.monotonic()))
                if end is not None and time.monotonic() >= end:
                    return "duration"
                watched: list[Any] = [self._stop_r, self.listener, *self.connections]
                ready, _, _ = select.select(watched, [], [], wait)
                if self._stop_r in ready:
                    return "stop"
                for sock in ready:
                    if sock is self.listener:
                        conn, _ = self.listener.accept()
                        self.connections.append(conn)
                    elif isinstance(sock, socket.socket):
                        self._serve_one(sock)
        finally:
            self.close()

    def _serve_one(self, conn: socket.socket) -> None:
        try:
            request = conn.recv(PACKET)
        except OSError:
            request = b""
        if not request:  # the host went away: its claim with it (the outputs stay as written)
            if self.state.get("holder") is conn:
                self.state["holder"] = None
                self.board.release()
            self.connections.remove(conn)
            conn.close()
            return
        tag, request = request[:2], request[2:]
        reply = serve(self.board, request, self.clock(), conn, self.state)
        if reply is not None:
            try:
                conn.send(tag + reply)
            except OSError:
                pass

    def close(self) -> None:
        for conn in self.connections:
            conn.close()
        self.connections.clear()
        self.listener.close()
        for fd in (self._stop_r, self._stop_w):
            try:
                os.close(fd)
            except OSError:
                pass
        try:
            os.unlink(self.path)
        except OSError:
            pass
