#!/usr/bin/env python3
"""Does a drop test's damping ratio depend on how long it recorded?

For a spread of dampers (the Bouc-Wen exponent n, the yield torque through alpha1 and delta, the inertia
J, the viscous c1 and the spring k, each varied around seed 001's set, and a few combinations), at 0 A
and 1 A: a simulated drop test from -5 deg recorded for 3 s, 4 s and 10 s (three runs each, sim backend
on the virtual clock, 4096-count encoder), and

- the spread (max - min) / zeta(10 s) of the damping ratio the drop test reports (the log decrement
  over the first two cycles, peaks >= 8 encoder counts), worst and median over the dampers;
- the same spread for the mean of every successive decrement (what a record-long mean would report);
- whether the reported interval (+-1/2 encoder count on the two peaks) holds the log decrement of the
  same peaks read by an unquantised encoder;
- (not with --quick) a damper too slow for the shortest record (J = 4: 0.83 Hz, the first two cycles
  end after 3 s): its spread, and whether the 3 s drop says its record is too short.

Goal: worst spread <= 2 % over the dampers whose first two cycles fit in the shortest record.

    .venv/bin/python tools/bench_drop_damping.py [--quick]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path
from typing import Any

from sashil.engine.resolve import default_config
from sashil.lab._drop_test import run_drop_test
from sashil.lab.metrics import DropMetrics, damping_ratio_of

#: record lengths the damping ratio must not depend on [s]
DURATIONS_S = (3.0, 4.0, 10.0)
#: goal: the worst relative spread of the damping ratio over DURATIONS_S
GOAL = 0.02
#: an encoder fine enough that its quantisation does not matter (the reference damping ratio)
FINE_COUNTS = 2**24

#: (name, changes to the seed parameters): one parameter at a time, then combinations
DAMPERS: tuple[tuple[str, dict[str, float]], ...] = (
    ("seed", {}),
    ("n 0.3", {"n": 0.3}),
    ("n 1", {"n": 1.0}),
    ("alpha1 0.3", {"alpha1": 0.3}),
    ("alpha1 2", {"alpha1": 2.0}),
    ("delta 300", {"delta": 300.0}),
    ("delta 1500", {"delta": 1500.0}),
    ("J 0.5", {"J": 0.5}),
    ("J 1.5", {"J": 1.5}),
    ("J 2", {"J": 2.0}),
    ("c1 0.05", {"c1": 0.05}),
    ("c1 0.3", {"c1": 0.3}),
    ("c1 2", {"c1": 2.0}),
    ("k 70", {"k": 70.0}),
    ("k 160", {"k": 160.0}),
    ("c1 0.05 alpha1 0.3", {"c1": 0.05, "alpha1": 0.3}),
    ("J 2 k 70", {"J": 2.0, "k": 70.0}),
    ("n 1 delta 300 alpha1 2", {"n": 1.0, "delta": 300.0, "alpha1": 2.0}),
)
#: the --quick subset (CI): the seed, a light, a stiff-yield, a heavy-arm and a soft-spring damper
QUICK = ("seed", "c1 0.05", "alpha1 2", "J 2", "k 70")


def drop(params: dict[str, float], current_a: float, duration_s: float, counts: int = 4096) -> DropMetrics:
    """The metrics of one simulated drop test from -5 deg."""
    config: dict[str, Any] = default_config()
    config["model"]["params"].update(params)
    config["rig"]["encoder_counts_per_rev"] = counts
    metrics = run_drop_test(config, -5.0, current_a, duration_s).metrics
    assert metrics is not None  # run_drop_test always computes them
    return metrics


def spread(values: list[float | None]) -> float | None:
    """(max - min) / last of values that all exist, else None."""
    if any(v is None for v in values):
        return None
    known = [v for v in values if v is not None]
    return (max(known) - min(known)) / known[-1]


def mean_of_all(metrics: DropMetrics) -> float | None:
    """The damping ratio of the mean of every successive log decrement in the record."""
    return damping_ratio_of(statistics.fmean(metrics.log_decrements)) if metrics.log_decrements else None


def reference_ratio(params: dict[str, float], current_a: float, cycles: int) -> float:
    """The damping ratio of the first ``cycles`` cycles' peaks read by an unquantised encoder."""
    peaks = drop(params, current_a, DURATIONS_S[-1], FINE_COUNTS).peaks_deg
    return damping_ratio_of(math.log(peaks[0] / peaks[cycles]) / cycles)


def too_slow() -> None:
    """A damper whose first two cycles outlast the shortest record: the figure and the warning."""
    params = {"J": 4.0}
    runs = [drop(params, 0.0, d) for d in DURATIONS_S]
    s = spread([m.damping_ratio for m in runs])
    print(
        f"limit: J 4 (period {runs[-1].period_s:.2f} s) at 0 A: spread {'-' if s is None else f'{100 * s:.1f} %'}; "
        f"the 3 s drop says its record is too short: {runs[0].damping_record_short} ({runs[0].damping_note})"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="five dampers at 0 A only (CI)")
    args = parser.parse_args()
    dampers = [(name, p) for name, p in DAMPERS if not args.quick or name in QUICK]
    currents = (0.0,) if args.quick else (0.0, 1.0)
    print(f"damping ratio of drop tests recorded for {', '.join(f'{d:g}' for d in DURATIONS_S)} s")
    print(f"{'damper':26s} {'i [A]':>5s} {'zeta(10 s)':>10s} {'interval':>17s} {'spread':>7s} {'all-peaks':>9s} ref-in")
    spreads, old_spreads, covered, measured, without = [], [], 0, 0, []
    for name, params in dampers:
        for current in currents:
            runs = [drop(params, current, d) for d in DURATIONS_S]
            ratios = [m.damping_ratio for m in runs]
            s, old = spread(ratios), spread([mean_of_all(m) for m in runs])
            if s is None:
                without.append(f"{name} {current:g} A")
                continue
            measured += 1
            spreads.append(s)
            if old is not None:
                old_spreads.append(old)
            last = runs[-1]
            assert last.damping_ratio is not None and last.damping_ratio_interval is not None
            low, high = last.damping_ratio_interval
            inside = low <= reference_ratio(params, current, last.damping_cycles) <= high
            covered += inside
            old_text = "-" if old is None else f"{100 * old:.1f} %"
            print(
                f"{name:26s} {current:5g} {last.damping_ratio:10.4f} [{low:.4f}, {high:.4f}] {100 * s:5.2f} % "
                f"{old_text:>9s} {'yes' if inside else 'NO'}"
            )
    worst, typical = max(spreads), statistics.median(spreads)
    print(
        f"spread of zeta over 3/4/10 s records, {measured} drops: worst {100 * worst:.2f} %, median "
        f"{100 * typical:.2f} %   [goal <= {100 * GOAL:g} %]"
    )
    if old_spreads:
        print(
            f"  (mean of every successive decrement instead: worst {100 * max(old_spreads):.1f} %, median "
            f"{100 * statistics.median(old_spreads):.1f} %)"
        )
    print(f"  interval holds the unquantised encoder's zeta: {covered} of {measured}")
    if without:
        print(f"  no damping ratio (fewer than two peaks >= 8 counts): {', '.join(without)}")
    if not args.quick:
        too_slow()
    if worst > GOAL or not math.isfinite(worst):
        raise SystemExit(f"worst spread {100 * worst:.2f} % > {100 * GOAL:g} %")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_drop_damping", main)
