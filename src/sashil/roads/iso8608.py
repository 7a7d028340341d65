"""ISO 8608 road profiles as road-wheel angles θ1(t), and a bump.

ISO 8608:2016 classifies roads by the displacement PSD of the road height over the spatial
frequency n [cycles/m]: Gd(n) = Gd(n0)·(n/n0)^(−w), n0 = 0.1 cycles/m, waviness w = 2, with the
classes' geometric means Gd(n0) = 16·4^k × 10⁻⁶ m³ for A (k = 0) to H (k = 7) (the standard's
Table 1), over 0.011 ≤ n ≤ 2.83 cycles/m. At a speed V the time-frequency PSD is G(f) = Gd(f/V)/V.

The profile is synthesised as a periodic sum of cosines with seeded random phases, one per
frequency bin f_k = k/T, of amplitude √(2·G(f_k)·Δf) (the spectral representation method), so its
one-sided PSD is G(f) exactly in every bin. The road height h maps to the road wheel's angle through
the rig's geometry (config ``road.lever_m``): θ1 = h / lever_m.
"""

from __future__ import annotations

import math

import numpy as np

from sashil.models.plant import RoadProfile

__all__ = ["CLASSES", "N0", "N_BAND", "bump_profile", "iso8608_height", "periodic_profile", "spatial_psd"]

#: the reference spatial frequency n0 [cycles/m]
N0 = 0.1
#: the standard's spatial band [cycles/m]
N_BAND = (0.011, 2.83)
#: Gd(n0) [m^3] of each class, the geometric mean of its range (ISO 8608 Table 1)
CLASSES: dict[str, float] = {name: 16e-6 * 4.0**k for k, name in enumerate("ABCDEFGH")}


def spatial_psd(road_class: str, n: np.ndarray | float) -> np.ndarray:
    """Gd(n) = Gd(n0)·(n/n0)^−2 [m^3] of an ISO 8608 class."""
    return CLASSES[road_class] * (np.asarray(n, dtype=float) / N0) ** -2.0


def iso8608_height(road_class: str, speed_m_s: float, period_s: float, rate_hz: float, seed: int) -> np.ndarray:
    """Road height h [m] sampled at ``rate_hz`` over one period of ``period_s`` (periodic, zero mean)."""
    n_samples = int(round(period_s * rate_hz))
    df = 1.0 / (n_samples / rate_hz)
    f = np.fft.rfftfreq(n_samples, 1.0 / rate_hz)
    n = f / speed_m_s
    inside = (n >= N_BAND[0]) & (n <= N_BAND[1])
    psd = np.zeros_like(f)
    psd[inside] = spatial_psd(road_class, n[inside]) / speed_m_s
    amplitude = np.sqrt(2.0 * psd * df)
    phase = np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi, f.size)
    spectrum = 0.5 * n_samples * amplitude * np.exp(1j * phase)
    return np.fft.irfft(spectrum, n_samples)


def periodic_profile(theta: np.ndarray, rate_hz: float, ramp_s: float) -> RoadProfile:
    """The road profile of a periodic angle record (θ1, with θ̇1 and θ̈1 by spectral derivatives),
    linearly interpolated between samples and faded in over ``ramp_s`` with a raised cosine."""
    n_samples = theta.size
    omega = 2.0 * math.pi * np.fft.rfftfreq(n_samples, 1.0 / rate_hz)
    spectrum = np.fft.rfft(theta)
    rate = np.fft.irfft(1j * omega * spectrum, n_samples)
    accel = np.fft.irfft(-(omega**2) * spectrum, n_samples)
    table = list(zip(theta.tolist(), rate.tolist(), accel.tolist(), strict=True))  # Python floats, read per cycle

    def road(time_s: float) -> tuple[float, float, float]:
        x = time_s * rate_hz
        i = math.floor(x)
        frac = x - i
        a = table[i % n_samples]
        b = table[(i + 1) % n_samples]
        th = a[0] + frac * (b[0] - a[0])
        th_dot = a[1] + frac * (b[1] - a[1])
        th_ddot = a[2] + frac * (b[2] - a[2])
        if time_s < ramp_s:  # raised-cosine fade-in: s(t) = (1 - cos(pi t/ramp))/2
            s = 0.5 - 0.5 * math.cos(math.pi * time_s / ramp_s)
            ds = 0.5 * math.pi / ramp_s * math.sin(math.pi * time_s / ramp_s)
            dds = 0.5 * (math.pi / ramp_s) ** 2 * math.cos(math.pi * time_s / ramp_s)
            return s * th, s * th_dot + ds * th, s * th_ddot + 2.0 * ds * th_dot + dds * th
        return th, th_dot, th_ddot

    return road


def bump_profile(height_rad: float, width_s: float, start_s: float) -> RoadProfile:
    """A raised-cosine bump: θ1 = h·(1 − cos(2π(t − t0)/w))/2 for t0 ≤ t ≤ t0 + w, else 0."""
    w = 2.0 * math.pi / width_s

    def road(time_s: float) -> tuple[float, float, float]:
        if not start_s <= time_s <= start_s + width_s:
            return 0.0, 0.0, 0.0
        phase = w * (time_s - start_s)
        return (
            0.5 * height_rad * (1.0 - math.cos(phase)),
            0.5 * height_rad * w * math.sin(phase),
            0.5 * height_rad * w * w * math.cos(phase),
        )

    return road
