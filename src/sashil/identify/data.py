"""Recorded runs as identification records, with the checks identification needs.

A record is what one ``data.csv`` (docs/architecture.md columns) tells about the rig: time, relative angle,
coil current, and when present the road-side angle and an input torque. Bad input is one line
naming the file and the problem (:class:`~sashil.errors.DataFileError`, exit 2).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.signal import savgol_filter

from sashil.errors import DataFileError
from sashil.identify.road import angle_acceleration, road_of_columns
from sashil.recording.data_file import read_data_csv

#: fewest samples and shortest duration a record may have to be fitted
MIN_SAMPLES = 200
MIN_DURATION_S = 0.5
#: magnitudes no rig record reaches (angles in rad, current in A, torque in N m): beyond them a
#: value is a corrupt file, whose derivatives would overflow
PLAUSIBLE = {"theta_rad": 1e3, "theta_road_rad": 1e3, "current_a": 1e3, "torque_in_nm": 1e6}
#: the sample periods a rig record can have [s] (20 kHz .. 10 Hz, with margin)
MIN_PERIOD_S = 1e-5
MAX_PERIOD_S = 0.5
#: a current spread below this (A) across all records cannot separate alpha1/alpha2, c1/c2
MIN_CURRENT_SPREAD_A = 0.05


@dataclass
class Record:
    """One run: time [s], theta [rad], current [A], road-side acceleration, input torque."""

    name: str
    time_s: np.ndarray
    theta: np.ndarray
    current: np.ndarray
    acc_road: np.ndarray
    torque_in: np.ndarray
    theta_dot: np.ndarray = field(repr=False)
    theta_ddot: np.ndarray = field(repr=False)
    theta_smooth: np.ndarray = field(repr=False)
    start_at_rest: bool = True  # drop tests start at standstill; else v0 from the first 20 ms
    z0_sign: float | None = None  # the hysteretic state's sign at the start, when known otherwise

    @property
    def v0(self) -> float:
        """Initial angular velocity: 0 at rest, else a quadratic fit over the first 20 ms."""
        if self.start_at_rest:
            return 0.0
        t = self.time_s - self.time_s[0]
        m = max(4, int(np.searchsorted(t, 0.02)))
        return float(np.polyfit(t[:m], self.theta[:m], 2)[1])

    @property
    def dt(self) -> float:
        return float(np.median(np.diff(self.time_s)))

    @property
    def mean_current(self) -> float:
        return float(np.mean(self.current))

    def initial_state_sign(self) -> float:
        """Sign of the hysteretic state at the start: a drop test was pressed towards theta0,
        so z0 = sign(theta0)*bound; a moving start follows its velocity; ``z0_sign`` overrides both
        (a record that starts at a turning point: the sign of the motion before it)."""
        if self.z0_sign is not None:
            return self.z0_sign
        v0 = self.v0
        if v0 != 0.0:
            return math.copysign(1.0, v0)
        return math.copysign(1.0, float(self.theta[0])) if self.theta[0] != 0.0 else 0.0


def dominant_period(time_s: np.ndarray, theta: np.ndarray) -> float:
    """Period [s] of the strongest non-zero frequency of a record (FFT of the mean-removed angle)."""
    dt = float(np.median(np.diff(time_s)))
    spec = np.abs(np.fft.rfft(theta - np.mean(theta)))
    spec[0] = 0.0
    f = np.fft.rfftfreq(theta.size, dt)
    peak = f[int(np.argmax(spec))]
    return 1.0 / peak if peak > 0.0 else time_s[-1] - time_s[0]


def smooth_derivatives(time_s: np.ndarray, theta: np.ndarray, window_s: float | None = None) -> tuple[np.ndarray, ...]:
    """Savitzky-Golay (cubic) smoothed angle, velocity and acceleration for the equation-error stage.

    The default window is 13 % of the record's dominant period, within [21, 101] ms: long enough to
    average the encoder quantisation out of the acceleration, short against the motion."""
    dt = float(np.median(np.diff(time_s)))
    if window_s is None:
        window_s = min(max(0.13 * dominant_period(time_s, theta), 0.021), 0.101)
    window = max(5, int(round(window_s / dt)) | 1)
    largest = theta.size if theta.size % 2 else theta.size - 1
    window = min(window, largest)
    smooth = savgol_filter(theta, window, 3, mode="interp")
    vel = savgol_filter(theta, window, 3, deriv=1, delta=dt, mode="interp")
    acc = savgol_filter(theta, window, 3, deriv=2, delta=dt, mode="interp")
    return smooth, vel, acc


def record_from_columns(
    name: str, columns: dict[str, np.ndarray], start_at_rest: bool = True, z0_sign: float | None = None
) -> Record:
    """Build a record from data.csv columns (checked by the caller). The road-side acceleration is
    the applied road's (:func:`sashil.identify.road.road_of_columns`) when the columns carry the
    road encoder's edges on ``time_s``'s clock (``road_edge_s``, ``road_edge_dir``, as calibrate's
    road runs do), else the smoothed ``theta_road_rad``'s."""
    t = np.asarray(columns["time_s"], dtype=float)
    theta = np.asarray(columns["theta_rad"], dtype=float)
    current = np.asarray(columns["current_a"], dtype=float)
    if "current_cmd_a" in columns and not np.all(np.isfinite(current)):
        # no current sense (a bench with none wired leaves current_a empty): the command stands in
        current = np.where(np.isfinite(current), current, np.asarray(columns["current_cmd_a"], dtype=float))
    torque_in = np.asarray(columns.get("torque_in_nm", np.zeros_like(t)), dtype=float)
    torque_in = np.where(np.isfinite(torque_in), torque_in, 0.0)
    applied = road_of_columns(columns)
    if applied is not None:  # the road the board applied, from its encoder's edges
        acc_road = angle_acceleration(t, applied)
    elif "theta_road_rad" in columns and np.any(columns["theta_road_rad"] != 0.0):
        road = np.where(np.isfinite(columns["theta_road_rad"]), columns["theta_road_rad"], 0.0)
        acc_road = smooth_derivatives(t, road)[2]
    else:
        acc_road = np.zeros_like(t)
    smooth, vel, acc = smooth_derivatives(t, theta)
    return Record(name, t, theta, current, acc_road, torque_in, vel, acc, smooth, start_at_rest, z0_sign)


def load_records(
    paths: Sequence[str | Path], need_current_change: bool = False, start_at_rest: bool = True
) -> list[Record]:
    """Read and check the runs to fit (one-line DataFileError naming the file on bad input)."""
    records = []
    for path in paths:
        columns = read_data_csv(path, required=("time_s", "theta_rad", "current_a"), min_rows=MIN_SAMPLES)
        for name in ("theta_road_rad", "torque_in_nm"):
            if name in columns and not np.all(np.isfinite(columns[name])):
                line = int(np.argmax(~np.isfinite(columns[name]))) + 2
                raise DataFileError(f"{path}: line {line}, column {name}: NaN or inf")
        for name, limit in PLAUSIBLE.items():
            if name in columns and np.any(np.abs(columns[name]) > limit):
                line = int(np.argmax(np.abs(columns[name]) > limit)) + 2
                value = float(columns[name][line - 2])
                raise DataFileError(
                    f"{path}: line {line}, column {name}: {value:g} is beyond ±{limit:g} (not a rig value)"
                )
        t = columns["time_s"]
        period = float(np.median(np.diff(t)))
        if not MIN_PERIOD_S <= period <= MAX_PERIOD_S:
            raise DataFileError(
                f"{path}: time_s advances {period:.3g} s per sample (median); expected a sample period "
                f"between {MIN_PERIOD_S:g} and {MAX_PERIOD_S:g} s (a rig record, time in seconds)"
            )
        if t[-1] - t[0] < MIN_DURATION_S:
            raise DataFileError(f"{path}: record too short ({t[-1] - t[0]:.3g} s; need at least {MIN_DURATION_S} s)")
        if np.ptp(columns["theta_rad"]) == 0.0:
            raise DataFileError(f"{path}: theta_rad never changes (the arm did not move; nothing to fit)")
        records.append(record_from_columns(str(path), columns, start_at_rest))
    if need_current_change:
        check_current_spread(records)
    return records


def angle_quantum(records: Sequence[Record]) -> float:
    """The encoder count of the records' angles [rad]: the smallest step between consecutive samples
    when every step is a whole number of it (encoder records), else 0 (angles that are not counts).
    Each record's first sample is left out: it may be an estimate between counts (a turning point's
    vertex, :func:`sashil.lab.calibration.analysis.from_turning_point`)."""
    steps = np.concatenate([np.abs(np.diff(r.theta[1:])) for r in records])
    moved = steps[steps > 0.0]
    if moved.size == 0:
        return 0.0
    quantum = float(moved.min())
    ratio = moved / quantum
    whole = np.abs(ratio - np.round(ratio)) <= 1e-3 * np.maximum(ratio, 1.0)
    return quantum if float(np.mean(whole)) >= 0.99 else 0.0


def check_current_spread(records: Sequence[Record]) -> None:
    """alpha2 and c2 need runs at different currents."""
    values = np.concatenate([r.current for r in records])
    spread = float(np.ptp(values))
    if spread < MIN_CURRENT_SPREAD_A:
        names = ", ".join(r.name for r in records)
        raise DataFileError(
            f"{names}: current_a never changes (spread {spread:.3g} A < {MIN_CURRENT_SPREAD_A} A), so the "
            "current-dependent parameters (alpha2, c2, ...) cannot be identified; add a run at another "
            "current or pass --passive"
        )
