"""The port's checks: the device file, this user's permission on it, a USB-serial adapter's
latency timer, and a SocketCAN interface's state, bitrate and error counters.

sysfs is read from ``sys_root`` and ``ip``'s JSON report comes from ``ip_json`` (a callable),
so tests feed fixtures; file permission goes through ``access`` (``os.access`` by default).
"""

from __future__ import annotations

import grp
import json
import os
import pwd
import stat
import subprocess
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from sashil.diagnostics import FAIL, OK, WARN, Check


def _check(name: str, status: str, found: str, fix: str = "") -> Check:
    return Check("port", name, status, found, fix)


def _read(path: Path) -> str | None:
    try:
        return path.read_text().strip()
    except OSError:
        return None


def is_url(port: str) -> bool:
    return "://" in port


def exists(port: str) -> Check:
    if os.path.exists(port):
        real = os.path.realpath(port)
        return _check("exists", OK, port if real == port else f"{port} -> {real}")
    if os.path.islink(port):
        return _check(
            "exists",
            FAIL,
            f"{port} is a link to {os.readlink(port)}, which does not exist",
            "is the device plugged in?",
        )
    return _check(
        "exists", FAIL, f"{port} does not exist", "plug the adapter in; `ls /dev/serial/by-id/` lists the serial ports"
    )


def _user_groups(user: str, primary: int) -> set[int]:
    """The groups the user database gives ``user`` (which a new login gets)."""
    return {g.gr_gid for g in grp.getgrall() if user in g.gr_mem} | {primary}


def permission(port: str, access: Callable[[str, int], bool] = os.access) -> Check:
    """Whether this user may open ``port`` for reading and writing; names the group to join."""
    if access(port, os.R_OK | os.W_OK):
        return _check("permission", OK, "read and write allowed")
    info = os.stat(port)
    mode = stat.filemode(info.st_mode)
    try:
        group = grp.getgrgid(info.st_gid).gr_name
    except KeyError:
        group = str(info.st_gid)
    found = f"no read/write permission on {port} ({mode}, group {group})"
    if not info.st_mode & stat.S_IRGRP or not info.st_mode & stat.S_IWGRP:
        return _check("permission", FAIL, found, f'`sudo chmod g+rw {port}` (or a udev rule that sets MODE="0660")')
    me = pwd.getpwuid(os.getuid())
    if info.st_gid in _user_groups(me.pw_name, me.pw_gid):
        return _check(
            "permission", FAIL, found + f"; {me.pw_name} joined {group} after this login", "log out and in again"
        )
    return _check("permission", FAIL, found, f"`sudo usermod -aG {group} $USER`, then log out and in again")


def latency_timer(port: str, rate_hz: float, sys_root: Path = Path("/sys")) -> Check:
    """A USB-serial adapter's latency timer (ms): the longest it holds received bytes back."""
    name = os.path.basename(os.path.realpath(port))
    for path in (
        sys_root / "bus" / "usb-serial" / "devices" / name / "latency_timer",
        sys_root / "class" / "tty" / name / "device" / "latency_timer",
    ):
        text = _read(path)
        if text is None or not text.isdigit():
            continue
        ms = int(text)
        fix = f'`echo 1 | sudo tee {path}` (a udev rule ATTR{{latency_timer}}="1" keeps it)'
        if ms <= 1:
            return _check("latency_timer", OK, f"{ms} ms ({path})")
        period_ms = 1e3 / rate_hz
        status = FAIL if ms >= period_ms else WARN
        found = f"{ms} ms: samples arrive in bursts up to {ms} ms apart (the period is {period_ms:g} ms)"
        return _check("latency_timer", status, found, fix)
    if name.startswith("ttyUSB"):
        return _check("latency_timer", WARN, f"{name}: a USB-serial adapter without latency_timer in sysfs")
    if name.startswith("ttyACM"):
        return _check("latency_timer", OK, f"{name}: a USB CDC-ACM device (no latency timer)")
    if os.path.dirname(os.path.realpath(port)) == "/dev/pts":
        return _check("latency_timer", OK, f"/dev/pts/{name}: a pseudo-terminal (no latency timer)")
    return _check("latency_timer", OK, f"{name}: not a USB-serial adapter (no latency timer)")


def ip_link_json(interface: str) -> str | None:
    """``ip -details -statistics -json link show dev INTERFACE``'s output, or None."""
    try:
        done = subprocess.run(
            ["ip", "-details", "-statistics", "-json", "link", "show", "dev", interface],
            capture_output=True,
            text=True,
            timeout=5,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout if done.returncode == 0 else None


def socketcan(
    interface: str,
    bitrate: int,
    sys_root: Path = Path("/sys"),
    ip_json: Callable[[str], str | None] = ip_link_json,
) -> list[Check]:
    """A SocketCAN interface: it exists and is up, its bitrate against ``driver.can_bitrate``, and
    its controller state and error counters (from the kernel's ``ip`` report)."""
    up_fix = f"`sudo ip link set {interface} up type can bitrate {bitrate}`"
    net = sys_root / "class" / "net" / interface
    if not net.is_dir():
        return [_check("can_interface", FAIL, f"no network interface {interface}", "is the CAN adapter plugged in?")]
    flags = _read(net / "flags")
    up = flags is not None and int(flags, 16) & 0x1
    if not up:
        return [_check("can_interface", FAIL, f"{interface} is down", up_fix)]
    checks = [_check("can_interface", OK, f"{interface} is up ({_read(net / 'operstate') or 'state unknown'})")]
    report = ip_json(interface)
    try:
        info = json.loads(report)[0]["linkinfo"]["info_data"] if report else None
    except (ValueError, LookupError, TypeError):
        info = None
    if info is None:
        checks.append(_check("can_bitrate", WARN, f"no CAN details for {interface} from `ip -details link`"))
        return checks
    checks.append(_bitrate(interface, info, bitrate))
    checks.append(_errors(interface, info))
    return checks


def _bitrate(interface: str, info: dict[str, Any], bitrate: int) -> Check:
    got = info.get("bittiming", {}).get("bitrate")
    if got == bitrate:
        return _check("can_bitrate", OK, f"{got} bit/s")
    fix = f"`sudo ip link set {interface} down && sudo ip link set {interface} up type can bitrate {bitrate}`"
    return _check("can_bitrate", FAIL, f"{got} bit/s; driver.can_bitrate is {bitrate}", fix)


def _errors(interface: str, info: dict[str, Any]) -> Check:
    state = str(info.get("state", "unknown"))
    counters = info.get("berr_counter", {})
    found = f"{state}, error counters tx {counters.get('tx', '?')} rx {counters.get('rx', '?')}"
    if state == "BUS-OFF":
        fix = f"check the wiring and termination, then `sudo ip link set {interface} type can restart`"
        return _check("can_errors", FAIL, found, fix)
    if state in ("ERROR-WARNING", "ERROR-PASSIVE"):
        return _check("can_errors", WARN, found, "check the bus termination (120 ohm at each end) and the bitrate")
    return _check("can_errors", OK, found)


def tty_checks(port: str, rate_hz: float, sys_root: Path = Path("/sys"), access: Any = os.access) -> list[Check]:
    """A serial device file: it exists, this user may open it, its latency timer."""
    found = exists(port)
    if found.status == FAIL:
        return [found]
    allowed = permission(port, access)
    return [found, allowed, latency_timer(port, rate_hz, sys_root)]


def port_checks(
    driver: Mapping[str, Any],
    rate_hz: float,
    sys_root: Path = Path("/sys"),
    access: Any = os.access,
    ip_json: Callable[[str], str | None] = ip_link_json,
) -> list[Check]:
    """The checks of the config's ``driver`` section's port (serial or CAN)."""
    port = str(driver["port"])
    if driver["name"] == "can" and driver["can_interface"] != "slcan":
        if driver["can_interface"] == "socketcan":
            return socketcan(port, int(driver["can_bitrate"]), sys_root, ip_json)
        return [_check("can_interface", OK, f"python-can interface {driver['can_interface']}: checked when opened")]
    if is_url(port):
        return [_check("exists", OK, f"{port}: a pyserial URL (no device file to check)")]
    return tty_checks(port, rate_hz, sys_root, access)


__all__ = ["exists", "latency_timer", "permission", "port_checks", "socketcan", "tty_checks"]
