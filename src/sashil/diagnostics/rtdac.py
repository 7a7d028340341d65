"""``sashil doctor --driver rtdac``: find the RT-DAC/USB2, read its header, time the exchange, and
(``--walk``) find the rig's wiring with the operator at the terminal.

The walk (:mod:`sashil.diagnostics.rtdac_walk`) trusts none of the ``rtdac`` section's wiring: it
finds the arm's counter from an angle the operator sets, pulses every PWM and D/A channel to find
the coil's output and sense and the road motor's output and encoder, measures the road wheel's
counts per revolution and the coil's map, and writes what it found, with the keys it confirmed
(``rtdac.confirmed``), as a fragment of the section for the lab to review. Its table rows say what
each step found or why it found nothing.
"""

from __future__ import annotations

import math
import select
import statistics
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TextIO

import yaml

from sashil.config.rtdac_section import WIRING_KEYS
from sashil.diagnostics import FAIL, OK, WARN, Check
from sashil.diagnostics.rtdac_walk import Walk, WalkOptions
from sashil.drivers.rtdac_bus import LOOP_SHARE, highest_rate_hz
from sashil.drivers.rtdac_rig import RtdacRig
from sashil.drivers.rtdac_usb import UDEV_FILE, UDEV_RULE, BoardLink, describe_device
from sashil.errors import DriverError, SashilError

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

#: what the walk's pulses drive: a low duty, or a low voltage
PULSE_DUTY = 0.1
PULSE_VOLTS = 1.0
PULSE_S = 0.3
ROAD_S = 1.0

NO_WATCHDOG = (
    "the RT-DAC/USB2 has no watchdog: it keeps its last outputs when the host goes quiet. sashil rests the coil "
    "and the road motor and checks the board's readback on every stop it runs (a signal, a fault, a law that "
    "raises, the loop process killed); it cannot when both of its processes die or the cable is pulled"
)
E_STOP = "wire the rig's hardware E-stop to cut the coil's and the road motor's power; keep it in reach"
HEARTBEAT = (
    "wire a retriggerable watchdog relay on the power stages to a digital output and set rtdac.heartbeat_bit "
    "(docs: the heartbeat relay); and the E-stop, in reach"
)


def safe_stop_check(heartbeat_bit: int | None) -> Check:
    """What ends a stop the host cannot run: the heartbeat relay where its bit is set, else only the E-stop."""
    if heartbeat_bit is None:
        return Check("board", "safe stop", WARN, NO_WATCHDOG, HEARTBEAT)
    return Check(
        "board",
        "safe stop",
        OK,
        f"the RT-DAC/USB2 has no watchdog; digital output {heartbeat_bit} toggles every cycle (rtdac.heartbeat_bit) "
        "for a watchdog relay on the power stages, which drops them when the host stops: test that it does",
    )


def exchange_times(rig: RtdacRig, n: int) -> list[float]:
    """``n`` exchanges (write frame, read request, read frame) with the outputs at rest, each timed [s]."""
    times = []
    for _ in range(n):
        start = time.perf_counter()
        rig.exchange()
        times.append(time.perf_counter() - start)
    return times


def exchange_checks(rig: RtdacRig, n: int, rate_hz: float) -> list[Check]:
    """The exchange's round trip (median, p99) and the highest loop rate it leaves room for."""
    times = sorted(exchange_times(rig, n))
    median = statistics.median(times)
    p99 = times[min(len(times) - 1, math.ceil(0.99 * len(times)) - 1)]
    data = {
        "n": n,
        "median_us": round(median * 1e6, 1),
        "p99_us": round(p99 * 1e6, 1),
        "max_us": round(times[-1] * 1e6, 1),
    }
    highest = highest_rate_hz(p99)
    data["highest_rate_hz"] = highest
    round_trip = Check(
        "board", "exchange", OK, f"{n} exchanges: median {data['median_us']:g} us, p99 {data['p99_us']:g} us", data=data
    )
    ok = highest >= rate_hz
    rate = Check(
        "board",
        "rate",
        OK if ok else WARN,
        f"the exchange leaves room for {highest} Hz (p99 and {LOOP_SHARE:.0%} of a period for the loop); "
        f"loop.rate_hz is {rate_hz:g}",
        "" if ok else f"--set loop.rate_hz={highest} (or a faster USB port: no hub, a USB 2 port of its own)",
    )
    return [round_trip, rate]


def board_checks(run: RunSpec, round_trips: int) -> tuple[list[Check], RtdacRig | None]:
    """Find and open the board, read its header and map, time the exchange; the rig is left open
    (outputs at rest) for the walk, or None when it could not be opened."""
    rig = RtdacRig.from_parts(run.rig)
    checks: list[Check] = []
    try:
        rig.configure()
    except SashilError as err:
        text = str(err)
        fix = ""
        if "permission denied" in text:
            fix = f"echo '{UDEV_RULE}' | sudo tee {UDEV_FILE} && sudo udevadm control --reload, then replug"
        elif "another program holds" in text:
            fix = "close the other program (MATLAB/Simulink, INTECO's toolbox, another sashil)"
        elif "no RT-DAC/USB2 found" in text:
            fix = "plug the board in and power it; lsusb lists it"
        elif "USB link" in text:
            fix = "plug the board into a high-speed (USB 2.0) port with no USB 1.1 hub between; lsusb -t shows 480M"
        checks.append(Check("board", "usb", FAIL, text, fix))
        rig.close()
        return checks, None
    assert rig.header is not None and rig.map is not None
    where = describe_device(rig.link.dev)
    checks.append(Check("board", "usb", OK, f"RT-DAC/USB2 at {where}"))
    checks.append(link_check(rig.link, run.loop.rate_hz))
    checks.append(
        Check(
            "board",
            "header",
            OK,
            rig.header.describe(),
            data={"logic": rig.header.logic, "application": rig.header.application},
        )
    )
    checks.append(Check("board", "register map", OK, rig.map.describe()))
    checks += exchange_checks(rig, round_trips, run.loop.rate_hz)
    checks.append(safe_stop_check(rig.wiring.heartbeat_bit))
    return checks, rig


def link_check(link: BoardLink, rate_hz: float) -> Check:
    """What the board said of itself at open (ids, strings, speed, stale frames) and whether its bus
    carries ``rate_hz``."""
    limit = link.max_rate_hz
    ok = limit is None or rate_hz <= limit
    fix = "" if ok else f"a high-speed (USB 2.0) port with no USB 1.1 hub between, or --set loop.rate_hz={limit}"
    return Check("board", "link", OK if ok else WARN, link.summary(), fix, data=link.facts())


# the walk ------------------------------------------------------------------------------------------
def terminal_asker(stream: TextIO = sys.stdin, out: TextIO = sys.stdout) -> Callable[[str], str | None]:
    """An ask that prints its prompt once and returns the operator's line, or None while none has come
    (so the walk keeps reading the board between the operator's keys)."""

    def ask(prompt: str) -> str | None:
        if prompt:
            out.write(prompt)
            out.flush()
        ready, _, _ = select.select([stream], [], [], 0.002)
        if not ready:
            return None
        line = stream.readline()
        if not line:
            return "s"  # the input ended: skip what is left
        if not stream.isatty():
            out.write(line)  # a scripted answer: shown where a terminal would echo it
        return line.rstrip("\n")

    return ask


def walk_checks(
    rig: RtdacRig,
    fragment_path: str,
    ask: Callable[[str], str | None],
    say: Callable[[str], None],
    options: WalkOptions | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> list[Check]:
    """The walk (:mod:`sashil.diagnostics.rtdac_walk`), one row a step, then the fragment written for
    review; every output at rest at the end, confirmed by the board's readback."""
    walk = Walk(rig, ask, say, options or WalkOptions(), clock, sleep)
    try:
        walk.run()
    finally:
        walk.rest()
    checks = [Check("walk", step, OK if ok else WARN, text) for step, ok, text in walk.outcomes]
    at_rest = walk.at_rest()
    checks.append(
        Check(
            "walk",
            "outputs at rest",
            OK if at_rest else FAIL,
            "every PWM at duty 0 and every D/A at 0 V, confirmed by the readback"
            if at_rest
            else "the readback did not confirm every output at rest",
            "" if at_rest else E_STOP,
        )
    )
    if not walk.found:
        checks.append(Check("walk", "fragment", WARN, "the walk found nothing (every step skipped or nothing moved)"))
        return checks
    text = fragment_text(walk.found, walk.confirmed_keys())
    try:
        with open(fragment_path, "w", encoding="utf-8") as handle:
            handle.write(text)
    except OSError as err:
        raise DriverError(f"--fragment {fragment_path}: cannot write ({err.strerror})") from None
    confirmed = walk.confirmed_keys()
    left = [key for key in WIRING_KEYS if key not in confirmed]
    checks.append(
        Check(
            "walk",
            "fragment",
            OK if not left else WARN,
            f"written to {fragment_path}: {len(confirmed)} of {len(WIRING_KEYS)} wiring keys confirmed"
            + (f"; unconfirmed (the config's guesses, under the bring-up caps): {', '.join(left)}" if left else ""),
            f"review {fragment_path}, then run with --config {fragment_path}",
            data={"found": dict(walk.found), "confirmed": confirmed},
        )
    )
    return checks


def fragment_text(found: dict[str, Any], confirmed: list[str]) -> str:
    """The fragment of the ``rtdac`` section the walk writes: what it found, and which wiring keys
    it confirmed (a group not wholly confirmed runs under its bring-up cap)."""
    section = {**found, "confirmed": confirmed}
    return (
        "# the RT-DAC wiring sashil doctor --walk found on this bench: review it, then --config this file.\n"
        "# rtdac.confirmed lists the wiring keys the walk confirmed; the coil and the road motor run under\n"
        "# rtdac.bringup_current_max_a and rtdac.bringup_road_output until all of their keys are confirmed.\n"
        + yaml.safe_dump({"driver": {"name": "rtdac"}, "rtdac": section}, sort_keys=False)
    )


def rtdac_checks(
    run: RunSpec,
    round_trips: int,
    walk: bool = False,
    fragment_path: str = "rtdac-wiring.yaml",
    ask: Callable[[str], str | None] | None = None,
    say: Callable[[str], None] | None = None,
    options: WalkOptions | None = None,
) -> list[Check]:
    """The board's checks, and the walk on request; the board is left with both outputs at rest."""
    checks, rig = board_checks(run, round_trips)
    if rig is None:
        return checks
    try:
        if walk:
            checks += walk_checks(rig, fragment_path, ask or terminal_asker(), say or print, options)
    finally:
        rig.deactivate()
        confirmed = rig.safe_state.get("safe_state_confirmed")
        rig.close()
    checks.append(
        Check(
            "board",
            "at rest",
            OK if confirmed else FAIL,
            "both outputs at rest, confirmed by the board's readback"
            if confirmed
            else "the readback did not confirm both outputs at rest",
            "" if confirmed else E_STOP,
        )
    )
    return checks
