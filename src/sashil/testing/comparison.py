"""What a lab asserts on about its law's run: comfort and travel against the best constant current,
and the share of the optimal bound.

The metrics are ``sashil compare``'s (:mod:`sashil.lab._compare`): comfort is the RMS arm
acceleration θ̈2 low-passed at ``compare.accel_bandwidth_hz``, travel the RMS relative angle θ, both
after ``compare.settle_s``. The references are the passive damper at constant currents, each run on
the same rig, road, seed and duration as the law (the law's ``config.yaml`` with the passive law).
The optimal bound is :func:`sashil.lab.optimal_bound.optimal_bound`'s: the best comfort any
damping inside the feasible band could reach on this road knowing it in advance, in the model's
viscous envelope; a law's share of it is its comfort gain over the best constant current as a share
of the bound's gain over the best constant damping (as ``compare.md`` reports it).

References and bounds are kept for the rest of the process: every law of a test session compared on
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
from sashil.config.parts import StageParts
from sashil.engine import assemble
from sashil.engine.resolve import ConfigSource, resolve
from sashil.lab._compare import READS as COMPARE_READS
from sashil.lab._compare import LawJob, run_job
from sashil.lab.optimal_bound import BoundResult, optimal_bound
from sashil.models.hysteresis import BoucWenParams
from sashil.roads.option import RoadParts, parse_road

__all__ = ["Comparison", "compare_with_passive"]

#: the constant currents tried, as fractions of rig.current_max_a
CURRENT_FRACTIONS = (0.0, 0.25, 0.5, 0.75, 1.0)

_passive_cache: dict[str, dict[str, float]] = {}
_bound_cache: dict[str, BoundResult] = {}


@dataclass(frozen=True)
class Comparison:
    """A law's run against the constant currents on the same rig and road.

    Gains are positive when the law is better: ``comfort_gain_pct`` = 100·(1 − RMS θ̈2 / that of the
    constant current with the lowest RMS θ̈2), ``travel_gain_pct`` = 100·(1 − RMS θ / that of the
    constant current with the lowest RMS θ). ``share_of_bound_pct``: ``comfort_gain_pct`` as a share
    of the optimal bound's gain (100: all the bound allows; NaN when the bound is no better than
    constant damping)."""

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

    def __str__(self) -> str:
        return (
            f"{self.law}: comfort {self.comfort_gain_pct:+.1f} % against {self.comfort_current_a:g} A, travel "
            f"{self.travel_gain_pct:+.1f} % against {self.travel_current_a:g} A, "
            f"{self.share_of_bound_pct:.0f} % of the optimal bound's {self.bound_gain_pct:.1f} %"
        )


def compare_with_passive(run: Run, currents_a: Sequence[float] | None = None, *, bound: bool = True) -> Comparison:
    """Compare a law's ``run`` (a run of :func:`sashil.testing.run_law`) with the passive damper at
    ``currents_a`` (default: 0, ¼, ½, ¾ and all of ``rig.current_max_a``) and, with ``bound``, with
    the optimal bound on its road."""
    config = run.config
    summary = run.summary
    if summary.get("exit_status") != "ok" or not run.metrics:
        raise ValueError(f"{run.path}: the law's run did not finish ({summary.get('error') or summary.get('status')})")
    stage = StageParts.read(config)
    i_max = stage.current_max_a
    currents = [fraction * i_max for fraction in CURRENT_FRACTIONS] if currents_a is None else list(currents_a)
    if not currents:
        raise ValueError("currents_a: give at least one constant current")
    passive = {current: _passive(config, current) for current in currents}
    comfort = min(passive, key=lambda current: passive[current]["rms_accel_rad_s2"])
    travel = min(passive, key=lambda current: passive[current]["rms_theta_deg"])
    accel, theta = float(run.metrics["rms_accel_rad_s2"]), float(run.metrics["rms_theta_deg"])
    comfort_gain = 100.0 * (1.0 - accel / passive[comfort]["rms_accel_rad_s2"])
    bound_gain = _bound(config).gain_pct if bound else math.nan
    return Comparison(
        law=str(summary.get("controller") or stage.law),
        rms_accel_rad_s2=accel,
        rms_theta_deg=theta,
        comfort_current_a=comfort,
        comfort_rms_accel_rad_s2=passive[comfort]["rms_accel_rad_s2"],
        travel_current_a=travel,
        travel_rms_theta_deg=passive[travel]["rms_theta_deg"],
        comfort_gain_pct=comfort_gain,
        travel_gain_pct=100.0 * (1.0 - theta / passive[travel]["rms_theta_deg"]),
        bound_gain_pct=bound_gain,
        share_of_bound_pct=100.0 * comfort_gain / bound_gain if bound_gain > 0.0 else math.nan,
    )


def _key(config: dict[str, Any], *parts: Any) -> str:
    """What a reference depends on: the config without the law's section, and ``parts``."""
    rest = {key: value for key, value in config.items() if key != "controller"}
    return json.dumps([rest, *parts], sort_keys=True, default=str)


def _passive(config: dict[str, Any], current_a: float) -> dict[str, float]:
    """The metrics of the passive damper at ``current_a`` on the run's rig and road."""
    key = _key(config, current_a)
    if key not in _passive_cache:
        passive = resolve(
            ConfigSource(config=config, controller="passive", sets=(f"controller.current_a={current_a!r}",)),
            "compare",
        )
        section = assemble(passive, reads=COMPARE_READS).options
        result = run_job(
            LawJob(f"passive {current_a:g} A", passive, str(section["road"]), float(section["duration_s"]))
        )
        if not result.ok:
            raise RuntimeError(f"the passive damper at {current_a:g} A did not finish: {result.status}")
        _passive_cache[key] = dict(result.metrics)
    return _passive_cache[key]


def _bound(config: dict[str, Any]) -> BoundResult:
    """The optimal bound on the run's road for its model (module docstring)."""
    key = _key(config, "bound")
    if key not in _bound_cache:
        run = assemble(freeze_config(config), reads=COMPARE_READS)
        section = run.options
        road, _ = parse_road(str(section["road"]), RoadParts.of(section))
        if road is None:
            raise ValueError("compare.road: none: the optimal bound needs a road")
        _bound_cache[key] = optimal_bound(
            BoucWenParams.from_mapping(run.stage.model.params),
            run.stage.current_max_a,
            road,
            float(section["duration_s"]),
            float(section["settle_s"]),
        )
    return _bound_cache[key]
