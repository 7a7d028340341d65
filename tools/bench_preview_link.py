#!/usr/bin/env python3
"""Benchmark: the preview law's share of the bound on a model calibrated over serial, and over serial
against the emulated board, beside the simulated rig with the exact model; a spread of dampers.

For each damper (``tools/bench_drop_damping.py``'s, by name; bench_preview's ORDER), on one road
(ISO 8608 C at 10 m/s), each run as ``sashil compare`` runs it (:func:`sashil.lab._compare.run_job`):

- ``sim``: the simulated rig (virtual clock), the law's model the plant's own: the passive runs at
  the currents ``compare.passive_currents_a`` lists (compare's baseline on a rig, the best of them)
  and ``preview-optimal``; θ̈2 the plant's own;
- ``calibrated``: the same, ``preview-optimal`` built on the model ``sashil calibrate`` fitted over
  serial against ``sashil emulate`` of this damper (``--calibrated DIR``: DIR/<damper>/params.yaml,
  from :func:`sashil.lab.calibration.emulated.calibrate_emulated`, ``--inertia`` the true J; ``--calibrate``
  makes them first), run against the true plant, on the true plant's passive runs and bound;
- ``serial``: the same runs over pyserial against ``sashil emulate`` of this damper (a fresh
  emulator per run, its ``--truth`` log joined to the host's rows on the wire's sequence number).
  θ̈2 both as compare measures it over a link (the encoders) and the emulator's true
  (−k·θ − T)/J, low-passed alike.

Shares, all on :func:`sashil.lab.compare_report.share_of_bound`'s scale, with the bound of
compare (:mod:`sashil.lab.hysteretic_bound`) on the damper's true model:

- ``encoders, model bound``: the encoders' θ̈2 against the model's bound (two chains on one scale);
- ``encoders, one chain``: the bound put on the encoders' chain
  (:func:`sashil.lab.hysteretic_bound.bound_on_chain`: compare's share over a link);
- ``truth``: the emulator's true θ̈2 against the bound (one chain: the plant's, as on the simulated rig).

Each round's runs are printed below the table: the RMS θ̈2 of the encoders and of the truth, and
the encoders' off the truth [%] (compare's chain alone: the same run, both low-passed alike).

With ``--repeat N`` each damper's serial runs go N rounds: the median share is the damper's and each
round's is printed beside it (a run's realised road varies with the host's and the emulator's pauses,
so one round's share varies). ``--keep DIR`` keeps each serial run's folder (its data.csv and the
emulator's truth log) in DIR/<damper>/round-<i>, to study the encoders' θ̈2 offline. A serial run's
link can fail under load (a write times out while the emulator stalls); ``--retries N`` runs such a
run again, up to N times, and its status says so. The host's load average is printed beside each run (the serial runs
are real time).

    .venv/bin/python tools/bench_preview_link.py [--quick] [--dampers seed,n 1,J 2] [--duration S]
        [--calibrated DIR] [--calibrate] [--no-serial] [--repeat N] [--json PATH] [--keep DIR] [--retries N]

``--quick``: the seed damper alone, 2.5 s runs (0.5 s after the 2 s left out), one round over serial:
seconds; the figures mean little.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_control_link import join_on_seq
from bench_drop_damping import DAMPERS
from bench_link import EmulatorProcess
from bench_preview import config_of, hysteretic_bound

from sashil.config import dump_config, load_params
from sashil.drivers.emulator import read_truth_csv
from sashil.engine.resolve import apply_overrides
from sashil.identify.rig_models import bouc_wen_rescale
from sashil.lab._compare import LawJob, run_job
from sashil.lab.compare_metrics import arm_acceleration
from sashil.lab.compare_report import share_of_bound
from sashil.lab.hysteretic_bound import bound_on_chain, model_passive
from sashil.lab.passive_baseline import passive_label
from sashil.models.hysteresis import BoucWenParams
from sashil.roads.option import RoadParts, parse_road

ROAD = "iso8608:C:10"
DAMPERS_DEFAULT = ("seed", "n 1", "J 2")
LAW = "preview-optimal"


def progress(text: str) -> None:
    print(f"  .. {time.strftime('%H:%M:%S')} load {os.getloadavg()[0]:.2f}  {text}", flush=True)


def reference_currents(config: dict[str, Any]) -> list[float]:
    """The passive references: the constant currents ``compare.passive_currents_a`` lists, compare's
    baseline on a rig where each candidate is a run of rig time (the best of them)."""
    return [float(current) for current in config["compare"]["passive_currents_a"]]


def labels(config: dict[str, Any]) -> list[tuple[str, list[str]]]:
    """The runs: the passive references and the preview law, each with its overrides."""
    passive = [
        (passive_label(current), ["controller.law=passive", f"controller.current_a={current}"])
        for current in reference_currents(config)
    ]
    return [*passive, (LAW, [f"controller.law={LAW}"])]


def sim_runs(config: dict[str, Any], road: str, duration: float) -> tuple[dict[str, float], dict[str, float]]:
    """RMS θ̈2 of each run on the simulated rig: the plant's own, and its encoders' (θ2 of the
    recorded encoder angles differentiated twice, as compare measures over a link)."""
    plant, encoders = {}, {}
    with tempfile.TemporaryDirectory(prefix="sashil-preview-sim-") as tmp:
        for label, sets in labels(config):
            folder = Path(tmp) / label.replace(" ", "-")
            folder.mkdir()
            result = run_job(LawJob(label, apply_overrides(config, sets), road, duration, str(folder)))
            plant[label] = result.metrics["rms_accel_rad_s2"] if result.ok else math.nan
            encoders[label] = encoder_rms(folder, config) if result.ok else math.nan
    return plant, encoders


def encoder_rms(folder: Path, config: dict[str, Any]) -> float:
    """RMS after the settling of θ̈2 from a run's encoder angles alone (the plant's own column left out)."""
    from sashil.recording.data_file import read_data_csv

    cols = read_data_csv(folder / "data.csv", required=("time_s",))
    stream = {k: v[:-1] for k, v in cols.items() if k != "arm_accel_true_rad_s2"}
    section = config["compare"]
    accel, _ = arm_acceleration(stream, float(config["loop"]["rate_hz"]), float(section["accel_bandwidth_hz"]))
    keep = stream["time_s"] >= float(section["settle_s"])
    return float(np.sqrt(np.mean(accel[keep] ** 2)))


def calibrated_run(config: dict[str, Any], params_path: Path, road: str, duration: float) -> float:
    """RMS θ̈2 of the preview law built on the calibrated model, on the simulated rig of the true plant.

    The simulated plant is the law's model after ``mismatch.params`` (each parameter's fraction): the
    true damper is expressed with z scaled to a unit bound, as the calibration gives its model
    (:func:`sashil.identify.rig_models.bouc_wen_rescale`: the same rig), and each fraction is that
    over the fitted value, so the plant is the true damper exactly."""
    fitted = {k: float(v) for k, v in load_params(params_path)["params"].items()}
    true = bouc_wen_rescale({k: float(v) for k, v in config["model"]["params"].items()}, 1.0)
    law_config = apply_overrides(config, [f"controller.law={LAW}", "mismatch.fraction=0"])
    law_config["model"]["params"] = {**true, **fitted}
    law_config["mismatch"]["params"] = {k: true[k] / fitted[k] - 1.0 for k in fitted if k in true and fitted[k]}
    result = run_job(LawJob(LAW, law_config, road, duration))
    return result.metrics["rms_accel_rad_s2"] if result.ok else math.nan


def truth_rms(folder: Path, truth: dict[str, np.ndarray], params: BoucWenParams, config: dict[str, Any]) -> float:
    """RMS after the settling of the emulator's true θ̈2 = (−k·θ − T)/J over the host's run, low-passed
    as compare's metric is."""
    from sashil.recording.data_file import read_data_csv

    cols = read_data_csv(folder / "data.csv", required=("time_s", "seq"))
    index = join_on_seq(cols["seq"][:-1].astype(np.int64), truth["seq"])
    ok = index >= 0
    if not np.any(ok):
        return math.nan
    lo, hi = int(index[ok].min()), int(index[ok].max()) + 1
    accel = (-params.k * truth["theta_true_rad"][lo:hi] - truth["torque_true_nm"][lo:hi]) / params.J
    rate, section = float(config["loop"]["rate_hz"]), config["compare"]
    smooth, _ = arm_acceleration({"arm_accel_true_rad_s2": accel}, rate, float(section["accel_bandwidth_hz"]))
    keep = np.unique(index[ok & (cols["time_s"][:-1] >= float(section["settle_s"]))]) - lo
    return float(np.sqrt(np.mean(smooth[keep] ** 2))) if keep.size else math.nan


def serial_run(config: dict[str, Any], sets: list[str], label: str, road: str, duration: float, tmp: Path) -> tuple:
    """One run over serial against a fresh ``sashil emulate`` of ``config``'s plant: (RMS θ̈2 of the
    encoders, of the emulator's truth, status)."""
    name = label.replace(" ", "-")
    plant, link, truth_path = tmp / f"{name}.yaml", tmp / f"{name}.pty", tmp / f"{name}.truth.csv"
    plant.write_text(dump_config(config), encoding="utf-8")
    folder = tmp / name
    folder.mkdir()
    # a link lost only after 2 s without a sample, as calibrate_emulated's host: a shared machine's pauses
    # (25 ms seen at load 4) do not end the run; the host still sets 0 A after driver.sample_timeout_ms
    host = apply_overrides(config, [*sets, "driver.name=serial", f"driver.port={link}", "driver.link_lost_ms=2000"])
    emulator = EmulatorProcess("serial", str(link), "--config", str(plant), "--truth", str(truth_path))
    try:
        result = run_job(LawJob(label, host, road, duration, str(folder)))
    finally:
        emulator.stop()
    if not result.ok:
        return math.nan, math.nan, result.status
    params = BoucWenParams.from_mapping(config["model"]["params"])
    return result.metrics["rms_accel_rad_s2"], truth_rms(folder, read_truth_csv(truth_path), params, config), "ok"


def model_refs(config: dict[str, Any], road_text: str, duration: float) -> dict[str, float]:
    """The bound on the damper's true model and the model's passive run at each reference current."""
    params = BoucWenParams.from_mapping(config["model"]["params"])
    road, _ = parse_road(road_text, RoadParts.read(config))
    tau, settle = float(config["rig"]["coil_tau_s"]), float(config["compare"]["settle_s"])
    bandwidth = float(config["compare"]["accel_bandwidth_hz"])
    refs = {"bound": hysteretic_bound(config, road, duration)}
    for current in reference_currents(config):
        refs[passive_label(current)] = model_passive(
            params, current, tau, road, duration, settle, bandwidth_hz=bandwidth
        )
    return refs


def shares(runs: dict[str, float], refs: dict[str, float], on_chain: bool) -> float:
    """The preview law's share of the bound with the best passive run of ``runs`` (NaN when one is
    missing); ``on_chain``: the bound put on the runs' chain first (:func:`bound_on_chain`)."""
    passive = {k: v for k, v in runs.items() if k.startswith("passive")}
    if not passive or not all(math.isfinite(v) for v in passive.values()):
        return math.nan  # a round without one of its passive runs: that one may have been the best
    best = min(passive, key=lambda k: passive[k])
    bound = bound_on_chain(refs["bound"], passive[best], refs[best]) if on_chain else refs["bound"]
    return share_of_bound(runs[LAW], passive[best], bound)


def damper_row(
    name: str,
    road: str,
    duration: float,
    calibrated: Path | None,
    serial: int,
    keep: Path | None = None,
    retries: int = 0,
) -> dict[str, Any]:
    """Every share of one damper (module docstring)."""
    config = config_of(dict(DAMPERS)[name], duration)
    refs = model_refs(config, road, duration)
    sim, sim_encoders = sim_runs(config, road, duration)
    row: dict[str, Any] = {"damper": name, "sim": shares(sim, refs, False), "refs": refs, "sim_rms": sim}
    row["sim_encoders"] = shares(sim_encoders, refs, True)
    params_path = calibrated / name.replace(" ", "_") / "params.yaml" if calibrated is not None else None
    if params_path is not None and params_path.exists():
        row["calibrated"] = shares({**sim, LAW: calibrated_run(config, params_path, road, duration)}, refs, False)
    if serial:
        folder = keep / name.replace(" ", "_") if keep is not None else None
        row.update(serial_shares(config, road, duration, refs, serial, folder, retries))
    progress(f"{name}: {_row_text(row)}")
    return row


def serial_shares(
    config: dict[str, Any],
    road: str,
    duration: float,
    refs: dict[str, float],
    repeat: int = 1,
    keep: Path | None = None,
    retries: int = 0,
) -> dict[str, Any]:
    """The runs over serial, ``repeat`` times, and the preview law's shares on each chain: the
    median of the rounds (each round's shares beside it: a run's realised road varies with the host's
    pauses, so one round's share varies)."""
    rounds = [serial_round(config, road, duration, refs, keep, i, retries) for i in range(repeat)]
    out: dict[str, Any] = {"serial_rounds": rounds}
    for key in ("serial_model_bound", "serial_one_chain", "serial_truth"):
        known = [r[key] for r in rounds if math.isfinite(r[key])]
        out[key] = statistics.median(known) if known else math.nan
    return out


def serial_round(
    config: dict[str, Any],
    road: str,
    duration: float,
    refs: dict[str, float],
    keep: Path | None = None,
    i: int = 0,
    retries: int = 0,
) -> dict[str, Any]:
    """One round of the runs over serial and the preview law's shares on each chain; ``keep``:
    the runs' folders (data.csv, the emulator's truth log) kept in keep/round-<i>; a run whose link
    failed (a write timeout while the emulator stalls under load) is run again up to ``retries``
    times, in keep/round-<i>/retry-<n>."""
    encoders, truth, status = {}, {}, {}
    with contextlib.ExitStack() as stack:
        if keep is None:
            tmp = stack.enter_context(tempfile.TemporaryDirectory(prefix="sashil-preview-link-"))
        else:
            tmp = str(keep / f"round-{i + 1}")
            Path(tmp).mkdir(parents=True, exist_ok=True)
        for label, sets in labels(config):
            for attempt in range(1 + retries):
                load = os.getloadavg()[0]
                folder = Path(tmp) / f"retry-{attempt}" if attempt else Path(tmp)
                folder.mkdir(exist_ok=True)
                encoders[label], truth[label], status[label] = serial_run(config, sets, label, road, duration, folder)
                progress(f"serial {label}: {status[label]}, encoders {encoders[label]:.3f}, truth {truth[label]:.3f}")
                status[label] += f" (load {load:.2f})" + (f" (retry {attempt})" if attempt else "")
                if math.isfinite(encoders[label]):
                    break
    return {
        "serial_model_bound": shares(encoders, refs, False),
        "serial_one_chain": shares(encoders, refs, True),
        "serial_truth": shares(truth, refs, False),
        "encoders": encoders,
        "truth": truth,
        "status": status,
    }


COLUMNS = (
    ("sim", "sim, exact model"),
    ("calibrated", "sim, calibrated model"),
    ("sim_encoders", "sim: encoders, one chain"),
    ("serial_model_bound", "serial: encoders vs model bound"),
    ("serial_one_chain", "serial: one chain (compare)"),
    ("serial_truth", "serial: emulator's truth"),
)


def _row_text(row: dict[str, Any]) -> str:
    return "  ".join(f"{key} {row[key]:6.1f}%" for key, _ in COLUMNS if key in row)


def table(rows: list[dict[str, Any]]) -> None:
    """Per damper the preview law's shares, then each column's median and worst."""
    print()
    print(f"preview-optimal's share of the bound [%], {ROAD}; load {os.getloadavg()[0]:.2f}")
    present = [(key, heading) for key, heading in COLUMNS if any(key in row for row in rows)]
    print(f"  {'damper':10s}" + "".join(f"{heading:>34s}" for _, heading in present))
    for row in rows:
        print(f"  {row['damper']:10s}" + "".join(f"{row.get(key, math.nan):33.1f}%" for key, _ in present))
    for what, pick in (("median", statistics.median), ("worst", min)):
        cells = []
        for key, _ in present:
            known = [row[key] for row in rows if key in row and math.isfinite(row[key])]
            cells.append(pick(known) if known else math.nan)
        print(f"  {what:10s}" + "".join(f"{cell:33.1f}%" for cell in cells))
    for row in rows:
        for i, r in enumerate(row.get("serial_rounds", ())):
            enc, truth = r["encoders"], r["truth"]
            off = "  ".join(f"{k} {100 * (enc[k] / truth[k] - 1):+.1f}" for k in enc)
            print(
                f"  {row['damper']} round {i + 1}: shares {r['serial_model_bound']:.1f} / {r['serial_one_chain']:.1f} / "
                f"{r['serial_truth']:.1f} %; encoders' RMS θ̈2 against the truth's [%]: {off}"
            )
            print(f"    RMS θ̈2 encoders {enc}, truth {truth}; {r['status']}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the seed damper, 2.5 s runs, serial only: seconds")
    parser.add_argument("--dampers", default=",".join(DAMPERS_DEFAULT), help="comma-separated damper names")
    parser.add_argument("--duration", type=float, default=12.0, help="seconds per run (the first 2 s left out)")
    parser.add_argument("--calibrated", type=Path, help="DIR/<damper>/params.yaml: models calibrated over serial")
    parser.add_argument("--calibrate", action="store_true", help="calibrate into --calibrated first (over serial)")
    parser.add_argument("--no-serial", action="store_true", help="leave out the runs over serial")
    parser.add_argument("--json", type=Path, help="write every damper's figures here")
    parser.add_argument("--keep", type=Path, help="keep the serial runs' folders in KEEP/<damper>/round-<i>")
    parser.add_argument("--retries", type=int, default=0, help="run a serial run whose link failed again, N times")
    parser.add_argument("--repeat", type=int, default=1, help="rounds of the serial runs per damper (median)")
    args = parser.parse_args()
    dampers = ["seed"] if args.quick else [d.strip() for d in args.dampers.split(",")]
    duration = 2.5 if args.quick else args.duration
    unknown = [d for d in dampers if d not in dict(DAMPERS)]
    if unknown:
        print(f"--dampers: no damper {unknown[0]!r} (bench_drop_damping's names)", file=sys.stderr)
        return 2
    if args.calibrate and args.calibrated is not None:
        calibrate(dampers, args.calibrated)
    print(f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; {len(dampers)} dampers, {ROAD}, {duration:g} s")
    rounds = 0 if args.no_serial else max(1, args.repeat)
    rows = [damper_row(d, ROAD, duration, args.calibrated, rounds, args.keep, max(0, args.retries)) for d in dampers]
    table(rows)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1), encoding="utf-8")
    return 0


def calibrate(dampers: list[str], folder: Path) -> None:
    """``sashil calibrate`` over serial against ``sashil emulate`` of each damper into folder/<damper>."""
    from sashil.engine.resolve import default_config
    from sashil.lab.calibration.emulated import calibrate_emulated

    for name in dampers:
        out = folder / name.replace(" ", "_")
        if (out / "params.yaml").exists():
            continue
        config = default_config()
        config["model"]["params"].update(dict(DAMPERS)[name])
        progress(f"calibrating {name} over serial")
        calibrate_emulated(config, out, transport="serial", inertia=float(config["model"]["params"]["J"]))


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("bench_preview_link", main))
