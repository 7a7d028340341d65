"""``sashil sweep``: road-side excitation through the resonance, chirp or stepped sine."""

from __future__ import annotations

import argparse

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_recording_options,
    add_verbosity_options,
    config_source,
    law_help,
    outputs_of,
    setup_logging,
)

EXAMPLE = "sashil sweep --f-start 0.5 --f-stop 5 --duration 30 --controller skyhook-onoff"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_driver_options(parser)
    parser.add_argument(
        "--f-start", type=float, metavar="HZ", help="start frequency [Hz] (default sweep.f_start_hz, 0.5)"
    )
    parser.add_argument(
        "--f-stop",
        type=float,
        metavar="HZ",
        help="stop frequency [Hz] (default sweep.f_stop_hz, 5; equal to --f-start: a sine at that frequency)",
    )
    parser.add_argument("--duration", type=float, metavar="S", help="chirp length [s] (default sweep.duration_s, 30)")
    parser.add_argument(
        "--amplitude-deg", type=float, metavar="DEG", help="road amplitude (override sweep.amplitude_deg)"
    )
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--controller", metavar="LAW", help=f"semi-active law ({law_help()}); default controller.law")
    group.add_argument(
        "--current", type=float, metavar="A", help="passive constant current instead of a law (controller.current_a)"
    )
    parser.add_argument(
        "--stepped",
        action=argparse.BooleanOptionalAction,
        help="stepped sine: transmissibility per frequency (sweep.steps); default sweep.stepped, false",
    )
    parser.add_argument(
        "--steps", type=int, metavar="N", help="stepped sine: number of frequencies (override sweep.steps)"
    )
    add_output_options(parser)
    add_recording_options(parser)  # live view / data.mat of the chirp's data.csv
    add_verbosity_options(parser)


def run(args: argparse.Namespace) -> int:
    from sashil.engine.events import printer
    from sashil.engine.resolve import Option, resolve
    from sashil.lab._sweep import sweep

    setup_logging(args)
    options = (
        Option("--f-start", "sweep.f_start_hz", args.f_start),
        Option("--f-stop", "sweep.f_stop_hz", args.f_stop),
        Option("--duration", "sweep.duration_s", args.duration),
        Option("--amplitude-deg", "sweep.amplitude_deg", args.amplitude_deg),
        Option("--stepped", "sweep.stepped", args.stepped),
        Option("--steps", "sweep.steps", args.steps),
        Option("--current", "controller.current_a", args.current),
    )
    if args.current is not None:  # a constant current is the passive law (argparse keeps --controller out)
        args.controller = "passive"
    config = resolve(config_source(args, options), "sweep")
    sweep(config, outputs_of(args), printer(quiet=args.quiet), progress=not args.quiet)
    return 0
