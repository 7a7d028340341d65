"""Free-oscillation metrics of a drop test: peaks, frequency, logarithmic decrement, settling.

Pure functions on sampled angle records (radians in, the unit named in each result out).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass

import numpy as np


@dataclass
class DropMetrics:
    """What a drop test is summarised by (one current)."""

    frequency_hz: float | None  # 1 / period_s
    period_s: float | None  # mean spacing of the first successive peaks and troughs (first two cycles)
    periods_s: list[float]  # every successive peak-to-peak interval (amplitude dependence)
    log_decrement: float | None  # mean ln(A_k / A_k+1) of successive positive peaks
    log_decrements: list[float]  # each ln(A_k / A_k+1)
    damping_ratio: float | None  # from the log decrement: d / sqrt(4 pi^2 + d^2)
    peaks_deg: list[float]  # successive positive peak amplitudes
    troughs_deg: list[float]  # successive negative peak magnitudes
    peak_times_s: list[float]
    settling_time_s: float | None  # time after which |theta| stays below the band
    settle_band_deg: float

    def as_dict(self) -> dict:
        return asdict(self)


def zero_crossings_up(time_s: np.ndarray, theta: np.ndarray, hysteresis_rad: float = 0.0) -> np.ndarray:
    """Times of upward zero crossings, linearly interpolated between samples.

    A crossing counts only after the signal has been below ``-hysteresis_rad`` since the last one,
    so encoder quantisation near rest does not produce false crossings.
    """
    times = []
    armed = False
    for index in range(1, len(theta)):
        if theta[index - 1] < -hysteresis_rad:
            armed = True
        if armed and theta[index - 1] < 0.0 <= theta[index]:
            t0, t1 = time_s[index - 1], time_s[index]
            x0, x1 = theta[index - 1], theta[index]
            times.append(t0 + (t1 - t0) * (-x0) / (x1 - x0))
            armed = False
    return np.asarray(times)


def _plateau_extremum(time_s: np.ndarray, values: np.ndarray) -> tuple[int, float]:
    """Index of the maximum and the mid-time of the plateau of samples equal to it (quantised peaks)."""
    j = int(np.argmax(values))
    top = np.nonzero(values == values[j])[0]
    return j, float(0.5 * (time_s[top[0]] + time_s[top[-1]]))


def half_cycle_extrema(time_s: np.ndarray, theta: np.ndarray, floor_rad: float) -> tuple[list, list]:
    """(positive peaks, negative troughs) as lists of (time, value): one per half cycle above ``floor_rad``."""
    peaks, troughs = [], []
    sign = np.sign(theta)
    start = 0
    for index in range(1, len(theta) + 1):
        if index == len(theta) or (sign[index] != sign[start] and sign[index] != 0):
            segment = theta[start:index]
            if segment.size:
                if sign[start] > 0:
                    j, t_peak = _plateau_extremum(time_s[start:index], segment)
                    if segment[j] > floor_rad and index < len(theta) and start + j > 0:
                        peaks.append((t_peak, float(segment[j])))
                elif sign[start] < 0:
                    j, t_peak = _plateau_extremum(time_s[start:index], -segment)
                    if -segment[j] > floor_rad and index < len(theta) and start + j > 0:
                        troughs.append((t_peak, float(segment[j])))
            start = index
    return peaks, troughs


def settling_time(time_s: np.ndarray, theta: np.ndarray, band_rad: float) -> float | None:
    """First time after which |theta| stays inside the band; None if it never does."""
    if len(theta) == 0:
        return None
    outside = np.nonzero(np.abs(theta) >= band_rad)[0]
    if outside.size == 0:
        return float(time_s[0])
    last = outside[-1]
    if last + 1 >= len(theta):
        return None
    return float(time_s[last + 1])


def drop_metrics(
    time_s: np.ndarray,
    theta_rad: np.ndarray,
    settle_band_deg: float = 0.25,
    resolution_rad: float = 0.0,
) -> DropMetrics:
    """Summarise a free oscillation that starts at release (``time_s[0]`` ~ 0).

    Peaks and crossings below ``max(4 * resolution, band / 2)`` are ignored as noise.
    """
    time_s = np.asarray(time_s, dtype=float)
    theta = np.asarray(theta_rad, dtype=float)
    band = math.radians(settle_band_deg)
    floor = max(4.0 * resolution_rad, 0.5 * band)
    peaks, troughs = half_cycle_extrema(time_s, theta, floor)
    # Period from the spacing of successive peaks and of successive troughs: with viscous and
    # Coulomb-like (hysteretic) damping each half cycle lasts half the damped period, while zero
    # crossings drift with the friction offset of the equilibrium.
    # The hysteretic torque stiffens the arm at small amplitude, so the period shortens as the
    # oscillation decays; the reported period is that of the first two cycles after release.
    peak_intervals = list(np.diff([t for t, _ in peaks]))
    trough_intervals = list(np.diff([t for t, _ in troughs]))
    first = peak_intervals[:2] + trough_intervals[:2]
    period = float(np.mean(first)) if first else None
    if period is None:
        ups = zero_crossings_up(time_s, theta, hysteresis_rad=floor)
        period = float(np.mean(np.diff(ups))) if ups.size >= 2 else None
    amplitudes = [value for _, value in peaks]
    decrements = [math.log(a / b) for a, b in itertools.pairwise(amplitudes)]
    decrement = float(np.mean(decrements)) if decrements else None
    ratio = None if decrement is None else decrement / math.sqrt(4 * math.pi**2 + decrement**2)
    return DropMetrics(
        frequency_hz=None if period is None else 1.0 / period,
        period_s=period,
        periods_s=[float(x) for x in peak_intervals],
        log_decrement=decrement,
        log_decrements=decrements,
        damping_ratio=ratio,
        peaks_deg=[math.degrees(a) for a in amplitudes],
        troughs_deg=[-math.degrees(v) for _, v in troughs],
        peak_times_s=[t for t, _ in peaks],
        settling_time_s=settling_time(time_s, theta, band),
        settle_band_deg=settle_band_deg,
    )
