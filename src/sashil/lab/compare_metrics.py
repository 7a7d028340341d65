"""What ``sashil compare`` measures of a law's run: comfort (the RMS of the arm's angular
acceleration θ̈2, low-passed), travel (the RMS of the relative angle θ), the peak current and the
coil's energy, after ``compare.settle_s``; and a law's result record.

θ̈2 is the plant's own on a simulated rig, (−k·θ − T)/J of its true state (seed 001 eq. 13); on
any other rig the arm angle θ2 = θ + θ1 of the encoders, differentiated twice after the low-pass,
on a uniform grid of the samples' own device time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

__all__ = ["METRICS", "LawResult", "arm_acceleration", "metrics_of", "sample_times"]


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
    the encoders (θ2 = θ + θ1, low-passed, differentiated twice); and which it is."""
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, min(bandwidth_hz, 0.45 * rate_hz), fs=rate_hz, output="sos")

    def smooth(x: np.ndarray) -> np.ndarray:
        return np.asarray(sosfiltfilt(sos, x)) if x.size > 30 else x

    true = np.asarray(stream.get("arm_accel_true_rad_s2", ()), dtype=float)
    if true.size and np.all(np.isfinite(true)):
        return smooth(true), "plant"
    theta2 = np.asarray(stream["theta_rad"], dtype=float) + np.asarray(stream["theta_road_rad"], dtype=float)
    dt = 1.0 / rate_hz
    sampled = sample_times(stream)
    if sampled is None:
        return np.asarray(np.gradient(np.gradient(smooth(theta2), dt), dt)), "encoders"
    # a link's samples are taken on the device's clock, with gaps where samples were lost and a
    # cycle that read no new sample repeating the last: differentiate on a uniform grid of the
    # device's time, then read the result back at every row
    from scipy.interpolate import CubicSpline

    times, first = sampled
    grid = np.arange(times[0], times[-1] + 0.5 * dt, dt)
    grid = grid[grid <= times[-1]]
    on_grid = CubicSpline(times, theta2[first])(grid)  # a lost sample's gap bridged smoothly
    accel = np.gradient(np.gradient(smooth(on_grid), dt), dt)
    row_times = np.interp(np.arange(theta2.size), first, times)
    return np.asarray(np.interp(row_times, grid, accel)), "encoders"


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


def metrics_of(stream: dict[str, Any], run: RunSpec) -> tuple[dict[str, float], np.ndarray, np.ndarray, str]:
    """The metrics of a law's stream (module docstring), its time and θ̈2 after the settling, and
    where θ̈2 came from (``run``: the law's, its ``options`` the ``compare`` section's keys)."""
    rate = run.loop.rate_hz
    section = run.options
    time_s = np.asarray(stream["time_s"], dtype=float)[:-1]  # the last row is the shutdown's safe state
    accel, source = arm_acceleration(
        {k: np.asarray(v)[:-1] for k, v in stream.items()}, rate, float(section["accel_bandwidth_hz"])
    )
    keep = time_s >= float(section["settle_s"])
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
