#!/usr/bin/env python3
"""The record a benchmark keeps of its figures: one JSON file with what was measured and how to trace
it, the commit measured (``git rev-parse HEAD``, with ``+dirty`` when tracked files differ from it),
the date (UTC), the machine's load (``os.getloadavg``: 1, 5 and 15 minutes) at the start and the end,
its cores and the command line. The docs cite the kept file behind each table (``tools/out/*.json``).

A tool whose figures are a structure writes them (``sys.path`` holds ``tools/`` when a script runs
from it)::

    from bench_record import Recorder
    record = Recorder("bench_compare")          # the start: commit, date, load now
    ...
    record.write(path, figures)                 # the end: the load again, the figures

and every other keeps what it prints, line by line, under the same provenance::

    keep_output("bench_sim", main)

A ``--quick`` run (CI's: its figures mean nothing) keeps nothing unless told where (``--json``).

Run alone it prints the record a benchmark started now would carry:

    .venv/bin/python tools/bench_record.py [--quick]
"""

from __future__ import annotations

import argparse
import io
import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: where the kept records live, one file per benchmark (and mode)
OUT = ROOT / "tools" / "out"

__all__ = ["OUT", "Recorder", "commit", "keep_output", "out_path", "provenance"]


def commit(root: Path = ROOT) -> str:
    """The commit checked out at ``root``, ``+dirty`` when a tracked file differs from it; ``unknown``
    outside a git checkout."""
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=False)
    if head.returncode != 0:
        return "unknown"
    status = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=no"], cwd=root, capture_output=True, text=True, check=False
    )
    return head.stdout.strip() + ("+dirty" if status.stdout.strip() else "")


def provenance() -> dict[str, Any]:
    """The commit measured, the date (UTC, ISO 8601), the machine's load (1, 5 and 15 minutes) and
    cores now."""
    return {
        "commit": commit(),
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "loadavg": list(os.getloadavg()),
        "cpus": os.cpu_count(),
    }


def out_path(name: str, quick: bool = False) -> Path:
    """The kept record of benchmark ``name``: ``tools/out/NAME.json`` (``NAME_quick.json`` for a
    quick run, whose figures mean nothing)."""
    return OUT / f"{name}{'_quick' if quick else ''}.json"


def _plain(value: Any) -> Any:
    """``value`` as JSON can hold it: NaN and infinities as null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


@dataclass
class Recorder:
    """A benchmark's record: its ``name``, the provenance at its start, the command line."""

    name: str
    start: dict[str, Any] = field(default_factory=provenance)
    command: list[str] = field(default_factory=lambda: [Path(sys.argv[0]).name, *sys.argv[1:]])

    def record(self, figures: Any) -> dict[str, Any]:
        """The record of ``figures``: the benchmark, the command, the provenance at the start and
        the load at the end."""
        return {
            "benchmark": self.name,
            "command": self.command,
            **self.start,
            "loadavg_end": list(os.getloadavg()),
            "figures": _plain(figures),
        }

    def write(self, path: Path, figures: Any) -> Path:
        """Write the record of ``figures`` to ``path`` (its folder made) and return it."""
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.record(figures), indent=1, allow_nan=False) + "\n", encoding="utf-8")
        return path


class _Tee(io.TextIOBase):
    """A text stream that writes to ``stream`` and keeps a copy."""

    def __init__(self, stream: Any):
        self.stream, self.kept = stream, io.StringIO()

    def write(self, text: str) -> int:
        self.kept.write(text)
        return int(self.stream.write(text) or len(text))

    def flush(self) -> None:
        self.stream.flush()

    def isatty(self) -> bool:
        return bool(self.stream.isatty())


def keep_output(name: str, main: Callable[[], Any], path: Path | None = None, children: tuple[str, ...] = ()) -> Any:
    """Run a benchmark's ``main`` and keep what it prints: when it returns, the lines go to ``path``
    (default :func:`out_path`) as ``figures.output`` with the provenance at its start, the load at
    its end and what ``main`` returned (``exit``). A run that raises (bad arguments, a failure), a
    ``--quick`` run, a run with one of the flags ``children`` (the tool started as its own child
    process: its parent keeps the figures) and a run with ``SASHIL_KEEP_OUTPUT=0`` in its environment
    (a test's) keep nothing. Returns what ``main`` returned."""
    quiet = os.environ.get("SASHIL_KEEP_OUTPUT") == "0"
    if quiet or any(flag in sys.argv[1:] for flag in ("--quick", *children)):
        return main()
    record = Recorder(name)
    tee = _Tee(sys.stdout)
    sys.stdout = tee
    try:
        result = main()
    finally:
        sys.stdout = tee.stream
    kept = record.write(path or out_path(name), {"output": tee.kept.getvalue().splitlines(), "exit": result})
    print(f"record: {kept}")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="the same: it measures nothing")
    parser.parse_args()
    print(json.dumps(Recorder("bench_record").record({}), indent=1))


if __name__ == "__main__":
    main()
