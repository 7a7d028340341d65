"""``sashil laws``: every law sashil can run, with its parameters, output, whether it reads the road
ahead, and origin."""

from __future__ import annotations

import argparse
import json
from typing import Any

EXAMPLE = "sashil laws --law examples/soft_skyhook/soft_skyhook.py:SoftSkyhook"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--law",
        action="append",
        default=[],
        metavar="SPEC",
        help="also describe this law (package.module:Class or path/file.py:Class); repeatable",
    )
    parser.add_argument("--json", action="store_true", help="the same table as JSON, for scripts")


def _text(laws: list[dict[str, Any]]) -> str:
    lines = []
    for law in laws:
        ahead = "; reads the road ahead (a road plan only)" if law["reads_road_ahead"] else ""
        lines.append(f"{law['name']}  ({law['output']}{ahead}; {law['origin']}: {law['class']})")
        if law["doc"]:
            lines.append(f"    {law['doc']}")
        for p in law["parameters"]:
            default = "required" if p["required"] else json.dumps(p["default"])
            unit = f" [{p['unit']}]" if p["unit"] else ""
            what = f"  {p['doc']}" if p["doc"] else ""
            lines.append(f"    controller.{p['name']}{unit} = {default}  ({p['accepts']}){what}")
        if not law["parameters"]:
            lines.append("    (no parameters)")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from sashil.control.law_registry import describe, find_law, known_laws

    entries = known_laws() + [find_law(spec) for spec in args.law]
    laws = [describe(entry) for entry in entries]
    print(json.dumps(laws, indent=2) if args.json else _text(laws))
    return 0
