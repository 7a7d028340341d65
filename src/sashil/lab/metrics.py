"""Free-oscillation metrics of a drop test: peaks, frequency, logarithmic decrement, settling.

Pure functions on sampled angle records (radians in, the unit named in each result out).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass

import numpy as np

#: the log decrement uses only peaks at least this many encoder counts high (each read to ±1/16 or better)
DAMPING_MIN_COUNTS = 8
#: cycles after the release the log decrement spans (as the period, the first two cycles): every record that
#: holds them gives the same damping ratio, whatever its length
DAMPING_CYCLES = 2


@dataclass
class DropMetrics:
    """What a drop test is summarised by (one current)."""

    frequency_hz: float | None  # 1 / period_s
    period_s: float | None  # mean spacing of the first successive peaks and troughs (first two cycles)
    periods_s: list[float]  # every successive peak-to-peak interval (amplitude dependence)
    log_decrement: float | None  # ln(A_0 / A_K) / K over the first K cycles' peaks >= DAMPING_MIN_COUNTS
    log_decrements: list[float]  # each ln(A_k / A_k+1) of successive positive peaks
    damping_ratio: float | None  # from the log decrement: d / sqrt(4 pi^2 + d^2)
    damping_ratio_interval: list[float] | None  # [low, high]: what the encoder's ±1/2 count on A_0, A_K allows
    damping_cycles: int  # K, the cycles the log decrement spans (0: no damping ratio)
    damping_note: str | None  # why the damping ratio is missing or spans fewer than DAMPING_CYCLES cycles
    damping_record_short: bool  # the record ends within the cycles the damping ratio spans
    peaks_deg: list[float]  # successive positive peak amplitudes
    troughs_deg: list[float]  # successive negative peak magnitudes
    peak_times_s: list[float]
    settling_time_s: float | None  # time after which |theta| stays below the band
    settle_band_deg: float
    peaks_note: str | None = None  # why no peak was found (None when there are peaks)

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class Decrement:
    """The log decrement over the first cycles of a free decay, with the interval quantisation allows."""

    value: float | None
    low: float | None
    high: float | None
    cycles: int
    note: str | None
    record_short: bool = False  # the record ended before the K cycles: a longer one may give another value


def damping_ratio_of(decrement: float) -> float:
    """Damping ratio of a logarithmic decrement per cycle: d / sqrt(4 pi^2 + d^2)."""
    return decrement / math.sqrt(4 * math.pi**2 + decrement**2)


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


def _peak_count_text(count: int) -> str:
    return {0: "no peak", 1: "one peak"}.get(count, f"{count} peaks")


def log_decrement_of(
    peaks: list[tuple[float, float]],
    resolution_rad: float,
    record_end_s: float,
    period_s: float | None,
    cycles: int = DAMPING_CYCLES,
    min_counts: int = DAMPING_MIN_COUNTS,
) -> Decrement:
    """Log decrement ``ln(A_0 / A_K) / K`` over the positive peaks of the first K = ``cycles`` cycles.

    The hysteretic torque α(i)·z of seed 001 eq. 9 saturates (|z| → (δ/(β+γ))^(1/n)), so it takes a nearly
    constant amplitude per cycle, as Coulomb friction does: the decrement ln(A_k / A_k+1) grows as the
    oscillation decays, and a mean over every peak of a record would depend on how long the record is. Over
    a fixed number of cycles from the release it does not. Peaks lower than ``min_counts`` encoder counts
    are left out (±1/2 count would be more than 1/16 of them). ``low``/``high`` are the decrements that
    ±1/2 count on A_0 and A_K allow (the encoder rounds the angle).
    """
    floor = min_counts * resolution_rad
    used: list[tuple[float, float]] = []
    for peak in peaks:
        if peak[1] < floor or len(used) > cycles:
            break
        used.append(peak)
    k = len(used) - 1
    note, short = None, False
    if k < cycles:
        note, short = _short_decrement_note(peaks, used, record_end_s, period_s, cycles, min_counts, floor)
    if k < 1:
        return Decrement(None, None, None, 0, note, short)
    first, last = used[0][1], used[-1][1]
    half = 0.5 * resolution_rad
    return Decrement(
        value=math.log(first / last) / k,
        low=math.log((first - half) / (last + half)) / k,
        high=math.log((first + half) / (last - half)) / k,
        cycles=k,
        note=note,
        record_short=short,
    )


def _short_decrement_note(
    peaks: list[tuple[float, float]],
    used: list[tuple[float, float]],
    record_end_s: float,
    period_s: float | None,
    cycles: int,
    min_counts: int,
    floor_rad: float,
) -> tuple[str | None, bool]:
    """Why the log decrement spans fewer than ``cycles`` cycles, and whether the record ended first
    (rather than the swing decaying below the peaks it counts)."""
    if not peaks:
        return None, False  # no peaks at all: peaks_note says why
    high = f"at least {min_counts} encoder counts ({math.degrees(floor_rad):.2f} deg) high"
    spans = "no damping ratio" if len(used) < 2 else f"the damping ratio spans {len(used) - 1} of {cycles} cycles"
    if len(peaks) == len(used) and used:
        # the next peak would come about one period later, and count once its half cycle ends (a quarter more);
        # without a period, the first peak (half a period after a release from below 0) gives one
        period = period_s if period_s is not None else 2.0 * used[0][0]
        if record_end_s < used[-1][0] + 1.25 * period:
            wanted = used[0][0] + (cycles + 0.25) * period
            return (
                f"{spans}: the record ends {record_end_s:g} s after the release, before the next peak; record at "
                f"least {wanted:.1f} s for a damping ratio that does not depend on the record length"
            ), True
    count = _peak_count_text(len(used))
    later = "no later one is" if len(peaks) == len(used) else "the later ones are lower"
    return f"{spans}: {count} {'is' if len(used) == 1 else 'are'} {high}, {later}", False


def no_peaks_reason(time_s: np.ndarray, theta: np.ndarray, floor_rad: float) -> str:
    """Why a free oscillation has no positive peak above ``floor_rad`` (for a warning that says so)."""
    if theta.size == 0:
        return "nothing was recorded after the release"
    first_negative = np.nonzero(theta <= 0.0)[0]
    after = theta[first_negative[0] :] if first_negative.size else theta[:0]
    if after.size == 0 or float(np.max(after)) <= floor_rad:
        return (
            f"the arm did not swing past +{math.degrees(floor_rad):.2f} deg after the release (smaller peaks are "
            f"not counted): it is overdamped at this current, or released too close to 0"
        )
    return (
        f"the record ends {float(time_s[-1]):g} s after the release, before the first swing above 0 is over "
        f"(a peak counts once the arm is back below 0): record longer"
    )


def drop_metrics(
    time_s: np.ndarray,
    theta_rad: np.ndarray,
    settle_band_deg: float = 0.25,
    resolution_rad: float = 0.0,
) -> DropMetrics:
    """Summarise a free oscillation that starts at release (``time_s[0]`` ~ 0).

    Peaks and crossings below ``max(4 * resolution, band / 2)`` are ignored as noise. The damping ratio
    comes from the log decrement over the first :data:`DAMPING_CYCLES` cycles (:func:`log_decrement_of`).
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
    end_s = float(time_s[-1]) if time_s.size else 0.0
    fit = log_decrement_of(peaks, resolution_rad, end_s, period)
    peaks_note = None if peaks else no_peaks_reason(time_s, theta, floor)
    return DropMetrics(
        frequency_hz=None if period is None else 1.0 / period,
        period_s=period,
        periods_s=[float(x) for x in peak_intervals],
        log_decrement=fit.value,
        log_decrements=decrements,
        damping_ratio=None if fit.value is None else damping_ratio_of(fit.value),
        damping_ratio_interval=None
        if fit.low is None or fit.high is None
        else [damping_ratio_of(fit.low), damping_ratio_of(fit.high)],
        damping_cycles=fit.cycles,
        damping_note=fit.note,
        damping_record_short=fit.record_short,
        peaks_deg=[math.degrees(a) for a in amplitudes],
        troughs_deg=[-math.degrees(v) for _, v in troughs],
        peak_times_s=[t for t, _ in peaks],
        settling_time_s=settling_time(time_s, theta, band),
        settle_band_deg=settle_band_deg,
        peaks_note=peaks_note,
    )


def settling_text(metrics: DropMetrics, record_s: float) -> str:
    """The settling time as a sentence: when the arm stays inside the band, or that it never does."""
    band = f"±{metrics.settle_band_deg:g} deg"
    settle = metrics.settling_time_s
    if settle is None:
        return f"still outside {band} at the end of the record ({record_s:g} s)"
    if settle <= 0.0:
        return f"inside {band} from the release on"
    return f"stays inside {band} from {settle:.3f} s after the release"


def damping_text(metrics: DropMetrics) -> str:
    """The damping ratio with its interval and the cycles it spans, or '-' when there is none."""
    ratio, interval = metrics.damping_ratio, metrics.damping_ratio_interval
    if ratio is None:
        return "ζ -"
    cycles = "first cycle" if metrics.damping_cycles == 1 else f"first {metrics.damping_cycles} cycles"
    spread = "" if interval is None else f" [{interval[0]:.4f}, {interval[1]:.4f}]"
    return f"ζ {ratio:.4f}{spread} ({cycles})"
