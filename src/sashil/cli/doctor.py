"""``sashil doctor``: is this PC, this port and this board ready for the rig? One table of checks.

With ``--driver rtdac --walk`` it also finds the rig's wiring to INTECO's RT-DAC/USB2 with the operator
(:mod:`sashil.diagnostics.rtdac_walk`: what the walk finds and what it does not) and writes it as a
fragment of the ``rtdac`` section, with the keys it confirmed in ``rtdac.confirmed``.
"""

from __future__ import annotations

import argparse
import json
import math
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
        help="find the rig's wiring with the operator at the terminal, trusting none of the rtdac section's: "
        "the arm's counter, counts per revolution and sign (the operator holds the arm at --arm-deg, then lets "
        "it rest at 0); which PWM or D/A channel drives the coil and which A/D senses it, which drives the road "
        "motor and which counter is its encoder, with its sign (each channel pulsed low for 0.3 s in turn); "
        "the road wheel's counts per revolution (the motor turns it, or the operator by hand, until a mark "
        "comes round), with the motor's speed per output and lag; the coil's map (output steps of a tenth of "
        "full against the sense, to rtdac.bringup_current_max_a). Each step that drives an output asks first "
        "(y/n), stays under the bring-up caps and ends at rest. Writes a fragment of the rtdac section with "
        "what it found and rtdac.confirmed (the keys it confirmed; a skipped or failed step confirms none). "
        "It does not find a PWM road motor's direction bit, a coil with no current sense, digital outputs "
        "or the board's own settings (PWM prescaler and mode, A/D gains)",
    )
    walk.add_argument(
        "--arm-deg",
        type=float,
        default=-5.0,
        metavar="DEG",
        help="the arm's marked angle for --walk [deg, theta2; the arm rests at 0] (default -5: the drop test's "
        "marker; a wider angle, e.g. a stop, measures the counts per revolution finer)",
    )
    walk.add_argument(
        "--sense-a-per-v",
        type=float,
        metavar="A_PER_V",
        help="the coil current sense's scale for --walk [A/V] (the A/D reads volts; without it the walk asks "
        "for it, or for a clamp meter's reading at the coil map's first step)",
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
    if not (math.isfinite(args.arm_deg) and 0.0 < abs(args.arm_deg) <= 90.0):
        raise ConfigError(f"--arm-deg: expected a marked angle in [-90, 90] deg other than 0, got {args.arm_deg:g}")
    sense = args.sense_a_per_v
    if sense is not None and not (math.isfinite(sense) and 1e-6 <= sense <= 1e6):
        raise ConfigError(f"--sense-a-per-v: expected a scale in [1e-06, 1e+06] A/V, got {sense:g}")
    if not args.walk and (sense is not None or args.arm_deg != -5.0):
        raise ConfigError("--arm-deg, --sense-a-per-v: only with --walk")


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
        from sashil.diagnostics.rtdac_walk import WalkOptions

        options = WalkOptions(args.arm_deg, args.sense_a_per_v)
        checks += rtdac_checks(run_spec, args.round_trips, args.walk, args.fragment, options=options)
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
