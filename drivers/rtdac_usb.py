"""Finding and opening an RT-DAC/USB2 through pyusb, and one exchange with it; errors in one line.

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

from sashil.drivers.rtdac_codec import ENDPOINT_IN, ENDPOINT_OUT, FRAME_BYTES, READ_REQUEST
from sashil.errors import ConfigError, DriverError, DriverIOError, DriverTimeoutError, ProtocolError

#: what a lab adds so that its users may open the board (udev matches the manufacturer string)
UDEV_RULE = 'SUBSYSTEM=="usb", ATTRS{manufacturer}=="InTeCo", MODE="0660", GROUP="plugdev", TAG+="uaccess"'
UDEV_FILE = "/etc/udev/rules.d/70-rtdac.rules"
EMULATED_BACKEND = "sashil.drivers.emulator.rtdac_usb:backend_for"


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


class BoardLink:
    """One opened board: claim, exchanges, release. pyusb's errors become sashil's, in one line."""

    def __init__(self, settings: UsbSettings, backend: Any = None):
        self.settings = settings
        self.backend = backend
        self.dev: Any = None
        self.timeout_ms = int(max(1, round(settings.timeout_ms)))
        self.where = "rtdac"

    def open(self) -> None:
        usb = _usb()
        dev = find_board(self.settings, self.backend)
        self.where = f"rtdac {describe_device(dev)}"
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
        self.dev = dev

    def _dispose(self, dev: Any) -> None:
        import usb.util

        try:
            usb.util.dispose_resources(dev)
        except Exception:
            pass

    def close(self) -> None:
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

    def write_frame(self, frame: bytes | bytearray) -> None:
        """Send a write frame to endpoint 2."""
        try:
            self.dev.write(ENDPOINT_OUT, frame, self.timeout_ms)
        except Exception as err:
            raise self._fail(err, "the write frame") from None

    def read_frame(self) -> Any:
        """Ask for a read frame (``FF 8F 00 00`` to endpoint 2) and read it from endpoint 4: 504 bytes,
        else ProtocolError naming the length."""
        try:
            self.dev.write(ENDPOINT_OUT, READ_REQUEST, self.timeout_ms)
            data = self.dev.read(ENDPOINT_IN, FRAME_BYTES, self.timeout_ms)
        except Exception as err:
            raise self._fail(err, "the read frame") from None
        if len(data) != FRAME_BYTES:
            raise ProtocolError(
                f"{self.where}: a read frame of {len(data)} bytes from endpoint 4, expected {FRAME_BYTES}"
            )
        return data  # pyusb's array('B'): a buffer the codec unpacks as it is
