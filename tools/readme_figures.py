"""Make the figures of the simulated rig's verbs in ``docs/figures/``, each with ``NAME.json`` beside
it: the numbers its caption may state, from the same run (``tools/figures.py`` is the one entry
for every figure; ``tests/test_figures.py`` checks the captions against the data and the data against
the code).

* ``drop_test.png``: ``sashil drop-test --current 0 --current 1`` (peaks, envelope, ζ); its data,
  each drop's release angle, ζ, δ and period as the legend and the quick start show them
  (``tests/test_readme_figure.py`` fails when a fresh drop test no longer gives them);
* ``hysteresis.png``: the seed's damper (seed 001 eqs. 9-17) under a 1.6 Hz, 2° sine of θ at 0, 0.5
  and 1 A: torque against angle and against rate, from :class:`sashil.models.hysteresis.BoucWenZ`;
  its data, each loop's peak torque, viscous and yield parts, energy per cycle and fill of its box;
* ``compare.png``: ``sashil compare`` as the compare guide runs it (ISO 8608 class C, 10 s, four laws);
  its data, each run's RMS θ̈2 and θ, gain and share of the bound, and the bound;
* ``transmissibility.png``: ``sashil report`` of three ``sashil sweep --stepped`` (24 log-spaced
  frequencies): 0 A, 1 A and the compare's best law, skyhook-add (:data:`SWEEP_CURVES`); its data,
  every point and each curve's peak;
* ``calibration.png``: the held-out validation plot (``validation.png``) of ``sashil calibrate`` on the
  simulated rig with a small plan (drops at 0 and 1 A and road runs to fit, a 0.5 A drop held out),
  as the calibration tutorial shows it; its data, each run's NRMSE;
* ``identify.png``: ``sashil identify`` of the quick start's two drops (``params_fit.png``: the
  recorded and the fitted θ, the residual beneath), as the identification guide shows it; its data,
  the fit's RMS residual and each run's;
* ``timing.png``: ``sashil report`` of two 10 s ``sashil run``s at 1 kHz (passive 0 A and skyhook),
  the percentile plot of their loop timing (on the machine this runs on); its data, each run's
  lateness and compute percentiles and missed deadlines.

    .venv/bin/python tools/readme_figures.py
    .venv/bin/python tools/readme_figures.py --quick   # a 2 s drop, 2 short frequencies, 0.5 s runs; PNGs to a temporary folder
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
from collections.abc import Callable
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
#: the coil currents hysteresis.png draws
HYSTERESIS_CURRENTS = (0.0, 0.5, 1.0)
#: transmissibility.png's curves: the passive damper at both ends of its current and the law that won
#: the compare guide's comparison (compare.png), each a stepped sine of SWEEP_STEPS frequencies
SWEEP_CURVES = {
    "passive-0A": ("--current", "0"),
    "passive-1A": ("--current", "1"),
    "skyhook-add": ("--controller", "skyhook-add"),
}
SWEEP_STEPS = 24
#: one sashil command (``sashil(*args)``), in a child process or in this one
Run = Callable[..., None]
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
    ``summary.json``: the release angle and the current, ζ and δ as the legend prints them, the period
    as the quick start does."""
    drops = []
    for run in summary["runs"]:
        drops.append(
            {
                "current_a": run["current_a"],
                "release_deg": f"{run['theta0_deg']:g}",
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
    for current in HYSTERESIS_CURRENTS:
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


def fmt(value: float, digits: int = 3) -> str:
    """A number as a caption prints it: ``digits`` significant figures, no trailing zeros."""
    return f"{value:.{digits}g}"


def hysteresis_numbers(cycles: float = 3.0) -> dict:
    """What hysteresis.png's caption states of its loops, measured on the same trajectories: per
    current, the peak torque, the viscous part c(i)·θ̇ at the peak rate, the yield torque α(i)·z_u,
    the energy per cycle ∮T dθ and the share of its bounding box the T-θ loop fills (an ellipse
    fills π/4, 79 %; a rectangle 100 %)."""
    import math

    import numpy as np

    from sashil.models.hysteresis import BoucWenParams, BoucWenZ

    params = BoucWenParams()
    f_hz, amplitude = 1.6, math.radians(2.0)
    t = np.arange(0.0, cycles / f_hz, 1e-4)
    theta = amplitude * np.sin(2 * math.pi * f_hz * t)
    rate = 2 * math.pi * f_hz * amplitude * np.cos(2 * math.pi * f_hz * t)
    z = BoucWenZ.from_params(params).trajectory(theta)
    last = t >= (cycles - 1.0) / f_hz
    loops = {}
    for current in HYSTERESIS_CURRENTS:
        torque = params.torque(z, rate, current)[last]
        angle = theta[last]
        energy = abs(float(np.sum(0.5 * (torque[1:] + torque[:-1]) * np.diff(angle))))
        box = float(np.ptp(angle) * np.ptp(torque))
        loops[f"{current:g} A"] = {
            "peak_torque_nm": fmt(float(np.max(np.abs(torque))), 2),
            "viscous_peak_nm": fmt(params.damping(current) * float(np.max(rate)), 2),
            "yield_torque_nm": fmt(params.hysteretic_gain(current) * params.z_bound, 2),
            "energy_per_cycle_j": fmt(energy, 2),
            "box_fill_pct": f"{100 * energy / box:.0f}",
        }
    return {
        "source": "Iskandarani & Karimi 2011 (seed 001), eqs. 9-17",
        "road": "theta = 2 deg sin(2 pi 1.6 Hz t), the last of 3 cycles",
        "ellipse_fill_pct": f"{100 * math.pi / 4:.0f}",
        "rectangle_fill_pct": "100",
        "loops": loops,
    }


def compare_numbers(folder: Path) -> dict:
    """What compare.png's caption states, from the compare folder: each run's RMS θ̈2, RMS θ, gain
    over the best passive run and share of the bound, as the figure prints them; the bound's RMS θ̈2."""
    import csv

    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    with (folder / "metrics.csv").open(encoding="utf-8", newline="") as handle:
        rows = list(csv.DictReader(handle))
    laws = {
        row["law"]: {
            "rms_accel_rad_s2": fmt(float(row["rms_accel_rad_s2"])),
            "rms_theta_deg": fmt(float(row["rms_theta_deg"]), 2),
            "vs_best_passive_pct": f"{float(row['vs_best_passive_pct']):+.1f}",
            "share_of_bound_pct": f"{float(row['share_of_bound_pct']):.0f}",
        }
        for row in rows
    }
    best = min(rows, key=lambda row: float(row["rms_accel_rad_s2"]))["law"]
    return {
        "command": "sashil " + " ".join(COMPARE_COMMAND),
        "bound_rms_accel_rad_s2": fmt(summary["optimal_bound_rms_accel_rad_s2"]),
        "best": best,
        "laws": laws,
    }


def sweep_curve(folder: Path) -> dict:
    """One stepped sine's transmissibility (a run folder's ``transmissibility.csv``): every point at
    full precision, for a recomputation of any of them, and its peak as the caption prints it."""
    import sashil

    table = sashil.load_run(folder).tables["transmissibility"]
    freqs = [float(f) for f in table["frequency_hz"]]
    values = [float(v) for v in table["transmissibility"]]
    peak = max(range(len(values)), key=values.__getitem__)
    return {
        "frequency_hz": freqs,
        "transmissibility": values,
        "peak_frequency_hz": f"{freqs[peak]:.2f}",
        "peak_transmissibility": fmt(values[peak]),
        "at_highest_frequency": fmt(values[-1], 2),
    }


def make_drop_test(out: Path, tmp: Path, quick: bool, run: Run) -> dict:
    drop = ("--duration", "2") if quick else ()
    run(*DROP_COMMAND, *drop, "--out", str(tmp / "drop"))
    shutil.copy(tmp / "drop" / "drop_test.png", out / "drop_test.png")
    return legend(json.loads((tmp / "drop" / "summary.json").read_text(encoding="utf-8")))


def make_hysteresis(out: Path, tmp: Path, quick: bool, run: Run) -> dict:
    cycles = 2.0 if quick else 3.0
    hysteresis_figure(out / "hysteresis.png", cycles=cycles)
    return {"command": "tools/figures.py --figure hysteresis", **hysteresis_numbers(cycles)}


def make_compare(out: Path, tmp: Path, quick: bool, run: Run) -> dict:
    duration = ("--duration", "3", "--set", "compare.settle_s=1") if quick else ()
    run(*COMPARE_COMMAND, *duration, "--out", str(tmp / "compare"))
    shutil.copy(tmp / "compare" / "compare.png", out / "compare.png")
    return compare_numbers(tmp / "compare")


def make_transmissibility(out: Path, tmp: Path, quick: bool, run: Run) -> dict:
    steps = ("--steps", "2") if quick else ("--steps", str(SWEEP_STEPS))
    short = ("--set", "sweep.settle_s=1", "--set", "sweep.measure_s=1") if quick else ()
    folders = []
    for name, setting in SWEEP_CURVES.items():
        run("sweep", "--stepped", *setting, *steps, *short, "--out", str(tmp / name))
        folders.append(str(tmp / name))
    run("report", *folders, "--out", str(tmp / "sweep-report"))
    shutil.copy(tmp / "sweep-report" / "transmissibility.png", out / "transmissibility.png")
    return {
        "command": [
            f"sashil sweep --stepped {' '.join(setting)} --steps {steps[1]}" for setting in SWEEP_CURVES.values()
        ],
        "road": json.loads((Path(folders[0]) / "summary.json").read_text(encoding="utf-8"))["road"],
        "curves": {name: sweep_curve(Path(folder)) for name, folder in zip(SWEEP_CURVES, folders, strict=True)},
    }


def make_calibration(out: Path, tmp: Path, quick: bool, run: Run) -> dict:
    road = ("--set", "calibrate.road_currents_a=[]", "--set", "calibrate.drop_duration_s=1.5") if quick else ()
    run("calibrate", *CALIBRATION_PLAN, *road, "--out", str(tmp / "calibration"))
    shutil.copy(tmp / "calibration" / "validation.png", out / "calibration.png")
    summary = json.loads((tmp / "calibration" / "summary.json").read_text(encoding="utf-8"))
    held_out = {name: f"{100 * value:.2f}" for name, value in summary["held_out_nrmse"].items()}
    return {
        "command": "sashil calibrate " + " ".join(CALIBRATION_PLAN),
        "plan": "drops at 0 and 1 A and road runs to fit, a 0.5 A drop held out",
        "held_out_nrmse_pct": held_out,
        "fit_nrmse_pct": _percent_values(summary["fit_nrmse"]),
        "encoder_count_deg": f"{360 / 4096:.3f}",
    }


def _percent_values(value: object) -> object:
    """NRMSE fractions as percent strings with two decimals, through dicts and lists."""
    if isinstance(value, dict):
        return {key: _percent_values(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_percent_values(item) for item in value]
    return f"{100 * float(value):.2f}" if isinstance(value, (int, float)) else value


def make_identify(out: Path, tmp: Path, quick: bool, run: Run) -> dict:
    import math

    import yaml

    if not (tmp / "drop").is_dir():
        run(*DROP_COMMAND, *(("--duration", "2") if quick else ()), "--out", str(tmp / "drop"))
    drops = sorted(str(path) for path in (tmp / "drop").glob("i*A"))
    run("identify", *drops, "--out", str(tmp / "identify" / "params.yaml"))
    shutil.copy(tmp / "identify" / "params_fit.png", out / "identify.png")
    fit = yaml.safe_load((tmp / "identify" / "params.yaml").read_text(encoding="utf-8"))["fit"]
    return {
        "command": "sashil identify (the drops of sashil " + " ".join(DROP_COMMAND) + ")",
        "fit_rms_deg": f"{math.degrees(fit['rms_rad_total']):.4f}",
        "runs": {
            Path(entry["file"]).parent.name: {
                "rms_deg": f"{math.degrees(entry['rms_rad']):.3f}",
                "nrmse_pct": f"{100 * entry['nrmse']:.1f}",
            }
            for entry in fit["runs"]
        },
        "encoder_count_deg": f"{360 / 4096:.3f}",
    }


def make_timing(out: Path, tmp: Path, quick: bool, run: Run) -> dict:
    seconds = "0.5" if quick else "10"
    shown = ("--set", "loop.max_missed_fraction=1")  # the timing figure shows the misses, whatever they are
    runs = {
        "passive 0 A": ("--current", "0"),
        "skyhook (c_sky=2)": ("--set", "controller.law=skyhook", "--set", "controller.c_sky=2"),
    }
    folders = []
    for name, setting in zip(("passive", "skyhook"), runs.values(), strict=True):
        run("run", "--duration", seconds, *setting, *shown, "--out", str(tmp / name))
        folders.append(tmp / name)
    run("report", *map(str, folders), "--out", str(tmp / "report"))
    shutil.copy(tmp / "report" / "timing.png", out / "timing.png")
    numbers = {label: timing_numbers(folder) for label, folder in zip(runs, folders, strict=True)}
    commands = [f"sashil run --duration {seconds} {' '.join(setting)}" for setting in runs.values()]
    return {"command": [*commands, "sashil report (the two)"], "rate_hz": "1000", "runs": numbers}


def timing_numbers(folder: Path) -> dict:
    """What timing.png marks of one run, from the cycles it draws (``timing.npz``): the lateness and
    compute time at p50, p99 and p99.9 and their maxima; the run's cycles and missed deadlines
    (summary.json). The summary's own lateness percentiles also count the deadlines a late cycle
    skipped, which the plot does not draw."""
    import numpy as np

    import sashil

    run = sashil.load_run(folder)
    timing = run.timing or {}
    numbers = {
        "cycles": str(run.summary["timing"]["cycles"]),
        "missed_deadlines": str(run.summary["timing"]["missed_deadlines"]),
    }
    for name in ("lateness", "compute"):
        values = np.asarray(timing[f"{name}_ns"], dtype=float) * 1e-3
        for key, q in (("p50", 50.0), ("p99", 99.0), ("p99_9", 99.9)):
            numbers[f"{name}_{key}_us"] = microseconds(float(np.percentile(values, q)))
        numbers[f"{name}_max_us"] = microseconds(float(values.max()))
    return numbers


def microseconds(value: float) -> str:
    """A time in µs as a caption prints it: whole µs from 10 µs up, two significant figures below."""
    return f"{value:.0f}" if value >= 10 else f"{value:.2g}"


#: each figure's maker: ``make(out, tmp, quick, run)`` (``run(*args)``: one sashil command) writes NAME.png into ``out`` and returns the numbers its
#: caption may state (kept beside it as NAME.json by :func:`figures`)
MAKERS = {
    "drop_test": make_drop_test,
    "hysteresis": make_hysteresis,
    "compare": make_compare,
    "transmissibility": make_transmissibility,
    "calibration": make_calibration,
    "identify": make_identify,
    "timing": make_timing,
}


def figures(
    out: Path, quick: bool, chosen: tuple[str, ...] = FIGURES, in_process: bool | None = None
) -> dict[str, dict]:
    """Make the chosen figures into ``out``, each with its numbers beside it (NAME.json); the numbers.
    ``in_process``: each command by ``sashil.cli.main`` in this process (default: in quick mode)."""
    out.mkdir(parents=True, exist_ok=True)
    run = functools.partial(sashil, in_process=quick if in_process is None else in_process)
    made = {}
    with tempfile.TemporaryDirectory(prefix="sashil-figures-") as name:
        for figure in chosen:
            made[figure] = MAKERS[figure](out, Path(name), quick, run)
            (out / f"{figure}.json").write_text(json.dumps(made[figure], indent=2) + "\n", encoding="utf-8")
    for path in sorted(out.glob("*.png")):
        print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}  {path.stat().st_size / 1e3:.0f} kB")
    return made


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
