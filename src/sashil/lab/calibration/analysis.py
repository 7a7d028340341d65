"""From the plan's records to a validated model: fit, held-out prediction, identifiability.

* The fit (:func:`sashil.identify.fit.fit_model`, output error of seed 000 eq. 10 on the rig model
  of seed 001 eqs. 13-17) sees only the ``fit`` steps; drop records are cut 0.5 s after the arm
  has come to rest (what follows carries no information and costs fit time); a record whose
  release was estimated from the data starts at its first turning point (:func:`from_turning_point`).
* Held-out validation: the fitted model is driven by each ``validate`` record's own inputs
  (initial angle, current, road motion) and its angle compared with the recorded one
  (NRMSE = RMS error / standard deviation of the recorded angle).
* Intervals: 95 % intervals of the lab's quantities and the raw parameters from a delete-one-block
  jackknife of the fit (:mod:`sashil.identify.intervals`); the Jacobian's
  1-sigma, which assumes white residuals, is kept beside them widened by the square root of the
  residuals' integrated autocorrelation time (in samples). For Bouc-Wen the
  exponent n is profiled: with n held at several values the rest is refitted (a short output-error
  refinement from the best fit) and the output error and held-out NRMSE reported for each, which
  shows how (un)determined n is and what that costs in prediction.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from sashil.errors import DataFileError
from sashil.identify.data import MIN_DURATION_S, Record, record_from_columns
from sashil.identify.fit import (
    FitOptions,
    FitResult,
    Problem,
    _inside,
    fit_model,
    initial_angle_tolerance,
    one_blas_thread,
    simulate_fitted,
)
from sashil.identify.intervals import Intervals, interval_blocks, jackknife
from sashil.identify.rig_models import MODELS
from sashil.identify.road import APPLIED_ROAD, road_of_columns, speed_steps_acceleration
from sashil.lab.calibration.rig import StepResult
from sashil.stats import nrmse

#: the arm is at rest once it stays within this many encoder counts of its final angle
REST_COUNTS = 2
#: kept after the arm came to rest [s]
REST_TAIL_S = 0.5
#: consecutive samples further apart than this are a link gap; a record is cut at its first one
#: (below the device watchdog's 50 ms nothing but samples is lost: the host skips to the newest
#: sample after a pause, and the commanded current and road speed hold)
GAP_S = 0.040
#: a record shorter than this (samples) after the cuts is left out
MIN_RECORD_SAMPLES = 300
#: values of n the profile refits at (geometric over the fit's bounds)
N_PROFILE = (0.1, 0.25, 0.6, 1.5)
#: output-error evaluations of each profile point's refinement (each costs a Jacobian)
PROFILE_NFEV = 8


def trimmed(columns: dict[str, np.ndarray], counts_per_rev: int) -> dict[str, np.ndarray]:
    """The record up to REST_TAIL_S after the arm last moved more than REST_COUNTS counts from its
    final angle (a drop at high current stops within a cycle; the rest is a flat line)."""
    theta, t = columns["theta_rad"], columns["time_s"]
    if theta.size == 0:
        return columns
    q = 2.0 * math.pi / counts_per_rev
    moving = np.nonzero(np.abs(theta - theta[-1]) > REST_COUNTS * q)[0]
    last = int(moving[-1]) if moving.size else 0
    end_t = max(t[last] + REST_TAIL_S, t[0] + MIN_DURATION_S + 0.1)
    keep = t <= end_t
    return {k: v[keep] for k, v in columns.items()}


def from_turning_point(
    columns: dict[str, np.ndarray], counts_per_rev: int
) -> tuple[dict[str, np.ndarray], float] | None:
    """The record from its first turning point after the release, and the sign of the motion before it.

    Where the release time is estimated from the data (a person, or the emulator, let go) it can be
    off by the ~10 ms the arm needs to move its first encoder count; an output-error fit reads that
    as damping. At a turning point the state is known without it: theta_dot = 0, theta the vertex
    of a parabola through the samples within 30 ms, and z at its bound with the sign of the motion
    that ended there (a swing of degrees saturates it). None when the arm does not turn and move on.
    """
    t, theta = columns["time_s"], columns["theta_rad"]
    q = 2.0 * math.pi / counts_per_rev
    if t.size < 50:
        return None
    dt = float(np.median(np.diff(t)))
    window = max(5, int(round(0.04 / dt)) | 1)
    smooth = savgol_filter(theta, window, 2, deriv=1, delta=dt, mode="interp")
    moved = np.nonzero(np.abs(theta - theta[0]) > 10 * q)[0]
    if moved.size == 0:
        return None
    start = int(moved[0])
    sign = math.copysign(1.0, float(smooth[start]))
    turns = np.nonzero(np.sign(smooth[start:]) == -sign)[0]
    if turns.size == 0:
        return None
    k = start + int(turns[0])
    near = np.abs(t - t[k]) <= 0.03
    a, b, _ = np.polyfit(t[near] - t[k], theta[near], 2)
    vertex_t = t[k] + (-b / (2 * a) if a != 0 else 0.0)
    first = int(np.argmin(np.abs(t - vertex_t)))
    rest = {name: v[first:].copy() for name, v in columns.items()}
    rest["theta_rad"][0] = float(np.polyval([a, b, _], vertex_t - t[k]))
    if rest["time_s"].size < 200 or np.ptp(rest["theta_rad"]) < 4 * q:
        return None
    return rest, sign


def until_gap(columns: dict[str, np.ndarray], gap_s: float = GAP_S) -> dict[str, np.ndarray]:
    """The record up to its first link gap (consecutive samples more than ``gap_s`` apart on the
    device's clock): in a gap the device's watchdog may have cut the current, which no sample shows,
    and the host commanded 0 A after ``driver.sample_timeout_ms``."""
    t = columns["time_s"]
    gaps = np.nonzero(np.diff(t) > gap_s)[0]
    if gaps.size == 0:
        return columns
    end = int(gaps[0]) + 1
    return {k: v[:end] for k, v in columns.items()}


def gap_cut(result: StepResult, counts_per_rev: int) -> float | None:
    """Where a link gap cuts the part of ``result``'s record the fit would use: the time of the last
    row kept [s from the release], or None when no gap falls inside it (see :func:`until_gap`)."""
    cols = trimmed(result.columns, counts_per_rev) if result.step.road is None else result.columns
    t = cols.get("time_s")
    if t is None or t.size == 0:
        return None
    kept = until_gap(cols)["time_s"]
    return None if kept.size == t.size else float(kept[-1])


def records_of(results: Sequence[StepResult], counts_per_rev: int) -> list[Record]:
    """Fit records of the steps: drops cut once at rest; a step whose release was estimated from
    the data (a link: the bench or the emulator) starts at its first turning point. A road run's
    forcing is the road the board applied (:func:`with_applied_road`), or where its record lacks the
    road encoder's edges the commanded speeds (:func:`road_acceleration`)."""
    out = []
    for r in results:
        cols = r.columns
        if r.step.road is not None:
            cols = with_applied_road(cols, counts_per_rev)
        cols = until_gap(trimmed(cols, counts_per_rev) if r.step.road is None else cols)
        if cols["time_s"].size < MIN_RECORD_SAMPLES:
            continue  # cut too short by a link gap: left out (the report lists it without NRMSE)
        z0_sign = None
        if r.release_estimated:
            turned = from_turning_point(cols, counts_per_rev)
            if turned is not None:
                cols, z0_sign = turned
        record = record_from_columns(r.step.name, cols, start_at_rest=True, z0_sign=z0_sign)
        if APPLIED_ROAD in cols:  # record_from_columns took the road's forcing from it
            pass
        elif "road_speed_cmd_rad_s" in cols:
            record = dataclasses.replace(
                record, acc_road=road_acceleration(cols["time_s"], cols["road_speed_cmd_rad_s"])
            )
        elif r.step.road is None:  # a drop: the wheel is held at rest, its encoder's noise is no forcing
            record = dataclasses.replace(record, acc_road=np.zeros_like(record.acc_road))
        out.append(record)
    return out


def with_applied_road(columns: dict[str, np.ndarray], counts_per_rev: int) -> dict[str, np.ndarray]:
    """``columns`` with the road angle the board applied at each sample (:data:`APPLIED_ROAD`, from
    the road encoder's edges on the device's clock: :func:`sashil.identify.road.road_of_columns`),
    when the record carries the edges and the encoder reported enough of them; else unchanged."""
    angle = road_of_columns(columns, 2.0 * math.pi / counts_per_rev)
    return columns if angle is None else {**columns, APPLIED_ROAD: angle}


def road_acceleration(time_s: np.ndarray, speed_cmd: np.ndarray) -> np.ndarray:
    """The road wheel's acceleration from the speeds commanded each cycle (a record without the
    road encoder's edges, as older run folders are): the wheel steps to the cycle's command
    at the cycle's sample (the emulator's wheel, a motor with a fast speed loop), so the speed
    changes by ``cmd[j] - cmd[j-1]`` at sample j (:func:`sashil.identify.road.speed_steps_acceleration`).
    Smoothing the recorded road angle instead (11 encoder counts for a 1 deg road) overstated the
    forcing by half at 3 Hz, and a fit to a 1 A road run could not follow it."""
    return speed_steps_acceleration(time_s, np.diff(speed_cmd, prepend=speed_cmd[:1]))


@dataclass
class Validation:
    name: str
    nrmse: float
    rms_rad: float
    time_s: np.ndarray
    measured: np.ndarray
    simulated: np.ndarray


@dataclass
class ProfilePoint:
    n: float
    rms_rad: float  # output error over the fit records with n held here, the rest refitted
    validation_nrmse: float  # mean held-out NRMSE of that model (nan without held-out runs)
    fitted: bool = False  # the fit's own n (the reference of the others)


@dataclass
class Calibration:
    """Everything the report needs."""

    results: list[FitResult]  # ranked, best first
    fit_records: list[Record]
    validate_records: list[Record]
    validations: list[Validation]
    inflation: float  # sqrt of the residuals' integrated autocorrelation time [samples]
    profile: list[ProfilePoint] = field(default_factory=list)
    fit_s: float = 0.0
    analysis_s: float = 0.0
    intervals: Intervals | None = None
    intervals_s: float = 0.0
    suggestions: list[Any] = field(default_factory=list)  # extra steps ranked (:mod:`.extra`)
    extra_note: str = ""  # why the extra steps' refit was not kept

    @property
    def best(self) -> FitResult:
        return self.results[0]

    @property
    def validation_nrmse(self) -> float:
        return float(np.mean([v.nrmse for v in self.validations])) if self.validations else math.nan


def validate(result: FitResult, records: Sequence[Record]) -> list[Validation]:
    model = MODELS[result.model]
    out = []
    for record in records:
        sim = model.simulate(result.params, record)
        rms = float(np.sqrt(np.mean((sim - record.theta) ** 2)))
        out.append(Validation(record.name, nrmse(sim, record.theta), rms, record.time_s, record.theta, sim))
    return out


def residual_inflation(result: FitResult, records: Sequence[Record], max_lag: int = 2000) -> float:
    """sqrt of the integrated autocorrelation time of the fit residuals (Sokal's window, c = 5):
    the factor by which white-noise standard errors understate the real ones."""
    taus = []
    for record, sim in zip(records, simulate_fitted(result, records), strict=True):
        e = sim - record.theta
        e = e - e.mean()
        var = float(np.dot(e, e))
        if var <= 0.0 or e.size < 8:
            continue
        size = 1 << int(math.ceil(math.log2(2 * e.size)))
        spectrum = np.fft.rfft(e, size)
        acf = np.fft.irfft(spectrum * np.conj(spectrum), size)[: min(max_lag, e.size)] / var
        tau = 1.0
        for lag in range(1, acf.size):
            tau += 2.0 * acf[lag]
            if lag >= 5.0 * tau:
                break
        taus.append(max(tau, 1.0))
    return float(math.sqrt(np.median(taus))) if taus else 1.0


def n_profile(
    result: FitResult,
    records: Sequence[Record],
    held_out: Sequence[Record],
    options: FitOptions,
    values: Sequence[float] = N_PROFILE,
) -> list[ProfilePoint]:
    """Bouc-Wen only: with n held at each value, every other parameter refitted on the output error
    (a short trust-region refinement from the best fit), then the fit's RMS and the held-out NRMSE
    of that model."""
    if result.model != "bouc-wen":
        return []
    problem = Problem(MODELS["bouc-wen"], records, options)
    lo, hi = problem.bounds()
    names = problem.free
    index = names.index("n")
    # the initial-angle offsets stay at the fit's: the profile is about the shape
    keep = [j for j in range(problem.model_size) if j != index]
    p = result.params
    coordinate = {"log10_S": math.log10(p["delta"]), "b": p["beta"] / p["delta"]}
    offsets = dict(zip(problem.offsets, result.initial_offsets_rad, strict=False))
    best = np.array([coordinate.get(name, offsets.get(name, p.get(name, 0.0))) for name in names])
    points = [ProfilePoint(float(best[index]), float(np.sqrt(np.mean(problem.residuals(best) ** 2))), math.nan, True)]
    if held_out:
        points[0].validation_nrmse = float(np.mean([v.nrmse for v in validate(result, held_out)]))
    # continuation: outwards from the best n on each side, each point starting from its neighbour's
    below = sorted((n for n in values if n < best[index]), reverse=True)
    above = sorted(n for n in values if n >= best[index])
    for side in (below, above):
        x = best.copy()
        for n in side:

            def residuals(v: np.ndarray, n: float = n, x: np.ndarray = x) -> np.ndarray:
                y = x.copy()
                y[keep] = v
                y[index] = n
                return problem.residuals(y)

            fit = least_squares(
                residuals, _inside(x, lo, hi)[keep], bounds=(lo[keep], hi[keep]), x_scale="jac", max_nfev=PROFILE_NFEV
            )
            x = x.copy()
            x[keep] = fit.x
            x[index] = n
            trial = dataclasses.replace(result, params=problem.params_of(x))
            held = float(np.mean([v.nrmse for v in validate(trial, held_out)])) if held_out else math.nan
            points.append(ProfilePoint(float(n), float(np.sqrt(np.mean(fit.fun**2))), held))
    return sorted(points, key=lambda point: point.n)


def analyse(
    fit_results: Sequence[StepResult],
    validate_results: Sequence[StepResult],
    model: str,
    inertia: float,
    counts_per_rev: int,
    progress: Callable[[str], None] | None = None,
    profile: bool = True,
    current_max_a: float = 1.0,
    block_s: float = 2.0,
) -> Calibration:
    """Fit ``model`` (or all four, ranked by output error) to the fit runs, validate on the others,
    and give 95 % intervals (jackknife blocks of ``block_s``; see :func:`interval_blocks`)."""
    say = progress or (lambda text: None)
    fit_records = records_of(fit_results, counts_per_rev)
    validate_records = records_of(validate_results, counts_per_rev)
    if len(fit_records) < 2:
        raise DataFileError(
            f"calibrate: only {len(fit_records)} of the {len(fit_results)} runs to fit are usable (link gaps cut "
            "the others short); repeat the calibration on a quieter link"
        )
    options = FitOptions(J=inertia, initial_angle_tolerance_rad=initial_angle_tolerance(fit_records))
    names = ["bouc-wen", "dahl", "lugre", "bingham"] if model == "all" else [model]
    started = time.perf_counter()
    results = []
    for name in names:
        say(f"fitting {name} to {len(fit_records)} runs ...")
        result = fit_model(name, fit_records, options)
        say(
            f"  {name}: RMS {math.degrees(result.rms_total):.4f} deg, {result.wall_s:.1f} s, "
            f"{result.convergence.get('message', '')}"
        )
        results.append(result)
    results.sort(key=lambda r: r.rms_total)
    fit_s = time.perf_counter() - started
    best = results[0]
    validations = validate(best, validate_records)
    cal = Calibration(results, fit_records, validate_records, validations, residual_inflation(best, fit_records))
    cal.fit_s = fit_s
    started_intervals = time.perf_counter()
    block = interval_blocks(fit_records, block_s, best.model_free)
    if block != block_s:
        say(f"interval blocks shortened to {block:.3g} s: the records are too short for {block_s:g} s blocks")
    cal.intervals = jackknife(best, fit_records, current_max_a, block)
    cal.intervals_s = time.perf_counter() - started_intervals
    if profile and best.model == "bouc-wen":
        say(f"profiling n at {', '.join(f'{v:g}' for v in N_PROFILE)} ...")
        with one_blas_thread():
            cal.profile = n_profile(best, fit_records, validate_records, options)
    cal.analysis_s = time.perf_counter() - started - fit_s
    return cal
