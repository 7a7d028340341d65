#!/usr/bin/env python3
"""Benchmark: how far one host pause moves a compared law's figures, which sets
``compare.max_pause_ms``.

Over a link the host sends each cycle's road speed, and the board holds the last one while the host
is paused. For a spread of dampers (``tools/bench_drop_damping.py``'s: the Bouc-Wen exponent n, the
yield torque through alpha1, the inertia J, c1 and k varied around seed 001's set), each law of a
comparison (passive at 0 A and 1 A, skyhook-add) runs on ISO 8608 class C on the simulated rig
(virtual clock), once as the host runs it and then with the host paused once for Δ (every command,
the coil's and the road's, held for Δ) at each of several moments after the settle. It prints, per Δ,
the change of RMS travel θ and of RMS θ̈2 against the unpaused run, worst and median over the
dampers, laws and moments; the baseline is Δ = 0 (the same run twice: 0 exactly, as the rig is
deterministic on the virtual clock).

    .venv/bin/python tools/bench_compare_pause.py [--quick] [--json PATH]

The figures are kept as JSON (``tools/bench_record.py``: the commit, the date, the load):
``tools/out/bench_compare_pause.json``, or ``--json PATH`` (a quick run: only with ``--json``).

``--quick``: one damper, one law, one Δ, two moments, 3 s runs; the figures mean little.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_drop_damping import DAMPERS
from bench_record import Recorder, out_path

from sashil import engine
from sashil.control.registry import make_stage
from sashil.drivers import open_rig
from sashil.drivers.interface import RigCommand
from sashil.engine import assemble
from sashil.engine.resolve import apply_overrides, default_config
from sashil.lab._compare import READS, MeasuredStage
from sashil.lab.compare_metrics import metrics_of
from sashil.roads.option import RoadParts, RoadStage, parse_road

LAWS = {"passive 0 A": ["controller.law=passive", "controller.current_a=0"],
        "passive 1 A": ["controller.law=passive", "controller.current_a=1"],
        "skyhook-add": ["controller.law=skyhook-add"]}  # fmt: skip
DAMPER_SET = ("seed", "n 1", "alpha1 0.3", "alpha1 2", "J 0.5", "J 2", "c1 0.05", "k 70")
PAUSES_MS = (5.0, 10.0, 20.0, 40.0)
DURATION_S, SETTLE_S, MOMENTS = 8.0, 2.0, 6


class PausedHost:
    """The stage of a host that pauses once, from ``start_s`` for ``pause_s`` after its first step:
    the rig holds the last command meanwhile (the law does not run), as a board holds it."""

    def __init__(self, stage: Any, start_s: float, pause_s: float):
        self.stage, self.start_s, self.pause_s = stage, start_s, pause_s
        self._t0: int | None = None
        self._last: RigCommand | None = None

    def __getattr__(self, name: str) -> Any:
        if name == "stage":
            raise AttributeError(name)
        return getattr(self.stage, name)

    def step(self, sample: Any, t_ns: int, dt_ns: int) -> RigCommand | None:
        if self._t0 is None:
            self._t0 = t_ns
        t = (t_ns - self._t0) * 1e-9
        if self._last is not None and self.start_s <= t < self.start_s + self.pause_s:
            return RigCommand(self._last.current_a, self._last.road_speed_rad_s)
        cmd = self.stage.step(sample, t_ns, dt_ns)
        if cmd is not None:
            self._last = RigCommand(cmd.current_a, cmd.road_speed_rad_s)
        return cmd


@dataclass
class Figures:
    travel_deg: float
    comfort_rad_s2: float


def run_law(config: dict[str, Any], duration_s: float, pause: tuple[float, float] | None) -> Figures:
    """One law's run on the road, its host paused once (``(start_s, pause_s)``) or not (None)."""
    run = assemble(config, reads=READS)
    road, _ = parse_road("iso8608:C", RoadParts.of(run.options))
    stage: Any = RoadStage(make_stage(run.stage)[1], road, duration_s)
    if pause is not None:
        stage = PausedHost(stage, *pause)
    rig = open_rig(run.rig)
    outcome = engine.run(run, MeasuredStage(stage, rig), duration_s, rig=lambda: rig, realtime=False,
                         say=lambda _: None)  # fmt: skip
    metrics, *_ = metrics_of(outcome.stream, run)
    return Figures(metrics["rms_theta_deg"], metrics["rms_accel_rad_s2"])


def change_pct(paused: Figures, base: Figures) -> tuple[float, float]:
    return (
        100.0 * (paused.travel_deg / base.travel_deg - 1.0),
        100.0 * (paused.comfort_rad_s2 / base.comfort_rad_s2 - 1.0),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="a tiny problem (CI): the figures mean little")
    parser.add_argument(
        "--json", metavar="PATH", type=Path, help="write the record here (default: tools/out/bench_compare_pause.json)"
    )
    args = parser.parse_args()
    record = Recorder("bench_compare_pause")
    dampers = [(n, p) for n, p in DAMPERS if n in (("seed",) if args.quick else DAMPER_SET)]
    laws = dict(list(LAWS.items())[:1]) if args.quick else LAWS
    pauses = (20.0,) if args.quick else PAUSES_MS
    duration, moments = (3.0, 2) if args.quick else (DURATION_S, MOMENTS)
    settle = 1.0 if args.quick else SETTLE_S
    starts = [settle + (duration - settle - 0.5) * (k + 0.5) / moments for k in range(moments)]
    print(f"one host pause on iso8608:C, {duration:g} s runs (the first {settle:g} s left out), paused at "
          f"{', '.join(f'{s:.2f}' for s in starts)} s; {len(dampers)} dampers x {len(laws)} laws")  # fmt: skip
    changes: dict[float, list[tuple[float, float]]] = {0.0: []}
    rows = []
    for name, params in dampers:
        base_config: dict[str, Any] = default_config()
        base_config["model"]["params"].update(params)
        base_config["compare"]["settle_s"] = settle
        for law, sets in laws.items():
            config = apply_overrides(base_config, sets)
            base = run_law(config, duration, None)
            changes[0.0].append(change_pct(run_law(config, duration, None), base))
            for pause_ms in pauses:
                for start in starts:
                    travel, comfort = change_pct(run_law(config, duration, (start, pause_ms / 1e3)), base)
                    changes.setdefault(pause_ms, []).append((travel, comfort))
                    rows.append({"damper": name, "law": law, "pause_ms": pause_ms, "start_s": start,
                                 "travel_pct": travel, "comfort_pct": comfort})  # fmt: skip
            print(f"  {name:12s} {law:12s} travel {base.travel_deg:.3f} deg, RMS θ̈2 {base.comfort_rad_s2:.3f} rad/s²",
                  flush=True)  # fmt: skip
    print(f"\n{'pause [ms]':>10s} {'runs':>5s} {'travel: worst':>14s} {'median':>7s} {'θ̈2: worst':>11s} {'median':>7s}")
    for pause_ms, seen in changes.items():
        travel = [abs(t) for t, _ in seen]
        comfort = [abs(c) for _, c in seen]
        label = f"{pause_ms:g}" + (" (baseline: none)" if pause_ms == 0.0 else "")
        print(f"{label:>10s} {len(seen):5d} {max(travel):13.2f}% {statistics.median(travel):6.2f}% "
              f"{max(comfort):10.2f}% {statistics.median(comfort):6.2f}%")  # fmt: skip
    path = args.json if args.json is not None else (None if args.quick else out_path("bench_compare_pause"))
    if path is not None:
        summary = {
            f"{pause_ms:g}": {
                "runs": len(seen),
                "travel_worst_pct": max(abs(t) for t, _ in seen),
                "travel_median_pct": statistics.median(abs(t) for t, _ in seen),
                "comfort_worst_pct": max(abs(c) for _, c in seen),
                "comfort_median_pct": statistics.median(abs(c) for _, c in seen),
            }
            for pause_ms, seen in changes.items()
        }
        figures = {"duration_s": duration, "settle_s": settle, "by_pause_ms": summary, "changes": rows}
        print(f"record: {record.write(path, figures)}")


if __name__ == "__main__":
    main()
