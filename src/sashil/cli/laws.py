"""``sashil laws``: every law sashil can run, with its parameters, output, whether it reads the road
ahead, and origin."""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sashil.control.law_registry import LawEntry

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


def describe(entry: LawEntry) -> dict[str, Any]:
    """One law as a plain mapping: name, output, origin, target and parameters."""
    cls = entry.cls
    paragraph = (cls.__doc__ or "").strip().split("\n\n")[0]
    doc = [" ".join(line.strip() for line in paragraph.splitlines())] if paragraph else []
    return {
        "name": cls.name,
        "output": cls.output_kind(),
        "reads_road_ahead": bool(getattr(cls, "reads_road_ahead", False)),
        "origin": entry.origin,
        "class": entry.spec,
        "doc": doc[0] if doc else "",
        "parameters": [
            {
                "name": key,
                "default": None if param.required else param.default,
                "required": param.required,
                "unit": param.unit,
                "low": param.low,
                "high": param.high,
                "low_open": param.low_open,
                "accepts": param.field.expected(),
                "doc": param.doc,
            }
            for key, param in cls.params().items()
        ],
    }


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
    from sashil.control.law_registry import find_law, known_laws

    entries = known_laws() + [find_law(spec) for spec in args.law]
    laws = [describe(entry) for entry in entries]
    print(json.dumps(laws, indent=2) if args.json else _text(laws))
    return 0
