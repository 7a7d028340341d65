"""What a lab asserts on about its law's run: comfort and travel against the passive baseline, and
the share of the optimal bound, the figures ``sashil compare`` reports for the same run.

The metrics are ``sashil compare``'s (:mod:`sashil.lab._compare`): comfort is the RMS arm
acceleration θ̈2 low-passed at ``compare.accel_bandwidth_hz``, travel the RMS relative angle θ, both
after ``compare.settle_s``. The passive baseline is compare's own
(:func:`sashil.lab.passive_baseline.best_constant_current`): on the simulated rig a bounded search
for the best constant current over [0, i_max], each candidate run on the same rig, road, seed and
duration as the law (the law's ``config.yaml`` with the passive law); with ``currents_a`` the best
of those currents, as compare finds it on a real rig. The optimal bound is compare's too
(:func:`sashil.lab._compare.compare_bound`, on the controller's model, its cost over the metric's
window, from starts no law made), and a law's share of it is compare's
100·(passive − law)/(passive − bound) (:func:`sashil.lab.compare_report.share_of_bound`).

Baselines and bounds are kept for the rest of the process: every law of a test session compared on
one road runs them once.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sashil.api import Run
from sashil.config.frozen import freeze_config
from sashil.config.parts import RunSpec, StageParts
from sashil.engine import assemble
from sashil.lab._compare import READS as COMPARE_READS
from sashil.lab._compare import compare_bound, passive_job, run_job, scale_bound
from sashil.lab.compare_metrics import LawResult
from sashil.lab.compare_report import above_bound, share_of_bound
from sashil.lab.hysteretic_bound import HystereticBound
from sashil.lab.passive_baseline import Baseline, best_constant_current
from sashil.roads.option import RoadParts, parse_road

__all__ = ["Comparison", "compare_with_passive"]

_baseline_cache: dict[str, Baseline] = {}
_bound_cache: dict[str, HystereticBound | None] = {}


@dataclass(frozen=True)
class Comparison:
    """A law's run against the passive baseline on the same rig and road.

    Gains are positive when the law is better: ``comfort_gain_pct`` = 100·(1 − RMS θ̈2 / the
    baseline's), the baseline the best constant current (``comfort_current_a``, found by
    ``baseline_method``: ``"search"`` or ``"listed"``); ``travel_gain_pct`` = 100·(1 − RMS θ / the
    least RMS θ of the constant currents run to find the baseline, 0 A and i_max among them on the
    simulated rig). ``bound_gain_pct``: how far the bound lies below the baseline;
    ``share_of_bound_pct``: where the law lies from the baseline (0) to the bound (100), flagged in
    ``above_bound`` beyond 100 % by more than compare's tolerance; NaN without a bound."""

    law: str
    rms_accel_rad_s2: float
    rms_theta_deg: float
    comfort_current_a: float
    comfort_rms_accel_rad_s2: float
    travel_current_a: float
    travel_rms_theta_deg: float
    comfort_gain_pct: float
    travel_gain_pct: float
    bound_gain_pct: float
    share_of_bound_pct: float
    baseline_method: str = "search"
    bound_rms_accel_rad_s2: float = math.nan
    above_bound: bool = False

    def __str__(self) -> str:
        return (
            f"{self.law}: comfort {self.comfort_gain_pct:+.1f} % against {self.comfort_current_a:g} A, travel "
            f"{self.travel_gain_pct:+.1f} % against {self.travel_current_a:g} A, "
            f"{self.share_of_bound_pct:.0f} % of the optimal bound's {self.bound_gain_pct:.1f} %"
            + (" (above the bound)" if self.above_bound else "")
        )


def compare_with_passive(run: Run, currents_a: Sequence[float] | None = None, *, bound: bool = True) -> Comparison:
    """Compare a law's ``run`` (a run of :func:`sashil.testing.run_law`) with compare's passive
    baseline (default: the bounded search over [0, ``rig.current_max_a``]; ``currents_a``: the best
    of those currents) and, with ``bound``, with compare's optimal bound on its road."""
    config = run.config
    summary = run.summary
    if summary.get("exit_status") != "ok" or not run.metrics:
        raise ValueError(f"{run.path}: the law's run did not finish ({summary.get('error') or summary.get('status')})")
    if currents_a is not None and not list(currents_a):
        raise ValueError("currents_a: give at least one constant current")
    stage = StageParts.read(config)
    spec = assemble(freeze_config(config), reads=COMPARE_READS)
    baseline = _baseline(config, spec, currents_a)
    travel = min(
        (c for c, r in baseline.evaluated.items() if r.ok), key=lambda c: baseline.evaluated[c].metrics["rms_theta_deg"]
    )
    travel_theta = float(baseline.evaluated[travel].metrics["rms_theta_deg"])
    accel, theta = float(run.metrics["rms_accel_rad_s2"]), float(run.metrics["rms_theta_deg"])
    p = baseline.rms_accel
    b = _scale(config, spec, baseline) if bound else math.nan
    share = share_of_bound(accel, p, b)
    return Comparison(
        law=str(summary.get("controller") or stage.law),
        rms_accel_rad_s2=accel,
        rms_theta_deg=theta,
        comfort_current_a=baseline.current_a,
        comfort_rms_accel_rad_s2=p,
        travel_current_a=travel,
        travel_rms_theta_deg=travel_theta,
        comfort_gain_pct=100.0 * (1.0 - accel / p),
        travel_gain_pct=100.0 * (1.0 - theta / travel_theta),
        bound_gain_pct=100.0 * (1.0 - b / p),
        share_of_bound_pct=share,
        baseline_method=baseline.method,
        bound_rms_accel_rad_s2=b,
        above_bound=above_bound(share),
    )


def _key(config: dict[str, Any], *parts: Any) -> str:
    """What a reference depends on: the config without the law's section, and ``parts``."""
    rest = {key: value for key, value in config.items() if key != "controller"}
    return json.dumps([rest, *parts], sort_keys=True, default=str)


def _road(spec: RunSpec) -> tuple[str, float]:
    return str(spec.options["road"]), float(spec.options["duration_s"])


def _baseline(config: dict[str, Any], spec: RunSpec, currents_a: Sequence[float] | None) -> Baseline:
    """Compare's passive baseline on the run's rig and road (module docstring)."""
    listed = None if currents_a is None else [float(c) for c in currents_a]
    key = _key(config, "baseline", listed)
    if key not in _baseline_cache:
        road, duration = _road(spec)

        def run_current(current: float) -> LawResult:
            return run_job(passive_job(config, current, road, duration))

        _baseline_cache[key] = best_constant_current(run_current, spec.stage.current_max_a, listed)
    return _baseline_cache[key]


def _scale(config: dict[str, Any], spec: RunSpec, baseline: Baseline) -> float:
    """Compare's 100 %: its optimal bound on the run's road, on the runs' chain (module docstring)."""
    key = _key(config, "bound")
    road_text, duration = _road(spec)
    road, _ = parse_road(road_text, RoadParts.of(spec.options))
    if road is None:
        raise ValueError("compare.road: none: the optimal bound needs a road")
    if key not in _bound_cache:
        _bound_cache[key] = compare_bound(spec, road, duration)
    bound = _bound_cache[key]
    if bound is None:
        return math.nan
    return scale_bound(spec, road, duration, bound.rms_accel_bound, baseline)
