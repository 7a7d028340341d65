"""Regenerate the README's figures in ``docs/figures/`` with the sashil CLI (simulated rig).

* ``drop_test.png``: ``sashil drop-test --current 0 --current 1`` (peaks, envelope, ζ);
* ``transmissibility.png``: ``sashil sweep --stepped --current 0`` (24 log-spaced frequencies);
* ``timing.png``: ``sashil report`` of two 10 s ``sashil run``s at 1 kHz (passive 0 A and skyhook),
  the percentile plot of their loop timing (on the machine this runs on).

    .venv/bin/python tools/readme_figures.py
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures"
SASHIL = [sys.executable, "-c", "import sys; from sashil.cli import main; sys.exit(main(sys.argv[1:]))"]


def sashil(*args: str) -> None:
    subprocess.run([*SASHIL, *args, "-q"], check=True)


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="sashil-figures-") as name:
        tmp = Path(name)
        sashil("drop-test", "--current", "0", "--current", "1", "--out", str(tmp / "drop"))
        shutil.copy(tmp / "drop" / "drop_test.png", OUT / "drop_test.png")
        sashil("sweep", "--stepped", "--current", "0", "--out", str(tmp / "sweep"))
        shutil.copy(tmp / "sweep" / "transmissibility.png", OUT / "transmissibility.png")
        sashil("run", "--duration", "10", "--current", "0", "--out", str(tmp / "passive"))
        sashil("run", "--duration", "10", "--set", "controller.law=skyhook", "--set", "controller.c_sky=2",
               "--out", str(tmp / "skyhook"))  # fmt: skip
        sashil("report", str(tmp / "passive"), str(tmp / "skyhook"), "--out", str(tmp / "report"))
        shutil.copy(tmp / "report" / "timing.png", OUT / "timing.png")
    for path in sorted(OUT.glob("*.png")):
        print(f"{path.relative_to(ROOT)}  {path.stat().st_size / 1e3:.0f} kB")


if __name__ == "__main__":
    main()
