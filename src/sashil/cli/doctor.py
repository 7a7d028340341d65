"""``sashil doctor``: is this PC, this port and this board ready for the rig? One table of checks."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from sashil.cli.common import add_config_options, add_driver_options, resolve_config
from sashil.diagnostics import FAIL, WARN, Check, exit_code, table
from sashil.errors import ConfigError

EXAMPLE = "sashil doctor --driver serial --port /dev/ttyUSB0    (INTECO's board: sashil doctor --driver rtdac --walk)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_driver_options(parser)
    parser.add_argument("--json", action="store_true", help="the same table as JSON, for scripts")
    parser.add_argument(
        "--jitter-s",
        type=float,
        default=5.0,
        metavar="S",
        help="length of the wake-up jitter measurement at loop.rate_hz (default 5 s; 0: skip it)",
    )
    parser.add_argument(
        "--round-trips",
        type=int,
        default=1000,
        metavar="N",
        help="host-paced round trips to the board at loop.rate_hz (default 1000)",
    )
    walk = parser.add_argument_group("RT-DAC/USB2 (--driver rtdac)")
    walk.add_argument(
        "--walk",
        action="store_true",
        help="name the rig's channels with the operator at the terminal: move the arm, pulse the coil, run the "
        "road motor (each step confirmed, each ended at rest), then write a config fragment to review",
    )
    walk.add_argument(
        "--fragment",
        default="rtdac-wiring.yaml",
        metavar="FILE",
        help="where --walk writes the wiring it found (default rtdac-wiring.yaml)",
    )
    parser.add_argument("--sys-root", default="/sys", metavar="DIR", help=argparse.SUPPRESS)  # tests: a sysfs tree


def _check_arguments(args: argparse.Namespace) -> None:
    if not (args.jitter_s >= 0 and args.jitter_s <= 600):
        raise ConfigError(f"--jitter-s: expected seconds in [0, 600], got {args.jitter_s:g}")
    if not 1 <= args.round_trips <= 1_000_000:
        raise ConfigError(f"--round-trips: expected a count in [1, 1000000], got {args.round_trips}")
    if args.walk and args.json:
        raise ConfigError("--walk: asks the operator at a terminal; it does not run with --json")


def run(args: argparse.Namespace) -> int:
    _check_arguments(args)
    from sashil.engine import assemble

    run_spec = assemble(resolve_config(args))
    backend, loop = run_spec.rig.backend, run_spec.loop
    if args.walk and backend != "rtdac":
        raise ConfigError(f"--walk: names an RT-DAC/USB2's channels (--driver rtdac), not driver {backend}'s")
    from sashil.diagnostics.machine import machine_checks, read_facts

    sys_root = Path(args.sys_root)
    checks: list[Check] = machine_checks(read_facts(sys_root), loop.rt)
    if args.jitter_s > 0:
        from sashil.diagnostics.jitter import judge, measure

        checks.append(judge(measure(loop, args.jitter_s)))
    if backend == "rtdac":
        from sashil.diagnostics.rtdac import rtdac_checks

        checks += rtdac_checks(run_spec, args.round_trips, args.walk, args.fragment)
    elif run_spec.rig.values.get("port") is None:
        checks.append(Check("port", "port", "ok", f"driver {backend}: no port (add --driver and --port)"))
    else:
        from sashil.diagnostics.board import board_checks
        from sashil.diagnostics.port import port_checks

        port_rows = port_checks({"name": backend, **run_spec.rig.values}, loop.rate_hz, sys_root)
        checks += port_rows
        if any(row.status == FAIL for row in port_rows):
            checks.append(Check("board", "hello", FAIL, "not checked: the port failed above", "fix the port first"))
        else:
            checks += board_checks(run_spec, args.round_trips)
    code = exit_code(checks)
    if args.json:
        print(json.dumps({"exit_code": code, "checks": [c.as_dict() for c in checks]}, indent=2))
    else:
        print(table(checks))
        fails = sum(c.status == FAIL for c in checks)
        warns = sum(c.status == WARN for c in checks)
        print(f"\n{len(checks)} checks: {fails} failed, {warns} warnings")
    return code
