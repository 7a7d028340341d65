"""Which extra step would most shrink the widest interval of the lab's quantities.

A candidate step s (a drop from an angle at a current, or a road chirp at a current, seed 001
section 8) is simulated with the fitted model on its inputs
(:meth:`sashil.identify.rig_models.RigModel.simulate`) and differentiated over the fit's search
vector: J_s. Adding it to the fit's information H = J^T J shrinks a quantity q's variance along
g = dq/dx by

    ratio = sqrt(g^T (H + J_s^T J_s)^-1 g / g^T H^-1 g)

if the step's residuals scatter like the fit's (per unit of information; their correlation is the
same factor in both and cancels). The predicted interval is the jackknife's present one times that
ratio. A prediction from the linearised model, not a measurement: it ranks the candidates.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sashil.config.section_parts import CalibratePart
from sashil.identify.data import Record, record_from_columns
from sashil.identify.fit import FitResult
from sashil.identify.intervals import LAB, Intervals, params_at, quantities
from sashil.identify.rig_models import MODELS
from sashil.lab.calibration.analysis import road_acceleration, trimmed
from sashil.plans.calibration_step import RoadChirp, Step

#: sample period of a candidate's simulated record [s]
CANDIDATE_DT_S = 1e-3


@dataclass
class Suggestion:
    step: Step
    quantity: str  # the lab quantity whose interval is widest now
    now: float  # its relative half-width now
    predicted: float  # its predicted relative half-width with the step added


def candidates(section: CalibratePart, current_max_a: float, road: RoadChirp) -> list[Step]:
    """Drops from the plan's large and small angles, and road chirps, at 0 A, i_max/2 and i_max."""
    currents = (0.0, 0.5 * current_max_a, current_max_a)
    out = []
    for i in currents:
        for angle in (section.theta0_deg, section.small_theta0_deg):
            out.append(Step(f"extra-drop-{abs(angle):g}deg-{i:.2f}A", "fit", angle, i, section.drop_duration_s))
    for i in currents:
        out.append(
            Step(
                f"extra-road-{abs(section.theta0_deg):g}deg-{i:.2f}A",
                "fit",
                section.theta0_deg,
                i,
                section.road_duration_s,
                road,
            )
        )
    return out


def candidate_record(result: FitResult, step: Step, counts_per_rev: int) -> Record:
    """The step's record as the fitted model predicts it (a drop cut as the fit cuts one)."""
    t = np.arange(0.0, step.duration_s, CANDIDATE_DT_S)
    columns = {
        "time_s": t,
        "theta_rad": np.full(t.size, math.radians(step.theta0_deg)),
        "current_a": np.full(t.size, step.current_a),
    }
    acc = np.zeros(t.size)
    if step.road is not None:
        acc = road_acceleration(t, np.array([step.road.speed(v) for v in t]))
    probe = _with_road(record_from_columns(step.name, columns), acc)
    columns["theta_rad"] = MODELS[result.model].simulate(result.params, probe)
    if step.road is None:
        columns = trimmed(columns, counts_per_rev)
        acc = acc[: columns["time_s"].size]
    return _with_road(record_from_columns(step.name, columns), acc)


def _with_road(record: Record, acc: np.ndarray) -> Record:
    """The record driven by the road acceleration ``acc`` (the chirp's; zero for a drop)."""
    return dataclasses.replace(record, acc_road=acc)


def step_jacobian(result: FitResult, record: Record) -> np.ndarray:
    """d theta_sim / dx over the step's record (central differences over the search vector)."""
    assert result.x is not None
    model = MODELS[result.model]
    out = np.zeros((record.theta.size, result.x.size))
    for j in range(result.x.size):
        h = 1e-6 * max(abs(result.x[j]), 1e-3)
        up, down = result.x.copy(), result.x.copy()
        up[j] += h
        down[j] -= h
        out[:, j] = (
            model.simulate(params_at(result, up), record) - model.simulate(params_at(result, down), record)
        ) / (2 * h)
    return out


def gradients(result: FitResult, names: Sequence[str], current_max_a: float) -> np.ndarray:
    """dq/dx of each named quantity (rows) at the optimum."""
    assert result.x is not None
    out = np.zeros((len(names), result.x.size))
    for j in range(result.x.size):
        h = 1e-6 * max(abs(result.x[j]), 1e-3)
        up, down = result.x.copy(), result.x.copy()
        up[j] += h
        down[j] -= h
        qu = quantities(result, params_at(result, up), current_max_a)
        qd = quantities(result, params_at(result, down), current_max_a)
        out[:, j] = [(qu[n] - qd[n]) / (2 * h) for n in names]
    return out


def predicted_ratio(H: np.ndarray, Js: np.ndarray, g: np.ndarray) -> float:
    """sqrt(g^T (H + Js^T Js)^-1 g / g^T H^-1 g) on column-scaled matrices (see the module docstring)."""
    scale = np.sqrt(np.diag(H))
    scale[scale == 0.0] = 1.0
    Hn = H / np.outer(scale, scale)
    Sn = (Js / scale).T @ (Js / scale)
    gn = g / scale
    now = float(gn @ np.linalg.pinv(Hn) @ gn)
    after = float(gn @ np.linalg.pinv(Hn + Sn) @ gn)
    return math.sqrt(max(after, 0.0) / now) if now > 0 else 1.0


def suggest(
    result: FitResult,
    intervals: Intervals,
    steps: Sequence[Step],
    current_max_a: float,
    counts_per_rev: int,
) -> list[Suggestion]:
    """The candidate steps ranked by the predicted width of the widest lab quantity's interval."""
    if result.jacobian is None:
        return []
    lab = [n for n in LAB if n in intervals.value]
    widest = max(lab, key=intervals.half_width)
    g = gradients(result, [widest], current_max_a)[0]
    H = result.jacobian.T @ result.jacobian
    now = intervals.half_width(widest)
    out = []
    for step in steps:
        Js = step_jacobian(result, candidate_record(result, step, counts_per_rev))
        out.append(Suggestion(step, widest, now, now * predicted_ratio(H, Js, g)))
    return sorted(out, key=lambda s: s.predicted)
