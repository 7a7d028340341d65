"""Regenerate the README's figures in ``docs/figures/`` with the sashil CLI (simulated rig).

* ``drop_test.png``: ``sashil drop-test --current 0 --current 1`` (peaks, envelope, ζ), and beside it
  ``drop_test.json``: the command and each drop's ζ, δ and period as the legend and the quick start
  show them (``tests/test_readme_figure.py`` fails when a fresh drop test no longer gives them);
* ``transmissibility.png``: ``sashil sweep --stepped --current 0`` (24 log-spaced frequencies);
* ``timing.png``: ``sashil report`` of two 10 s ``sashil run``s at 1 kHz (passive 0 A and skyhook),
  the percentile plot of their loop timing (on the machine this runs on).

    .venv/bin/python tools/readme_figures.py
    .venv/bin/python tools/readme_figures.py --quick   # a 2 s drop, 2 frequencies, 0.5 s runs; PNGs to a temporary folder
    .venv/bin/python tools/readme_figures.py --figure drop_test   # one figure (repeatable)

``--quick`` leaves ``docs/figures/`` alone: it runs the same commands on a tiny problem, each by
``sashil.cli.main`` in this process (one interpreter's start-up and imports instead of five; the full
run starts each command as a user would): seconds.
"""

from __future__ import annotations

import argparse
import functools
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures"
FIGURES = ("drop_test", "transmissibility", "timing")
#: the quick start's drop test, which drop_test.png shows
DROP_COMMAND = ("drop-test", "--current", "0", "--current", "1")
SASHIL = [sys.executable, "-c", "import sys; from sashil.cli import main; sys.exit(main(sys.argv[1:]))"]


def sashil(*args: str, in_process: bool = False) -> None:
    """``sashil ARGS -q`` in a child process, or by ``sashil.cli.main`` in this one; stops on an error."""
    if not in_process:
        subprocess.run([*SASHIL, *args, "-q"], check=True)
        return
    from sashil.cli import main

    code = main([*args, "-q"])
    if code:
        raise SystemExit(f"sashil {' '.join(args)}: exit {code}")


def legend(summary: dict) -> dict:
    """What drop_test.png's legend and the quick start show of each drop of a drop test's
    ``summary.json``: the current, ζ and δ as the legend prints them, the period as the quick start does."""
    drops = []
    for run in summary["runs"]:
        drops.append(
            {
                "current_a": run["current_a"],
                "damping_ratio": f"{run['damping_ratio']:.3f}",
                "log_decrement": f"{run['log_decrement']:.3f}",
                "period_s": f"{run['period_s']:.3f}",
            }
        )
    return {"command": "sashil " + " ".join(DROP_COMMAND), "drops": drops}


def figures(out: Path, quick: bool, chosen: tuple[str, ...] = FIGURES) -> None:
    out.mkdir(parents=True, exist_ok=True)
    sashil = functools.partial(globals()["sashil"], in_process=quick)
    drop = ("--duration", "2") if quick else ()
    steps = ("--steps", "2") if quick else ()
    seconds = "0.5" if quick else "10"
    with tempfile.TemporaryDirectory(prefix="sashil-figures-") as name:
        tmp = Path(name)
        if "drop_test" in chosen:
            sashil(*DROP_COMMAND, *drop, "--out", str(tmp / "drop"))
            shutil.copy(tmp / "drop" / "drop_test.png", out / "drop_test.png")
            summary = json.loads((tmp / "drop" / "summary.json").read_text(encoding="utf-8"))
            (out / "drop_test.json").write_text(json.dumps(legend(summary), indent=2) + "\n", encoding="utf-8")
        if "transmissibility" in chosen:
            sashil("sweep", "--stepped", "--current", "0", *steps, "--out", str(tmp / "sweep"))
            shutil.copy(tmp / "sweep" / "transmissibility.png", out / "transmissibility.png")
        if "timing" in chosen:
            shown = ("--set", "loop.max_missed_fraction=1")  # the timing figure shows the misses, whatever they are
            sashil("run", "--duration", seconds, "--current", "0", *shown, "--out", str(tmp / "passive"))
            sashil("run", "--duration", seconds, "--set", "controller.law=skyhook", "--set", "controller.c_sky=2",
                   *shown, "--out", str(tmp / "skyhook"))  # fmt: skip
            sashil("report", str(tmp / "passive"), str(tmp / "skyhook"), "--out", str(tmp / "report"))
            shutil.copy(tmp / "report" / "timing.png", out / "timing.png")
    for path in sorted(out.glob("*.png")):
        print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}  {path.stat().st_size / 1e3:.0f} kB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", action="store_true", help="a 2 s drop, 2 frequencies, 0.5 s runs; PNGs to a temporary folder"
    )
    parser.add_argument(
        "--figure", action="append", choices=FIGURES, help="make only this figure (repeatable; default: all)"
    )
    args = parser.parse_args()
    chosen = tuple(args.figure or FIGURES)
    if args.quick:
        with tempfile.TemporaryDirectory(prefix="readme_figures-") as tmp:
            figures(Path(tmp), quick=True, chosen=chosen)
    else:
        figures(OUT, quick=False, chosen=chosen)


if __name__ == "__main__":
    main()
