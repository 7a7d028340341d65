"""Road profiles of the sweeps: θ1(t) = A(t)·sin(φ(t)), a linear chirp or a sine, with their rate
and acceleration, A(t) rising over ``ramp_s`` with a raised cosine (and falling again from
``stop_s`` on).

* chirp: φ(t) = 2π(f0·t + (f1 − f0)·t²/(2T)), the instantaneous frequency f0 → f1 over T, then f1
  held;
* sine: φ(t) = 2π·f·t.

A profile carries the plain values it was made from (:class:`SweepRoad`), so a loop process builds
the same road again (:func:`road_of`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sashil.drivers.interface import TWO_PI
from sashil.models.plant import RoadProfile

__all__ = ["SweepRoad", "chirp_profile", "road_of", "sine_profile"]


def _envelope(t: float, ramp_s: float) -> tuple[float, float, float]:
    """Raised-cosine ramp e(t) from 0 to 1 over ramp_s, with e' and e''."""
    if ramp_s <= 0.0 or t >= ramp_s:
        return 1.0, 0.0, 0.0
    if t <= 0.0:
        return 0.0, 0.0, 0.0
    w = math.pi / ramp_s
    return 0.5 - 0.5 * math.cos(w * t), 0.5 * w * math.sin(w * t), 0.5 * w * w * math.cos(w * t)


def _profile(
    amplitude_rad: float,
    ramp_s: float,
    phase: Callable[[float], tuple[float, float, float]],
    stop_s: float | None = None,
) -> RoadProfile:
    """A(t)*sin(phi(t)) with A(t) = A*e(t): e ramps up over ``ramp_s`` and, from ``stop_s`` on,
    back down over ``ramp_s`` (the product rule gives the rate and acceleration)."""

    def road(t: float) -> tuple[float, float, float]:
        e, de, dde = _envelope(t, ramp_s)
        if stop_s is not None and t > stop_s:
            r, dr, ddr = _envelope(t - stop_s, ramp_s)
            e, de, dde = e * (1.0 - r), de * (1.0 - r) - e * dr, dde * (1.0 - r) - 2.0 * de * dr - e * ddr
        p, dp, ddp = phase(t)
        s, c = math.sin(p), math.cos(p)
        a = amplitude_rad
        return (a * e * s, a * (de * s + e * c * dp), a * (dde * s + 2.0 * de * c * dp + e * (c * ddp - s * dp * dp)))

    return road


@dataclass(frozen=True)
class SweepRoad:
    """A sweep's road profile and what it was made from (:func:`road_of` makes it again: a loop
    process builds the same road from the spec)."""

    spec: dict[str, Any]
    profile: RoadProfile

    def __call__(self, t: float) -> tuple[float, float, float]:
        return self.profile(t)


def road_of(spec: dict[str, Any]) -> SweepRoad:
    """The road of a :class:`SweepRoad`'s ``spec`` (``shape`` chirp or sine and its arguments)."""
    shapes: dict[str, Callable[..., SweepRoad]] = {"chirp": chirp_profile, "sine": sine_profile}
    arguments = {key: value for key, value in spec.items() if key != "shape"}
    return shapes[spec["shape"]](**arguments)


def chirp_profile(
    amplitude_rad: float, f_start_hz: float, f_stop_hz: float, duration_s: float, ramp_s: float = 1.0
) -> SweepRoad:
    """theta1(t) = A*sin(2*pi*(f0*t + (f1 - f0)*t^2/(2*T))), frequency held at f1 after T."""
    rate = (f_stop_hz - f_start_hz) / duration_s

    def phase(t: float) -> tuple[float, float, float]:
        if t <= duration_s:
            return TWO_PI * (f_start_hz * t + 0.5 * rate * t * t), TWO_PI * (f_start_hz + rate * t), TWO_PI * rate
        end = TWO_PI * (f_start_hz * duration_s + 0.5 * rate * duration_s**2)
        return end + TWO_PI * f_stop_hz * (t - duration_s), TWO_PI * f_stop_hz, 0.0

    spec = {"shape": "chirp", "amplitude_rad": amplitude_rad, "f_start_hz": f_start_hz, "f_stop_hz": f_stop_hz}
    return SweepRoad({**spec, "duration_s": duration_s, "ramp_s": ramp_s}, _profile(amplitude_rad, ramp_s, phase))


def sine_profile(amplitude_rad: float, f_hz: float, ramp_s: float = 1.0, stop_s: float | None = None) -> SweepRoad:
    """theta1(t) = A(t)*sin(2*pi*f*t); from ``stop_s`` on the amplitude ramps back to 0."""
    w = TWO_PI * f_hz
    spec = {"shape": "sine", "amplitude_rad": amplitude_rad, "f_hz": f_hz, "ramp_s": ramp_s, "stop_s": stop_s}
    return SweepRoad(spec, _profile(amplitude_rad, ramp_s, lambda t: (w * t, w, 0.0), stop_s))
