"""``sashil emulate``: the simulated rig behind a pseudo-terminal, speaking the serial or SLCAN protocol,
or behind an emulated RT-DAC/USB2 on a Unix socket (``--transport rtdac``, for ``--driver rtdac --port
emulated:PATH``)."""

from __future__ import annotations

import argparse
import math
import signal
import sys
from typing import TYPE_CHECKING

from sashil.cli.common import add_config_options, positive_seconds, resolve_config
from sashil.cli.emulate_rtdac import add_rtdac_arguments, run_rtdac
from sashil.errors import ConfigError, DriverError

if TYPE_CHECKING:
    from sashil.drivers.emulator import Faults, Operator

EXAMPLE = "sashil emulate --transport slcan --link /tmp/rig --hold-deg -5 --release-after 1"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    parser.add_argument(
        "--transport",
        choices=("serial", "slcan", "rtdac"),
        default="serial",
        help="sashil serial frames, an SLCAN (LAWICEL) CAN adapter, or INTECO's RT-DAC/USB2 at the USB layer "
        "(a socket at --link; the host opens it with --driver rtdac --port emulated:PATH) (default serial)",
    )
    parser.add_argument(
        "--board",
        choices=("auto", "c", "python"),
        default="auto",
        help="the board's logic: c (the firmware's C code, drivers/firmware, built with the system C compiler), "
        "python (drivers/emulator/device.py), or auto: c where a C compiler is found (default)",
    )
    parser.add_argument(
        "--rate",
        type=float,
        metavar="HZ",
        help="fixed device sample rate; a host asking for another is refused (default: the host's)",
    )
    parser.add_argument("--link", metavar="PATH", help="also make PATH a symlink to the pty")
    parser.add_argument(
        "--duration", type=float, metavar="S", help="exit after S seconds (default: until SIGINT/SIGTERM)"
    )
    parser.add_argument(
        "--truth",
        metavar="FILE",
        help="ground truth: write FILE (CSV) on exit with one row per sample sent: seq (as on the wire), "
        "device_time_us, plant_time_s and the plant's true theta_true_rad, theta_dot_true_rad_s, "
        "z_true, current_true_a, torque_true_nm, theta_road_true_rad; join with the host's data.csv on seq",
    )
    op = parser.add_argument_group("operator (drop test)")
    op.add_argument(
        "--hold-deg",
        type=float,
        nargs="+",
        metavar="DEG",
        help="hold the arm at DEG when the host connects (Configure); several: the next one at each Configure, "
        "round and round (a calibration plan's drop angles)",
    )
    op.add_argument("--release-after", type=float, default=1.0, metavar="S", help="let go S seconds later (default 1)")
    op.add_argument(
        "--prompts",
        metavar="FILE",
        help="the host's console (its stderr written to FILE, e.g. sashil calibrate ... 2> FILE): at each Configure "
        "the operator holds at the angle of the last 'press the arm to DEG deg' prompt there, as a person at the "
        "bench reads it (a repeated step gets its own angle); --hold-deg's angles before the first prompt",
    )
    parser.add_argument(
        "--priority",
        type=int,
        default=60,
        metavar="P",
        help="SCHED_FIFO priority of the emulator, best effort (default 60, above the loop's 50)",
    )
    faults = parser.add_argument_group("fault injection (times count from the host's Configure)")
    faults.add_argument(
        "--drop-rate", type=float, default=0.0, metavar="P", help="drop outgoing frames with probability P"
    )
    faults.add_argument(
        "--corrupt-rate", type=float, default=0.0, metavar="P", help="send frames with a bad CRC with probability P"
    )
    faults.add_argument("--latency-ms", type=float, default=0.0, metavar="MS", help="delay every outgoing frame")
    faults.add_argument("--stall-after", type=float, metavar="S", help="go silent after S seconds")
    faults.add_argument("--disconnect-after", type=float, metavar="S", help="close the link after S seconds and exit")
    faults.add_argument("--stuck-sensor-after", type=float, metavar="S", help="freeze both encoders after S seconds")
    faults.add_argument("--seed", type=int, default=0, help="seed of the fault injection (default 0)")
    add_rtdac_arguments(parser)


def _probability(option: str, value: float) -> float:
    if not 0.0 <= value <= 1.0:
        raise ConfigError(f"{option}: expected a probability in [0, 1], got {value:g}")
    return value


def _seconds_or_none(option: str, value: float | None) -> float | None:
    if value is None:
        return None
    if not value >= 0.0:
        raise ConfigError(f"{option}: expected seconds >= 0, got {value:g}")
    return float(value)


def _start_truth_file(path: str) -> None:
    """Create the --truth file now (header only) so a path that cannot be written fails before the link is up."""
    from sashil.drivers.emulator import TRUTH_COLUMNS

    try:
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(",".join(TRUTH_COLUMNS) + "\n")
    except OSError as err:
        raise ConfigError(f"--truth {path}: cannot write ({err.strerror})") from None


def _announce(line: str) -> None:
    """The emulated operator's notices, on stderr beside the emulator's other status lines."""
    print(f"sashil emulate: {line}", file=sys.stderr, flush=True)


def _board(board: str) -> str:
    """``--board``: ``auto`` is the C board where this machine can build it, else the Python board."""
    from sashil.drivers import firmware

    if board == "auto":
        board = "c" if firmware.compiler() is not None else "python"
    if board == "c":
        try:
            firmware.library_path()  # built once per source hash; a machine that cannot build it is told why
        except DriverError as err:
            raise ConfigError(f"--board c: {err} (--board python runs the Python board)") from None
    return board


def _faults(args: argparse.Namespace) -> Faults:
    """The link's faults the options ask for (drops, corruption, latency, a stall, a disconnect, a stuck sensor)."""
    from sashil.drivers.emulator import Faults

    if args.latency_ms < 0:
        raise ConfigError(f"--latency-ms: expected >= 0, got {args.latency_ms:g}")
    return Faults(
        drop_rate=_probability("--drop-rate", args.drop_rate),
        corrupt_rate=_probability("--corrupt-rate", args.corrupt_rate),
        latency_ms=args.latency_ms,
        stall_after_s=_seconds_or_none("--stall-after", args.stall_after),
        disconnect_after_s=_seconds_or_none("--disconnect-after", args.disconnect_after),
        stuck_sensor_after_s=_seconds_or_none("--stuck-sensor-after", args.stuck_sensor_after),
        seed=args.seed,
    )


def _operator(args: argparse.Namespace) -> Operator | None:
    """The emulated operator of ``--hold-deg`` (reading the host's console with ``--prompts``), or None."""
    from sashil.drivers.emulator import HostConsole, Operator

    if args.hold_deg is not None:
        for angle in args.hold_deg:
            if not (math.isfinite(angle) and abs(angle) <= 90.0):
                raise ConfigError(f"--hold-deg: expected angles within ±90 deg, got {angle:g}")
        release = _seconds_or_none("--release-after", args.release_after) or 0.0
        console = HostConsole(args.prompts) if args.prompts is not None else None
        return Operator(args.hold_deg[0], release, tuple(args.hold_deg[1:]), announce=_announce, console=console)
    if args.prompts is not None:
        raise ConfigError("--prompts: expected --hold-deg too (the angles held before the host's first prompt)")
    return None


def run(args: argparse.Namespace) -> int:
    from sashil.drivers.emulator import Emulator, TruthLog, build_device
    from sashil.drivers.emulator.runner import open_transport
    from sashil.recording.data_file import write_data_csv

    config = resolve_config(args)
    if args.transport == "rtdac":
        if args.board == "c":
            raise ConfigError("--board c: the emulated RT-DAC/USB2 is a Python board (--board python or auto)")
        board = "python"
    else:
        board = _board(args.board)
    rate = None
    if args.rate is not None:
        rate = int(round(positive_seconds("--rate", args.rate)))
        if not 1 <= rate <= 20_000:
            raise ConfigError(f"--rate: expected 1..20000 Hz, got {args.rate:g}")
    faults = _faults(args)
    operator = _operator(args)
    duration = None if args.duration is None else positive_seconds("--duration", args.duration)
    from sashil.runtime.warmup import warm_kernels

    # the simulated rig's kernels load before the link opens, so no session's first Command waits on them
    warm_kernels()
    if args.transport == "rtdac":
        return run_rtdac(args, config, operator, duration, _announce)
    truth = None
    if args.truth is not None:
        truth = TruthLog()
        _start_truth_file(args.truth)
    link_kind = "serial" if args.transport == "serial" else "can"
    device = build_device(config, operator, faults, rate, truth, board=board, link=link_kind)
    try:
        transport = open_transport(args.transport, raw=board == "c", link=args.link)
    except OSError as err:
        raise ConfigError(f"--link {args.link}: cannot create the link ({err.strerror})") from None
    emulator = Emulator(device, transport)

    def _stop(signum: int, frame: object) -> None:
        emulator.request_stop()  # no lock in a handler: a second signal must not deadlock the first

    # a device's sample timer is not starved by the host: best-effort SCHED_FIFO above the loop's 50
    from sashil.runtime.rt_setup import RealtimeSetup

    realtime = RealtimeSetup(priority=args.priority)
    realtime.apply()
    handlers = {sig: signal.signal(sig, _stop) for sig in (signal.SIGTERM, signal.SIGINT)}
    link = f" (link {args.link})" if args.link else ""
    print(f"sashil emulate: {args.transport} rig on {transport.description}{link} ({board} board)", flush=True)
    if operator is not None:
        _announce(
            "--hold-deg: the arm is held at each host connection (Configure), also for a run or a sweep, "
            "which then start with the arm held; connect with drop-test or calibrate"
        )
        if args.prompts is not None:
            _announce(f"--prompts: the operator holds at the angle the host's last hold prompt in {args.prompts} asks")
    try:
        why = emulator.run(duration)
    finally:  # the caller's scheduling and signal handlers back (sashil emulate may run in-process)
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        realtime.restore()
        if truth is not None:  # stopped by SIGINT/SIGTERM, --duration, a disconnect or an error
            write_data_csv(args.truth, truth.columns())
            print(f"sashil emulate: truth: {len(truth)} samples written to {args.truth}", file=sys.stderr, flush=True)
    print(
        f"sashil emulate: {why}; samples sent {device.samples_sent}, bad frames from host {device.bad_frames}, "
        f"frames corrupted {transport.tx_corrupted}, watchdog trips {device.watchdog_trips}, late samples {device.overruns}",
        file=sys.stderr,
        flush=True,
    )
    return 0
