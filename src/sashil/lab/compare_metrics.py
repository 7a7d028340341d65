"""What ``sashil compare`` measures of a law's run: comfort (the RMS of the arm's angular
acceleration θ̈2, low-passed), travel (the RMS of the relative angle θ), the peak current and the
coil's energy, after ``compare.settle_s``; and a law's result record.

θ̈2 is the plant's own on a simulated rig, (−k·θ − T)/J of its true state (seed 001 eq. 13); on
any other rig the arm encoder's angle θ2 = θ + θ1, a curve through its edges (each an exact angle at
its own time; through the samples' counts where the stream has no edges) on the samples' own device
time, differentiated twice, then low-passed, on a uniform grid of that time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from scipy.interpolate import CubicSpline

    from sashil.config.parts import RunSpec

__all__ = [
    "METRICS",
    "LawResult",
    "arm_acceleration",
    "arm_curve",
    "cycle_times",
    "metric_window",
    "metrics_of",
    "sample_times",
]


@dataclass
class LawResult:
    """A law's metrics (NaN when it did not finish), its status and what the plots show."""

    label: str
    status: str = "ok"
    metrics: dict[str, float] = field(default_factory=dict)
    wall_s: float = 0.0
    psd_f: list[float] = field(default_factory=list)
    psd: list[float] = field(default_factory=list)
    trace_t: list[float] = field(default_factory=list)
    trace: list[float] = field(default_factory=list)
    #: where θ̈2 came from: "plant" (a simulated rig's true state) or "encoders"
    accel_source: str = ""
    #: the runner's common summary keys of the law's run (timing, trips, controller_stats, ...)
    summary: dict[str, Any] = field(default_factory=dict)
    #: the host's longest pause in each run of the law [ms], the last the one kept
    #: (:mod:`sashil.lab.compare_pauses`); empty where the laws ran on the virtual clock
    pauses_ms: list[float] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


METRICS = (
    "rms_accel_rad_s2",
    "rms_theta_deg",
    "peak_current_a",
    "coil_energy_j",
)


def arm_acceleration(stream: dict[str, Any], rate_hz: float, bandwidth_hz: float) -> tuple[np.ndarray, str]:
    """θ̈2 [rad/s²] low-passed at ``bandwidth_hz``: the plant's own when the stream has it, else from
    the encoders (the second derivative of the arm angle's curve, :func:`arm_curve`, low-passed);
    and which it is.

    The encoders' θ2 is differentiated before the low-pass: inside the record the order makes no
    difference (both are linear and time-invariant), but at its ends the zero-phase filter extends
    its input by a point reflection, which keeps an angle's slope and flips its curvature (a step of
    2·θ̈2 at the end, read as a transient of up to twice the local θ̈2 over the filter's length),
    while it keeps an acceleration's value, as it does for the plant's own."""
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, min(bandwidth_hz, 0.45 * rate_hz), fs=rate_hz, output="sos")

    def smooth(x: np.ndarray) -> np.ndarray:
        return np.asarray(sosfiltfilt(sos, x)) if x.size > 30 else x

    true = np.asarray(stream.get("arm_accel_true_rad_s2", ()), dtype=float)
    if true.size and np.all(np.isfinite(true)):
        return smooth(true), "plant"
    theta2 = np.asarray(stream["theta_rad"], dtype=float) + np.asarray(stream["theta_road_rad"], dtype=float)
    dt = 1.0 / rate_hz
    # a link's samples are taken on the device's clock, with gaps where samples were lost and a
    # cycle that read no new sample repeating the last: θ̈2 on a uniform grid of the device's time,
    # read back at every row (without a device clock the rows are the samples, one period apart)
    sampled = sample_times(stream) or (np.arange(theta2.size) * dt, np.arange(theta2.size))
    times, first = sampled
    if times.size < 2:
        return np.zeros(theta2.size), "encoders"
    curve = arm_curve(stream, theta2, sampled)
    grid = np.arange(times[0], times[-1] + 0.5 * dt, dt)
    grid = grid[grid <= times[-1]]
    # beyond the curve's first and last point θ̈2 is held at its end value
    accel = smooth(np.asarray(curve(np.clip(grid, curve.x[0], curve.x[-1]), 2)))
    row_times = np.interp(np.arange(theta2.size), first, times)
    return np.asarray(np.interp(row_times, grid, accel)), "encoders"


def arm_curve(stream: dict[str, Any], theta2: np.ndarray, sampled: tuple[np.ndarray, np.ndarray]) -> CubicSpline:
    """The arm angle θ2 [rad] against the device's time [s] from the arm encoder, a cubic spline:
    through its edges when the stream has them, else through the samples' counts.

    The edges (``arm_edge_us``, ``arm_edge_dir``: each sample's last count change, ``drivers/protocol.md``,
    "Encoder edges") are the instants θ2 crossed a boundary between two counts: points of θ2 without
    quantisation (:func:`sashil.identify.road.edge_boundaries`), placed at their own times rather
    than the count at each sample's time (the edge-time reading of an incremental encoder: Merry,
    van de Molengraft and Steinbuch, 2010, "Velocity and acceleration estimation for optical
    incremental encoders", Mechatronics 20(1)). A count read at each sample is the angle plus an
    error of up to half a count; differentiated twice, that error's spectrum is raised by ω⁴ and
    fills the metric's band. The edges' spline leaves only the shape of θ2 between two edges, which
    it does not see (most at a reversal inside one count, and where edges lie further apart than the
    band's period: it reads RMS θ̈2 a little low there), and the edges' timing.

    Without edges (an older board, a recorder without the columns, an angle that is not a count)
    the spline runs through the samples' counts (``sampled``: their times and first rows,
    :func:`sample_times`), a lost sample's gap bridged smoothly."""
    from scipy.interpolate import CubicSpline

    from sashil.identify.road import edge_boundaries

    times, first = sampled
    q = encoder_count(stream, theta2)
    edges = None
    if q > 0.0 and {"arm_edge_us", "arm_edge_dir", "device_time_us"} <= stream.keys():
        edge_us = np.asarray(stream["arm_edge_us"], dtype=float)
        edges = edge_boundaries(
            np.where(edge_us >= 0.0, edge_us * 1e-6, np.nan),
            np.asarray(stream["arm_edge_dir"], dtype=float),
            np.rint(theta2 / q),
            np.asarray(stream["device_time_us"], dtype=float) * 1e-6,
        )
    if edges is None:
        return CubicSpline(times, theta2[first])
    t_edge, boundary = edges
    return CubicSpline(t_edge, boundary * q)


def encoder_count(stream: dict[str, Any], theta2: np.ndarray) -> float:
    """One count of the encoders [rad], from the recorded angles, 0 when they are not counts: the
    smaller of the relative angle's and the road angle's smallest step
    (:func:`sashil.identify.road.count_quantum`; each a whole number of counts, read exactly, while
    their sum θ2 carries the sum's rounding), if θ2 is a whole number of it."""
    from sashil.identify.road import count_quantum

    steps = [count_quantum(np.asarray(stream[key], dtype=float)) for key in ("theta_rad", "theta_road_rad")]
    q = min((step for step in steps if step > 0.0), default=0.0)
    if q <= 0.0 or not np.all(np.abs(theta2 / q - np.rint(theta2 / q)) < 1e-6):
        return 0.0
    return q


def sample_times(stream: dict[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """Each distinct sample's device time [s] (rising) and the row that first carried it, from the
    stream's ``seq`` and ``device_time_us``; None when the stream has no device clock (a simulated
    rig's rows are its samples, evenly spaced)."""
    device = np.asarray(stream.get("device_time_us", ()), dtype=float)
    seq = np.asarray(stream.get("seq", ()), dtype=float)
    if device.size < 3 or seq.size != device.size or not np.all(np.isfinite(device)) or not np.any(device):
        return None
    first = np.flatnonzero(np.r_[True, np.diff(seq) != 0])
    times = device[first] * 1e-6
    keep = np.r_[True, np.diff(times) > 0]  # a clock that did not advance adds nothing
    first, times = first[keep], times[keep]
    if times.size < 3:
        return None
    return times, first


def cycle_times(n: int, h: float) -> np.ndarray:
    """The times [s] of ``n`` cycles of period ``h`` from 0, as a run's stream records them (its
    ``time_s``: the cycle's start in whole nanoseconds, times 1e-9)."""
    return (np.arange(n) * int(round(h * 1e9))) * 1e-9


def metric_window(time_s: np.ndarray, settle_s: float) -> np.ndarray:
    """The cycles compare's metrics keep, as a boolean mask of their times ``time_s`` [s]: those at or
    after ``settle_s`` (``compare.settle_s``). The one window of the metrics and of the optimal
    bound's cost (:mod:`sashil.lab.hysteretic_bound`)."""
    return np.asarray(time_s, dtype=float) >= settle_s


def metrics_of(stream: dict[str, Any], run: RunSpec) -> tuple[dict[str, float], np.ndarray, np.ndarray, str]:
    """The metrics of a law's stream (module docstring), its time and θ̈2 after the settling, and
    where θ̈2 came from (``run``: the law's, its ``options`` the ``compare`` section's keys)."""
    rate = run.loop.rate_hz
    section = run.options
    time_s = np.asarray(stream["time_s"], dtype=float)[:-1]  # the last row is the shutdown's safe state
    accel, source = arm_acceleration(
        {k: np.asarray(v)[:-1] for k, v in stream.items()}, rate, float(section["accel_bandwidth_hz"])
    )
    keep = metric_window(time_s, float(section["settle_s"]))
    if not np.any(keep):
        raise ValueError("nothing recorded after compare.settle_s")
    theta = np.asarray(stream["theta_rad"], dtype=float)[:-1][keep]
    current = np.asarray(stream["current_a"], dtype=float)[:-1][keep]
    current = np.where(np.isfinite(current), current, 0.0)
    a = accel[keep]
    rms_a = float(np.sqrt(np.mean(a * a)))
    metrics = {
        "rms_accel_rad_s2": rms_a,
        "rms_theta_deg": math.degrees(float(np.sqrt(np.mean(theta * theta)))),
        "peak_current_a": float(np.max(current)),
        "coil_energy_j": float(section["coil_resistance_ohm"]) * float(np.sum(current * current)) / rate,
    }
    return metrics, time_s[keep], a, source
