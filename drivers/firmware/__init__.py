"""The interface board's logic in portable C, built for the host and loaded with ctypes.

So far: the serial framing of protocol v2 (``sashil_frame.c``: CRC-16, COBS, frame encode/decode, a
stream decoder), tested byte for byte against :mod:`sashil.drivers.serial_codec`, and the board's
session logic (``sashil_board.c``: Hello/Version, Configure/Status, Command and RoadSpeed, samples
in both pacings, the watchdog for coil and road) behind a hardware-interface struct, tested through
ctypes callbacks. The CAN frames, ``emulate --board c`` and the Cortex-M4 build are not written yet.

:func:`load` compiles the C sources with the system C compiler (``$CC``, else ``cc``) into a shared
library in a cache folder named by the hash of the sources and the flags (``$SASHIL_CACHE`` or
``~/.cache/sashil``), once, and loads it with ctypes: no build step at install time, a changed
source rebuilds itself, and a machine without a compiler gets one line saying so.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from sashil.errors import DriverError

SOURCES = ("sashil_frame.c", "sashil_board.c")
HEADERS = ("sashil_frame.h", "sashil_board.h")
CFLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic", "-fPIC", "-shared")
HERE = Path(__file__).resolve().parent


def compiler() -> str | None:
    """The C compiler to use: ``$CC`` or ``cc``/``gcc``/``clang`` on the PATH, else None."""
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return name
    return None


def library_path() -> Path:
    """Build (once per source hash) and return the shared library's path; DriverError if impossible."""
    cc = compiler()
    if cc is None:
        raise DriverError("firmware: no C compiler found (install gcc or set CC) to build the board's C code")
    digest = hashlib.sha256(" ".join(CFLAGS).encode())
    for name in (*SOURCES, *HEADERS):
        digest.update((HERE / name).read_bytes())
    cache = Path(os.environ.get("SASHIL_CACHE") or Path.home() / ".cache" / "sashil") / "firmware"
    target = cache / f"libsashil_board-{digest.hexdigest()[:16]}.so"
    if target.exists():
        return target
    cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=cache) as tmp:
        built = Path(tmp) / target.name
        done = subprocess.run(
            [cc, *CFLAGS, "-o", str(built), *(str(HERE / s) for s in SOURCES)],
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            first = (done.stderr.strip().splitlines() or ["?"])[0]
            raise DriverError(f"firmware: {cc} could not build the board's C code: {first}")
        os.replace(built, target)  # atomic: a concurrent build of the same sources is harmless
    return target


def load() -> ctypes.CDLL:
    """The C board library with its function signatures declared."""
    lib = ctypes.CDLL(str(library_path()))
    u8p = ctypes.POINTER(ctypes.c_uint8)
    lib.sashil_crc16.argtypes = (u8p, ctypes.c_size_t)
    lib.sashil_crc16.restype = ctypes.c_uint16
    lib.sashil_frame_encode.argtypes = (ctypes.c_uint8, ctypes.c_uint16, u8p, ctypes.c_uint8, u8p, ctypes.c_size_t)
    lib.sashil_frame_encode.restype = ctypes.c_size_t
    lib.sashil_frame_decode.argtypes = (
        u8p,
        ctypes.c_size_t,
        u8p,
        ctypes.POINTER(ctypes.c_uint16),
        u8p,
        u8p,
    )
    lib.sashil_frame_decode.restype = ctypes.c_int
    lib.sashil_stream_feed.argtypes = (ctypes.c_void_p, ctypes.c_uint8, u8p, ctypes.POINTER(ctypes.c_uint16), u8p, u8p)
    lib.sashil_stream_feed.restype = ctypes.c_int
    lib.sashil_stream_init.argtypes = (ctypes.c_void_p,)
    lib.sashil_stream_init.restype = None
    lib.sashil_board_size.argtypes = ()
    lib.sashil_board_size.restype = ctypes.c_size_t
    lib.sashil_board_init.argtypes = (
        ctypes.c_void_p,
        ctypes.c_void_p,
        ctypes.c_uint32,
        ctypes.c_uint16,
        ctypes.c_uint16,
    )
    lib.sashil_board_init.restype = None
    lib.sashil_board_receive.argtypes = (ctypes.c_void_p, u8p, ctypes.c_size_t, ctypes.c_uint64)
    lib.sashil_board_receive.restype = None
    lib.sashil_board_tick.argtypes = (ctypes.c_void_p, ctypes.c_uint64)
    lib.sashil_board_tick.restype = None
    lib.sashil_board_set_link.argtypes = (ctypes.c_void_p, ctypes.c_uint8)
    lib.sashil_board_set_link.restype = None
    lib.sashil_board_receive_can.argtypes = (ctypes.c_void_p, ctypes.c_uint16, u8p, ctypes.c_uint8, ctypes.c_uint64)
    lib.sashil_board_receive_can.restype = None
    lib.sashil_board_next_event_us.argtypes = (ctypes.c_void_p,)
    lib.sashil_board_next_event_us.restype = ctypes.c_uint64
    lib.sashil_board_sessions.argtypes = (ctypes.c_void_p,)
    lib.sashil_board_sessions.restype = ctypes.c_uint16
    lib.sashil_board_watchdog_trips.argtypes = (ctypes.c_void_p,)
    lib.sashil_board_watchdog_trips.restype = ctypes.c_uint16
    lib.sashil_board_set_max_rate.argtypes = (ctypes.c_void_p, ctypes.c_uint16)
    lib.sashil_board_set_max_rate.restype = None
    lib.sashil_board_refusals.argtypes = (ctypes.c_void_p,)
    lib.sashil_board_refusals.restype = ctypes.c_uint16
    lib.sashil_board_set_status_flags.argtypes = (ctypes.c_void_p, ctypes.c_uint8)
    lib.sashil_board_set_status_flags.restype = None
    lib.sashil_board_overruns.argtypes = (ctypes.c_void_p,)
    lib.sashil_board_overruns.restype = ctypes.c_uint32
    lib.sashil_board_bad_frames.argtypes = (ctypes.c_void_p,)
    lib.sashil_board_bad_frames.restype = ctypes.c_uint32
    return lib


ReadEncoders = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_int32))
ReadCurrent = ctypes.CFUNCTYPE(ctypes.c_int16, ctypes.c_void_p)
SetCoil = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_uint16)
SetRoadSpeed = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int32)
SensorFlags = ctypes.CFUNCTYPE(ctypes.c_uint8, ctypes.c_void_p)
Send = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint8), ctypes.c_size_t)
SendCan = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_uint16, ctypes.POINTER(ctypes.c_uint8), ctypes.c_uint8)


class Edge(ctypes.Structure):
    """``sashil_edge`` of sashil_board.h: one encoder's last count change (time in µs, direction)."""

    _fields_ = [("time_us", ctypes.c_uint32), ("dir", ctypes.c_int8)]


ReadEdges = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.POINTER(Edge), ctypes.POINTER(Edge))


class Hal(ctypes.Structure):
    """``sashil_hal`` of sashil_board.h: the board's hardware interface as callbacks."""

    _fields_ = [
        ("ctx", ctypes.c_void_p),
        ("read_encoders", ReadEncoders),
        ("read_current", ReadCurrent),
        ("set_coil", SetCoil),
        ("set_road_speed", SetRoadSpeed),
        ("sensor_flags", SensorFlags),
        ("send", Send),
        ("send_can", SendCan),
        ("read_edges", ReadEdges),
    ]


class StreamState(ctypes.Structure):
    """``sashil_stream`` of sashil_frame.h (the same layout)."""

    _fields_ = [
        ("buf", ctypes.c_uint8 * 40),
        ("n", ctypes.c_size_t),
        ("skipping", ctypes.c_int),
        ("frames", ctypes.c_uint32),
        ("bad_frames", ctypes.c_uint32),
    ]
