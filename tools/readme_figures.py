"""Regenerate the README's figures in ``docs/figures/`` with the sashil CLI (simulated rig).

* ``drop_test.png``: ``sashil drop-test --current 0 --current 1`` (peaks, envelope, ζ);
* ``transmissibility.png``: ``sashil sweep --stepped --current 0`` (24 log-spaced frequencies);
* ``timing.png``: ``sashil report`` of two 10 s ``sashil run``s at 1 kHz (passive 0 A and skyhook),
  the percentile plot of their loop timing (on the machine this runs on).

    .venv/bin/python tools/readme_figures.py
    .venv/bin/python tools/readme_figures.py --quick   # a 2 s drop, 2 frequencies, 0.5 s runs; PNGs to a temporary folder

``--quick`` leaves ``docs/figures/`` alone: it runs the same commands on a tiny problem, each by
``sashil.cli.main`` in this process (one interpreter's start-up and imports instead of five; the full
run starts each command as a user would): seconds.
"""

from __future__ import annotations

import argparse
import functools
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures"
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


def figures(out: Path, quick: bool) -> None:
    out.mkdir(parents=True, exist_ok=True)
    sashil = functools.partial(globals()["sashil"], in_process=quick)
    drop = ("--duration", "2") if quick else ()
    steps = ("--steps", "2") if quick else ()
    seconds = "0.5" if quick else "10"
    with tempfile.TemporaryDirectory(prefix="sashil-figures-") as name:
        tmp = Path(name)
        sashil("drop-test", "--current", "0", "--current", "1", *drop, "--out", str(tmp / "drop"))
        shutil.copy(tmp / "drop" / "drop_test.png", out / "drop_test.png")
        sashil("sweep", "--stepped", "--current", "0", *steps, "--out", str(tmp / "sweep"))
        shutil.copy(tmp / "sweep" / "transmissibility.png", out / "transmissibility.png")
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
    args = parser.parse_args()
    if args.quick:
        with tempfile.TemporaryDirectory(prefix="readme_figures-") as tmp:
            figures(Path(tmp), quick=True)
    else:
        figures(OUT, quick=False)


if __name__ == "__main__":
    main()
