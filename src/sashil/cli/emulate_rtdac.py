"""``sashil emulate --transport rtdac``: the emulated RT-DAC/USB2 served on a Unix socket.

The host reaches it through pyusb with ``--driver rtdac --port emulated:PATH``
(:mod:`sashil.drivers.emulator.rtdac_usb`). The board's wiring is the config's ``rtdac`` section
(``--set rtdac.arm_encoder=3`` wires the emulated bench differently from a host's config).
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable
from typing import Any

from sashil.errors import ConfigError


def add_rtdac_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("RT-DAC/USB2 board (--transport rtdac; times count from the host's claim)")
    group.add_argument(
        "--logic",
        choices=("0103", "0111"),
        default="0103",
        help="the register map the board is laid out by (default 0103)",
    )
    group.add_argument(
        "--header-logic",
        metavar="HEX",
        help="the logic version the header says (default: --logic's; another: a board no map serves)",
    )
    group.add_argument(
        "--application", default="SASHIL", metavar="NAME", help="the header's application name (default SASHIL)"
    )
    group.add_argument(
        "--stage-gain",
        type=float,
        default=1.0,
        metavar="G",
        help="the power stage's true current is G times what rtdac.coil_map_* says (default 1)",
    )
    group.add_argument(
        "--road-tau-ms",
        type=float,
        default=20.0,
        metavar="MS",
        help="the road motor's time constant: its speed follows its output with this first-order lag (default 20)",
    )
    add_rtdac_faults(group)


def add_rtdac_faults(group: Any) -> None:
    """The emulated board's faults and the bench's own (a relay, counters an earlier program left)."""
    group.add_argument(
        "--vanish-after", type=float, metavar="S", help="the board disappears from the bus after S seconds"
    )
    group.add_argument(
        "--stuck-busy-after", type=float, metavar="S", help="the coil sense A/D's busy bit sticks after S seconds"
    )
    group.add_argument(
        "--short-frame-after", type=float, metavar="S", help="read frames come two bytes short after S seconds"
    )
    group.add_argument("--timeout-after", type=float, metavar="S", help="reads go unanswered after S seconds")
    group.add_argument("--permission-denied", action="store_true", help="opening the board is refused (no udev rule)")
    group.add_argument(
        "--counter-preset",
        type=int,
        default=0,
        metavar="N",
        help="every counter shows N at power-up, as an earlier program left it (default 0)",
    )
    group.add_argument(
        "--index-reset-after", type=float, metavar="S", help="the arm's counter resets to 0 once after S seconds"
    )
    group.add_argument(
        "--ignore-word",
        type=int,
        action="append",
        default=[],
        metavar="W",
        help="the board does not take word W of a write frame (repeatable)",
    )
    group.add_argument(
        "--relay-bit",
        type=int,
        metavar="B",
        help="a watchdog relay on the power stages, retriggered by digital output B's toggles (default: none)",
    )
    group.add_argument(
        "--relay-ms",
        type=float,
        default=20.0,
        metavar="MS",
        help="the relay opens MS after the last toggle (default 20)",
    )

    group.add_argument(
        "--full-speed",
        action="store_true",
        help="the board enumerates at full speed (12 Mbit/s, 64-byte packets), as behind a USB 1.1 hub",
    )
    group.add_argument(
        "--missing-endpoint",
        choices=("02", "84"),
        metavar="EP",
        help="endpoint 0x02 or 0x84 is missing from the board's interface (other firmware)",
    )
    group.add_argument(
        "--stale-frames",
        type=int,
        default=0,
        metavar="N",
        help="N frames an earlier host asked for and never read wait on endpoint 4 (default 0)",
    )
    group.add_argument(
        "--halt-after",
        type=float,
        metavar="S",
        help="endpoint 0x02 (frames to the board) halts after S seconds, until the host clears its halt (once)",
    )
    group.add_argument(
        "--wedge-after",
        type=float,
        metavar="S",
        help="every transfer fails after S seconds, until the host resets or reopens the board (once)",
    )


def _word(option: str, value: int) -> int:
    if not 1 <= value <= 251:
        raise ConfigError(f"{option}: expected a word of a write frame from 1 to 251, got {value}")
    return value


def relay_line(relay: Any) -> str:
    """The relay's facts as one line: its last retrigger and its opening (monotonic ns, comparable
    across the machine's processes), and how often a pause opened it during a session."""
    if relay.last_toggle_ns is None:
        return "relay: never retriggered (open: the power stages were never powered)"
    return (
        f"relay: last toggle at {relay.last_toggle_ns} ns, open from {relay.opened_at_ns()} ns "
        f"({relay.hold_ms:g} ms later); dropped {relay.drops} times while retriggered"
    )


def _seconds(option: str, value: float | None) -> float | None:
    if value is not None and not value >= 0.0:
        raise ConfigError(f"{option}: expected seconds >= 0, got {value:g}")
    return value


def _faults(args: argparse.Namespace) -> tuple[Any, Any, Any]:
    """The board's faults, the bench's relay (None: none wired) and the USB side's faults, checked."""
    from sashil.drivers.emulator.rtdac_board import BoardFaults, Relay
    from sashil.drivers.emulator.rtdac_usb import UsbFaults

    faults = BoardFaults(
        vanish_after_s=_seconds("--vanish-after", args.vanish_after),
        stuck_busy_after_s=_seconds("--stuck-busy-after", args.stuck_busy_after),
        short_frame_after_s=_seconds("--short-frame-after", args.short_frame_after),
        timeout_after_s=_seconds("--timeout-after", args.timeout_after),
        permission_denied=args.permission_denied,
        counter_preset=args.counter_preset,
        index_reset_after_s=_seconds("--index-reset-after", args.index_reset_after),
        ignored_words=tuple(_word("--ignore-word", w) for w in args.ignore_word),
    )
    relay = None
    if args.relay_bit is not None:
        if not 0 <= args.relay_bit <= 25:
            raise ConfigError(f"--relay-bit: expected a digital output bit from 0 to 25, got {args.relay_bit}")
        if not 0.0 < args.relay_ms <= 10_000.0:
            raise ConfigError(f"--relay-ms: expected milliseconds in (0, 10000], got {args.relay_ms:g}")
        relay = Relay(args.relay_bit, args.relay_ms)
    if not 0 <= args.stale_frames <= 64:
        raise ConfigError(f"--stale-frames: expected a count from 0 to 64, got {args.stale_frames}")
    usb_faults = UsbFaults(
        full_speed=args.full_speed,
        missing_endpoint=None if args.missing_endpoint is None else int(args.missing_endpoint, 16),
        stale_frames=args.stale_frames,
        halt_after_s=_seconds("--halt-after", args.halt_after),
        wedge_after_s=_seconds("--wedge-after", args.wedge_after),
    )
    return faults, relay, usb_faults


def run_rtdac(
    args: argparse.Namespace, config: Any, operator: Any, duration: float | None, announce: Callable[[str], None]
) -> int:
    from sashil.drivers.emulator.rtdac_board import BoardIdentity, build_board
    from sashil.drivers.emulator.rtdac_usb import BoardServer

    if not args.link:
        raise ConfigError("--link: expected the path of the board's socket (the host opens --port emulated:PATH)")
    if not 0.0 < args.stage_gain <= 10.0:
        raise ConfigError(f"--stage-gain: expected a gain in (0, 10], got {args.stage_gain:g}")
    faults, relay, usb_faults = _faults(args)
    logic_word = int(args.logic, 16)
    if args.header_logic is not None:
        try:
            logic_word = int(args.header_logic, 16)
        except ValueError:
            raise ConfigError(
                f"--header-logic: expected a hex number such as 0200, got {args.header_logic!r}"
            ) from None
        if not 0 <= logic_word <= 0xFFFF:
            raise ConfigError(f"--header-logic: expected 0000..FFFF, got {args.header_logic}")
    if not args.application.isascii() or len(args.application) > 6:
        raise ConfigError(f"--application: expected up to 6 ASCII characters, got {args.application!r}")
    identity = BoardIdentity(logic_version=logic_word, application=args.application)
    if not 0.0 < args.road_tau_ms <= 10_000.0:
        raise ConfigError(f"--road-tau-ms: expected milliseconds in (0, 10000], got {args.road_tau_ms:g}")
    board = build_board(
        config, args.logic, identity, operator, faults, args.stage_gain, args.road_tau_ms * 1e-3, relay=relay
    )
    try:
        server = BoardServer(board, args.link, usb_faults=usb_faults)
    except OSError as err:
        raise ConfigError(f"--link {args.link}: cannot create the socket ({err.strerror})") from None

    def _stop(signum: int, frame: object) -> None:
        server.stop()

    # the board answers at once, as an FPGA does: best-effort SCHED_FIFO above the loop's 50
    from sashil.runtime.rt_setup import RealtimeSetup

    realtime = RealtimeSetup(priority=args.priority)
    realtime.apply()
    handlers = {sig: signal.signal(sig, _stop) for sig in (signal.SIGTERM, signal.SIGINT)}
    print(
        f"sashil emulate: rtdac board on {args.link} (logic {logic_word:04X} laid out as {args.logic}, "
        f"application {args.application!r}); the host opens --driver rtdac --port emulated:{args.link}",
        flush=True,
    )
    if operator is not None:
        announce("--hold-deg: the arm is held at each host claim of the board; connect with drop-test or calibrate")
    try:
        why = server.run(duration)
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        realtime.restore()
    state = "at rest" if board.at_rest() else "NOT at rest (the board keeps its last outputs)"
    if relay is not None:
        print(f"sashil emulate: {relay_line(relay)}", file=sys.stderr, flush=True)
    print(
        f"sashil emulate: {why}; exchanges {board.exchanges}, bad frames from host {board.bad_frames}, outputs {state}",
        file=sys.stderr,
        flush=True,
    )
    return 0
