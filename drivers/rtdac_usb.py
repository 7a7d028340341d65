"""Finding and opening an RT-DAC/USB2 through pyusb, and one exchange with it; errors in one line.

At open (:meth:`BoardLink.open`) the link makes first contact: it checks that the claimed interface
offers the bulk endpoints the protocol uses (0x02 out, 0x84 in), reads the bus speed and from it the
highest loop rate the link carries (:mod:`~sashil.drivers.rtdac_bus`), refusing a faster
``rate_hz``, and drains endpoint 4 of frames an earlier host asked for and never read (else the
first read of this host would return one of them, and every read after it a frame late). A stop
path that meets a transfer error calls :meth:`BoardLink.recover` (clear the endpoints' halt, else
reset, reopen and re-claim the same board).

The public app opens the first Cypress device it finds and checks the manufacturer string
``InTeCo`` only when asked for a serial number (``RTDACUSB2.cs`` lines 86-137); the source names no
USB vendor or product id. sashil matches on the manufacturer string (and the serial, when
``rtdac.serial`` names one), or on the ids ``rtdac.vendor_id`` / ``rtdac.product_id`` give.

The pyusb backend is libusb 1.0: the library ``libusb-package`` ships in its wheel when installed
(``pip install 'sashil[rtdac]'``), else the system's; or, with ``rtdac.usb_backend:
module:callable``, the backend that callable returns (given ``driver.port`` when it takes an
argument: an emulator's, or a lab's own pyusb backend). The
port ``emulated:PATH`` names sashil's own emulated board (``sashil emulate --transport rtdac``).
"""

from __future__ import annotations

import errno
import importlib
import inspect
from dataclasses import dataclass
from typing import Any

from sashil.drivers.rtdac_bus import SPEED_LOW, link_limits, speed_words
from sashil.drivers.rtdac_codec import ENDPOINT_IN, ENDPOINT_OUT, FRAME_BYTES, READ_REQUEST
from sashil.errors import ConfigError, DriverError, DriverIOError, DriverTimeoutError, ProtocolError

#: what a lab adds so that its users may open the board (udev matches the manufacturer string)
UDEV_RULE = 'SUBSYSTEM=="usb", ATTRS{manufacturer}=="InTeCo", MODE="0660", GROUP="plugdev", TAG+="uaccess"'
UDEV_FILE = "/etc/udev/rules.d/70-rtdac.rules"
EMULATED_BACKEND = "sashil.drivers.emulator.rtdac_usb:backend_for"
#: the drain at open: how long a read of endpoint 4 waits for a stale frame [ms], and how many it discards
DRAIN_TIMEOUT_MS = 5
DRAIN_FRAMES = 8
#: the bulk endpoints the protocol uses, their direction and their job
PROTOCOL_ENDPOINTS = ((ENDPOINT_OUT, "OUT", "frames to the FPGA"), (ENDPOINT_IN, "IN", "frames from the FPGA"))
TRANSFER_TYPES = {0: "control", 1: "isochronous", 2: "bulk", 3: "interrupt"}


def _usb() -> Any:
    try:
        import usb.core
        import usb.util
    except ImportError:
        raise DriverError(
            "rtdac: pyusb is not installed: pip install 'sashil[rtdac]' (pyusb and a packaged libusb)"
        ) from None
    return usb


@dataclass(frozen=True)
class UsbSettings:
    """The ``rtdac`` keys that find the board, and ``driver.port``."""

    manufacturer: str = "InTeCo"
    serial: str | None = None
    vendor_id: int | None = None
    product_id: int | None = None
    usb_backend: str | None = None
    port: str | None = None
    timeout_ms: float = 20.0
    #: the loop rate the link must carry (``loop.rate_hz``); None: not checked at open
    rate_hz: float | None = None


def pyusb_backend(settings: UsbSettings) -> Any:
    """The pyusb backend the settings ask for (module docstring); DriverError in one line."""
    target = settings.usb_backend
    if target is None and settings.port is not None and settings.port.startswith("emulated:"):
        target = EMULATED_BACKEND
    if target is not None:
        module_name, _, attr = target.partition(":")
        try:
            factory = getattr(importlib.import_module(module_name), attr)
        except (ImportError, AttributeError, ValueError) as err:
            raise ConfigError(f"rtdac.usb_backend: cannot load {target!r} ({err})") from None
        try:
            takes_port = bool(inspect.signature(factory).parameters)
        except (TypeError, ValueError):  # a builtin without a signature: give it the port
            takes_port = True
        return factory(settings.port or "") if takes_port else factory()
    _usb()
    import usb.backend.libusb1

    try:
        import libusb_package

        backend = usb.backend.libusb1.get_backend(find_library=lambda _name: libusb_package.get_library_path())
    except ImportError:
        backend = None
    backend = backend or usb.backend.libusb1.get_backend()
    if backend is None:
        raise DriverError("rtdac: no libusb 1.0 found: pip install 'sashil[rtdac]' (it ships one)")
    return backend


class Unreadable(Exception):
    """A device's string descriptor could not be read; ``denied``: for want of permission."""

    def __init__(self, reason: str, denied: bool):
        super().__init__(reason)
        self.denied = denied


def _string(dev: Any, index_name: str) -> str | None:
    """A string descriptor of ``dev`` (None: the device names none); Unreadable when it cannot be read."""
    import usb.util

    try:
        return usb.util.get_string(dev, getattr(dev, index_name))
    except usb.core.USBError as err:
        raise Unreadable(usb_reason(err), getattr(err, "errno", None) == errno.EACCES) from None
    except (ValueError, NotImplementedError) as err:
        # pyusb reads no language list from a device it may not open, and says so in a ValueError
        # that names the permission among its causes (libusb's EACCES does not reach it)
        text = str(err) or type(err).__name__
        raise Unreadable(text, "permission" in text) from None


def describe_device(dev: Any) -> str:
    return f"bus {dev.bus} device {dev.address} ({dev.idVendor:04x}:{dev.idProduct:04x})"


def find_board(settings: UsbSettings, backend: Any = None) -> Any:
    """The board's pyusb device, or DriverError: no device (with what was seen), or permission denied
    reading its strings (with the udev rule that fixes it). ``backend``: a pyusb backend object
    (default: the one the settings ask for)."""
    usb = _usb()
    backend = backend if backend is not None else pyusb_backend(settings)
    ids: dict[str, int] = {}
    if settings.vendor_id is not None:
        ids["idVendor"] = settings.vendor_id
    if settings.product_id is not None:
        ids["idProduct"] = settings.product_id
    try:
        devices = list(usb.core.find(find_all=True, backend=backend, **ids))
    except usb.core.NoBackendError:
        raise DriverError("rtdac: no libusb 1.0 found: pip install 'sashil[rtdac]' (it ships one)") from None
    denied: list[str] = []
    unreadable: list[str] = []
    for dev in devices:
        try:
            if not ids and _string(dev, "iManufacturer") != settings.manufacturer:
                continue
            if settings.serial is not None and _string(dev, "iSerialNumber") != settings.serial:
                continue
        except Unreadable as err:
            (denied if err.denied else unreadable).append(f"{describe_device(dev)}: {err}")
            continue
        return dev
    wanted = (
        f"USB ids {settings.vendor_id or 'any'}:{settings.product_id or 'any'}"
        if ids
        else f"manufacturer {settings.manufacturer!r}"
    )
    if settings.serial is not None:
        wanted += f", serial {settings.serial!r}"
    if denied:
        raise DriverError(
            f"rtdac: no RT-DAC/USB2 ({wanted}) among the devices this user may read; permission denied for "
            f"{'; '.join(denied)}: add the udev rule {UDEV_RULE} to {UDEV_FILE}, then replug the board (a board "
            "that names no manufacturer: match it by its USB ids, rtdac.vendor_id and rtdac.product_id)"
        )
    if unreadable:
        raise DriverError(
            f"rtdac: no RT-DAC/USB2 ({wanted}) among the devices whose strings could be read ({'; '.join(unreadable)}): "
            "name the board by its USB ids instead (rtdac.vendor_id, rtdac.product_id: lsusb shows them)"
        )
    where = f" at {settings.port}" if settings.port else ""
    raise DriverError(f"rtdac: no RT-DAC/USB2 found{where} ({wanted}; is it plugged in and powered?)")


def usb_reason(err: BaseException) -> str:
    """A pyusb error in words."""
    return str(getattr(err, "strerror", None) or err)


def _words(err: BaseException) -> str:
    """An error from a step of recovery in words: sashil's own without the place it already names."""
    text = usb_reason(err)
    return text.split(": ", 1)[1] if text.startswith("rtdac") and ": " in text else text


def _speed(dev: Any) -> int | None:
    """libusb's speed code of ``dev`` (pyusb's ``Device.speed``), None when the backend gives none."""
    speed = getattr(dev, "speed", None)
    return int(speed) if speed else None


class BoardLink:
    """One opened board: claim, first contact, exchanges, recovery, release. pyusb's errors become
    sashil's, in one line.

    After :meth:`open`: ``speed`` (libusb's code: 1 low, 2 full, 3 high, 4 super; None unknown),
    ``max_rate_hz`` (the highest loop rate the link carries, None when unknown) and :meth:`facts`."""

    def __init__(self, settings: UsbSettings, backend: Any = None):
        self.settings = settings
        self.backend = backend
        self.dev: Any = None
        self.timeout_ms = int(max(1, round(settings.timeout_ms)))
        self.where = "rtdac"
        self.speed: int | None = None
        self.max_exchanges_hz: int | None = None
        self.max_rate_hz: int | None = None
        self.exchange_us: float | None = None
        self._facts: dict[str, Any] = {}
        self._closed = False
        self.recoveries = {"clear_halt": 0, "reopen": 0}

    def open(self) -> None:
        """Find, claim and greet the board (module docstring); DriverError in one line, nothing written."""
        dev = find_board(self.settings, self.backend)
        self.where = f"rtdac {describe_device(dev)}"
        self._claim(dev)
        try:
            packets = self._endpoints(dev)
            self.speed = _speed(dev)
            self.max_exchanges_hz, self.max_rate_hz = link_limits(self.speed, *packets)
            self.check_rate(self.settings.rate_hz)
            stale = self._drain(dev)
            self._facts = self._read_facts(dev, stale)
        except BaseException:
            self._dispose(dev)
            raise
        self.dev = dev
        self._closed = False

    def _claim(self, dev: Any) -> None:
        usb = _usb()
        try:
            dev.set_configuration()
            usb.util.claim_interface(dev, 0)
        except usb.core.USBError as err:
            self._dispose(dev)
            code = getattr(err, "errno", None)
            if code == errno.EACCES:
                raise DriverError(
                    f"{self.where}: permission denied: add the udev rule {UDEV_RULE} to {UDEV_FILE}, then replug "
                    "the board"
                ) from None
            if code == errno.EBUSY:
                raise DriverError(
                    f"{self.where}: another program holds the board ({usb_reason(err)}); close it first"
                ) from None
            raise DriverError(f"{self.where}: cannot open ({usb_reason(err)})") from None

    def _endpoints(self, dev: Any) -> tuple[int, int]:
        """The protocol's endpoints on interface 0, checked; their packet sizes (out, in)."""
        usb = _usb()
        try:
            intf = dev.get_active_configuration()[(0, 0)]
        except (usb.core.USBError, KeyError, IndexError) as err:
            raise DriverError(f"{self.where}: cannot read its interface 0 ({usb_reason(err)})") from None
        sizes = []
        for address, direction, job in PROTOCOL_ENDPOINTS:
            ep = usb.util.find_descriptor(intf, bEndpointAddress=address)
            if ep is None or usb.util.endpoint_type(ep.bmAttributes) != usb.util.ENDPOINT_TYPE_BULK:
                offered = ", ".join(
                    f"0x{e.bEndpointAddress:02x} {TRANSFER_TYPES[usb.util.endpoint_type(e.bmAttributes)]} "
                    f"{'IN' if e.bEndpointAddress & 0x80 else 'OUT'}"
                    for e in intf
                )
                raise DriverError(
                    f"{self.where}: the board has no bulk {direction} endpoint 0x{address:02x} ({job}) on interface 0; "
                    f"it offers {offered or 'no endpoints'} (is its FPGA firmware an RT-DAC/USB2's?)"
                )
            sizes.append(int(ep.wMaxPacketSize) & 0x7FF)
        return sizes[0], sizes[1]

    def check_rate(self, rate_hz: float | None) -> None:
        """DriverError in one line when the link cannot carry a loop at ``rate_hz`` (:mod:`rtdac_bus`)."""
        limit = self.max_rate_hz
        if rate_hz is None or limit is None or rate_hz <= limit:
            return
        if self.speed == SPEED_LOW:
            raise DriverError(
                f"rtdac: the board is on a {speed_words(self.speed)} USB link, which carries no bulk transfers "
                "(USB 2.0 section 5.8): plug it into a USB 2.0 port directly"
            )
        bus_us = 1e6 / self.max_exchanges_hz if self.max_exchanges_hz else 0.0
        name, _, rate = speed_words(self.speed).partition(" ")
        raise DriverError(
            f"rtdac: the board is on a {name} USB link {rate}, which carries at most {self.max_exchanges_hz} "
            f"exchanges a second ({bus_us:.0f} us of bus time each, USB 2.0 section 5.11.3) and leaves room for a "
            f"{limit} Hz loop; loop.rate_hz is {rate_hz:g}: plug the board into a high-speed (USB 2.0) port with no "
            f"USB 1.1 hub between, or --set loop.rate_hz={limit}"
        )

    def _drain(self, dev: Any) -> int:
        """Read endpoint 4 until it times out (at most :data:`DRAIN_FRAMES` frames); the frames discarded."""
        import usb.core

        stale = 0
        while stale < DRAIN_FRAMES:
            try:
                dev.read(ENDPOINT_IN, FRAME_BYTES, DRAIN_TIMEOUT_MS)
            except usb.core.USBTimeoutError:
                break
            except usb.core.USBError as err:
                raise DriverError(
                    f"{self.where}: endpoint 0x84 fails before the first exchange ({usb_reason(err)})"
                ) from None
            stale += 1
        return stale

    def _read_facts(self, dev: Any, stale: int) -> dict[str, Any]:
        def text(index_name: str) -> str | None:
            try:
                return _string(dev, index_name)
            except Unreadable:
                return None

        return {
            "usb_ids": f"{dev.idVendor:04x}:{dev.idProduct:04x}",
            "manufacturer": text("iManufacturer"),
            "product": text("iProduct"),
            "serial": text("iSerialNumber"),
            "bus": dev.bus,
            "address": dev.address,
            "usb_speed": speed_words(self.speed),
            "bus_max_exchanges_hz": self.max_exchanges_hz,
            "bus_max_rate_hz": self.max_rate_hz,
            "stale_frames_discarded": stale,
        }

    def facts(self) -> dict[str, Any]:
        """What the board said of itself at open: USB ids, strings, bus and address, speed, the rates the
        link carries, the stale frames drained; and the recoveries since (empty before open)."""
        if not self._facts:
            return {}
        return {**self._facts, "recoveries_clear_halt": self.recoveries["clear_halt"],
                "recoveries_reopen": self.recoveries["reopen"]}  # fmt: skip

    def summary(self) -> str:
        """The facts in one line (``sashil doctor``'s board/link)."""
        f = self._facts
        if not f:
            return f"{self.where}: not open"
        names = " ".join(str(f[k]) for k in ("manufacturer", "product") if f[k]) or "a board that names itself not"
        serial = f", serial {f['serial']!r}" if f["serial"] else ""
        limit = (
            f"room for a {f['bus_max_rate_hz']} Hz loop ({f['bus_max_exchanges_hz']} exchanges a second at most)"
            if f["bus_max_rate_hz"] is not None
            else "the bus's limit unknown"
        )
        return (
            f"{names}{serial}, USB {f['usb_ids']} at bus {f['bus']} device {f['address']}, {f['usb_speed']}: "
            f"{limit}; {f['stale_frames_discarded']} stale frame(s) drained from endpoint 4"
        )

    def recover(self) -> None:
        """Bring a link that failed a transfer back: clear the halt of both endpoints and drain endpoint 4;
        when a read exchange still fails, reset the device, find the same board again (its serial, else
        its bus and address), re-claim and drain it. Ends with a read exchange that succeeded (no output
        is written); DriverIOError in one line when neither cured it (a later call tries the reopen again)."""
        if not self._facts or self._closed:
            raise DriverIOError(f"{self.where}: recover: the board is not open")
        dev = self.dev
        first: str | None = None  # a link let go by a recovery that failed goes straight to the reopen
        if dev is not None:
            try:
                for address in (ENDPOINT_OUT, ENDPOINT_IN):
                    dev.clear_halt(address)
                self._drain(dev)
                self.read_frame()
            except Exception as err:
                first = _words(err)
            else:
                self.recoveries["clear_halt"] += 1
                return
            try:
                dev.reset()
            except Exception:
                pass  # a device that re-enumerates on reset is gone from this handle: it is found again below
            self._dispose(dev)
            self.dev = None
        try:
            again = self._find_same()
            self.where = f"rtdac {describe_device(again)}"
            self._claim(again)
            self._drain(again)
            self.dev = again
            self.read_frame()
        except Exception as err:
            why = _words(err)
            said = (
                f"the reopen failed ({why})"
                if first is None
                else f"neither clearing the endpoints' halt ({first}) nor a reset and reopen ({why}) brought it back"
            )
            raise DriverIOError(f"{self.where}: recover: {said}") from None
        self.recoveries["reopen"] += 1

    def _find_same(self) -> Any:
        """The board opened before, found again: by its serial when it has one, else at its bus and address."""
        usb = _usb()
        f = self._facts
        backend = self.backend if self.backend is not None else pyusb_backend(self.settings)
        vendor, product = (int(part, 16) for part in f["usb_ids"].split(":"))
        for dev in usb.core.find(find_all=True, backend=backend, idVendor=vendor, idProduct=product):
            if f["serial"]:
                try:
                    if _string(dev, "iSerialNumber") == f["serial"]:
                        return dev
                except Unreadable:
                    continue
            elif (dev.bus, dev.address) == (f["bus"], f["address"]):
                return dev
        which = f"with serial {f['serial']!r} on the bus" if f["serial"] else f"at bus {f['bus']} device {f['address']}"
        raise DriverIOError(f"{self.where}: no {f['usb_ids']} {which} any more")

    def _dispose(self, dev: Any) -> None:
        import usb.util

        try:
            usb.util.dispose_resources(dev)
        except Exception:
            pass

    def close(self) -> None:
        self._closed = True
        dev, self.dev = self.dev, None
        if dev is None:
            return
        import usb.util

        try:
            usb.util.release_interface(dev, 0)
        except Exception:
            pass
        self._dispose(dev)

    def _fail(self, err: BaseException, what: str) -> DriverIOError:
        import usb.core

        if isinstance(err, usb.core.USBTimeoutError):
            return DriverTimeoutError(
                f"{self.where}: {what}: no answer within {self.timeout_ms} ms (transfer timed out)"
            )
        if getattr(err, "errno", None) == errno.ENODEV:
            return DriverIOError(f"{self.where}: the board is gone ({usb_reason(err)}) during {what}")
        return DriverIOError(f"{self.where}: {what}: {usb_reason(err)}")

    def _device(self, what: str) -> Any:
        if self.dev is None:
            raise DriverIOError(f"{self.where}: {what}: the board is not open (closed, or let go by a recovery)")
        return self.dev

    def write_frame(self, frame: bytes | bytearray) -> None:
        """Send a write frame to endpoint 2."""
        dev = self._device("the write frame")
        try:
            dev.write(ENDPOINT_OUT, frame, self.timeout_ms)
        except Exception as err:
            raise self._fail(err, "the write frame") from None

    def read_frame(self) -> Any:
        """Ask for a read frame (``FF 8F 00 00`` to endpoint 2) and read it from endpoint 4: 504 bytes,
        else ProtocolError naming the length."""
        dev = self._device("the read frame")
        try:
            dev.write(ENDPOINT_OUT, READ_REQUEST, self.timeout_ms)
            data = dev.read(ENDPOINT_IN, FRAME_BYTES, self.timeout_ms)
        except Exception as err:
            raise self._fail(err, "the read frame") from None
        if len(data) != FRAME_BYTES:
            raise ProtocolError(
                f"{self.where}: a read frame of {len(data)} bytes from endpoint 4, expected {FRAME_BYTES}"
            )
        return data  # pyusb's array('B'): a buffer the codec unpacks as it is
