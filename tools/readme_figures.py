"""Regenerate the README's figures in ``docs/figures/`` with the sashil CLI (simulated rig).

* ``drop_test.png``: ``sashil drop-test --current 0 --current 1`` (peaks, envelope, ζ), and beside it
  ``drop_test.json``: the command and each drop's ζ, δ and period as the legend and the quick start
  show them (``tests/test_readme_figure.py`` fails when a fresh drop test no longer gives them);
* ``hysteresis.png``: the seed's damper (seed 001 eqs. 9-17) under a 1.6 Hz, 2° sine of θ at 0, 0.5
  and 1 A: torque against angle and against rate, from :class:`sashil.models.hysteresis.BoucWenZ`;
* ``compare.png``: ``sashil compare`` as the compare guide runs it (ISO 8608 class C, 10 s, four laws);
* ``transmissibility.png``: ``sashil sweep --stepped --current 0`` (24 log-spaced frequencies);
* ``calibration.png``: the held-out validation plot (``validation.png``) of ``sashil calibrate`` on the
  simulated rig with a small plan (drops at 0 and 1 A and a road run to fit, a 0.5 A drop held out),
  as the calibration tutorial shows it;
* ``identify.png``: ``sashil identify`` of the quick start's two drops (``params_fit.png``: the
  recorded and the fitted θ, the residual beneath), as the identification guide shows it;
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
FIGURES = ("drop_test", "hysteresis", "compare", "transmissibility", "calibration", "identify", "timing")
#: the calibration tutorial's small plan: calibration.png shows its held-out drop
CALIBRATION_PLAN = (
    "--set", "calibrate.currents_a=[0,1]", "--set", "calibrate.small_currents_a=[]",
    "--set", "calibrate.validate_currents_a=[0.5]",
)  # fmt: skip
#: the compare guide's comparison (docs/how-to/compare-laws.md), which compare.png shows
COMPARE_COMMAND = (
    "compare", "--road", "iso8608:C", "--duration", "10", "--controller", "skyhook-add", "--controller",
    "clipped-optimal", "--controller", "pdd", "--controller", "skyhook", "--set", "controller.c_sky=2",
)  # fmt: skip
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


def hysteresis_figure(path: Path, cycles: float = 3.0) -> Path:
    """The damper torque T = α(i)·z + c(i)·θ̇ (seed 001 eqs. 9, 11-12) of the seed's parameters under
    θ = 2°·sin(2π·1.6 Hz·t), z integrated over the angle (eq. 17), at 0, 0.5 and 1 A: against θ and θ̇,
    the last cycle (the first leaves z's start behind)."""
    import math

    import numpy as np

    from sashil.models.hysteresis import BoucWenParams, BoucWenZ
    from sashil.recording.plots import pyplot, save_figure

    params = BoucWenParams()
    f_hz, amplitude = 1.6, math.radians(2.0)
    t = np.arange(0.0, cycles / f_hz, 1e-4)
    theta = amplitude * np.sin(2 * math.pi * f_hz * t)
    rate = 2 * math.pi * f_hz * amplitude * np.cos(2 * math.pi * f_hz * t)
    z = BoucWenZ.from_params(params).trajectory(theta)
    last = t >= (cycles - 1.0) / f_hz
    fig, (by_angle, by_rate) = pyplot().subplots(1, 2, figsize=(9, 3.8), dpi=110)
    for current in (0.0, 0.5, 1.0):
        torque = params.torque(z, rate, current)
        label = f"{current:g} A"
        by_angle.plot(np.degrees(theta[last]), torque[last], lw=1.2, label=label)
        by_rate.plot(rate[last], torque[last], lw=1.2, label=label)
    by_angle.set(xlabel="relative angle θ [deg]", ylabel="damper torque T [N m]", title="T against θ")
    by_rate.set(xlabel="rate θ̇ [rad/s]", title="T against θ̇: the Bouc-Wen loop")
    for ax in (by_angle, by_rate):
        ax.grid(alpha=0.3)
        ax.legend(title="coil current", fontsize=8)
    fig.suptitle("The seed's MR damper under a 1.6 Hz, ±2° sine (Iskandarani & Karimi 2011, eqs. 9-17)", fontsize=10)
    return save_figure(fig, path)


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
        if "hysteresis" in chosen:
            hysteresis_figure(out / "hysteresis.png", cycles=2.0 if quick else 3.0)
        if "compare" in chosen:
            duration = ("--duration", "3", "--set", "compare.settle_s=1") if quick else ()
            sashil(*COMPARE_COMMAND, *duration, "--out", str(tmp / "compare"))
            shutil.copy(tmp / "compare" / "compare.png", out / "compare.png")
        if "transmissibility" in chosen:
            sashil("sweep", "--stepped", "--current", "0", *steps, "--out", str(tmp / "sweep"))
            shutil.copy(tmp / "sweep" / "transmissibility.png", out / "transmissibility.png")
        if "calibration" in chosen:
            road = ("--set", "calibrate.road_currents_a=[]", "--set", "calibrate.drop_duration_s=1.5") if quick else ()
            sashil("calibrate", *CALIBRATION_PLAN, *road, "--out", str(tmp / "calibration"))
            shutil.copy(tmp / "calibration" / "validation.png", out / "calibration.png")
        if "identify" in chosen:
            if not (tmp / "drop").is_dir():
                sashil(*DROP_COMMAND, *drop, "--out", str(tmp / "drop"))
            drops = sorted(str(path) for path in (tmp / "drop").glob("i*A"))
            sashil("identify", *drops, "--out", str(tmp / "identify" / "params.yaml"))
            shutil.copy(tmp / "identify" / "params_fit.png", out / "identify.png")
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
