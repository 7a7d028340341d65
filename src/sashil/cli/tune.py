"""``sashil tune``: change a running law's parameters, or list them, without stopping the run."""

from __future__ import annotations

import argparse
import json
from typing import Any

from sashil.cli.common import add_verbosity_options, setup_logging
from sashil.errors import ConfigError

EXAMPLE = "sashil tune runs/20261125T101500Z-run controller.c_sky=2.5 controller.tune_ramp_s=1"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_folder", metavar="RUN_FOLDER", help="the folder of a running `sashil run`")
    parser.add_argument(
        "changes",
        nargs="*",
        metavar="controller.PARAM=VALUE",
        help="new values (YAML, as --set); controller.tune_ramp_s=S moves float parameters linearly over S seconds "
        "(default: the run's controller.tune_ramp_s); none: list the law's parameters",
    )
    parser.add_argument("--json", action="store_true", help="print the answer as JSON")
    add_verbosity_options(parser)


def parse_changes(texts: list[str]) -> tuple[dict[str, Any], float | None]:
    """``["controller.c_sky=2", "controller.tune_ramp_s=1"]`` -> ``({"c_sky": 2}, 1.0)``; ConfigError
    (one line naming the argument) for anything but ``controller.<param>=VALUE``."""
    from sashil.config.overrides import parse_override
    from sashil.runtime.tuning import RAMP_KEY, check_ramp

    values: dict[str, Any] = {}
    ramp: float | None = None
    for text in texts:
        path, value = parse_override(text, "sashil tune")
        if path[0] != "controller" or len(path) != 2:
            raise ConfigError(
                f"sashil tune {text!r}: only a running law's parameters can change: controller.<param>=VALUE"
            )
        if path[1] == RAMP_KEY:
            ramp = check_ramp(value)
        else:
            values[path[1]] = value
    if texts and not values:
        raise ConfigError("sashil tune: controller.tune_ramp_s alone changes nothing: add controller.<param>=VALUE")
    return values, ramp


def run(args: argparse.Namespace) -> int:
    from sashil.runtime.tune_socket import request

    setup_logging(args)
    values, ramp = parse_changes(args.changes)
    message: dict[str, Any] = {"set": values, "ramp_s": ramp} if values else {"get": True}
    answer = request(args.run_folder, message)
    if args.json:
        print(json.dumps(answer, indent=2))
        return 0
    if "parameters" in answer:
        print(f"law {answer['law']} (live changes ramp over {answer.get('ramp_s', 0):g} s)")
        for key, value in answer["parameters"].items():
            print(f"  controller.{key} = {value}")
        return 0
    for event in answer["events"]:
        ramp_text = f" over {event['ramp_s']:g} s" if event["ramp_s"] else ""
        print(
            f"controller.{event['key']}: {event['old']} -> {event['new']}{ramp_text} "
            f"(cycle {event['cycle']}, t = {event['time_s']:.3f} s)"
        )
    return 0
