"""Semi-active laws: what the damper should do this cycle (a desired torque T*, or a current).

Sign convention (seed 001 eq. 13): the damper torque T acts on the arm as -T, on the road side as
+T, and dissipates power T*theta_dot. A law's T* is realisable only when T*·theta_dot > 0 and
inside the feasible band; the inverse (:mod:`sashil.control.inverse`) clips and counts the rest.

* ``passive``: a constant current, no inverse.
* ``target-damping``: T* = c_target*theta_dot, c_target given or from a damping ratio
  zeta = c_target / (2*sqrt(k*J)) of the model (the damper then acts as a linear damper).
* ``skyhook`` (continuous): T* = c_sky*theta2_dot, a damper to the "sky" on the body (arm).
* ``skyhook-onoff``: i_max when theta2_dot*theta_dot > 0, else 0 A (two-state Karnopp skyhook).
* ``skyhook-add``: the mixed skyhook / acceleration-driven-damper on-off law (Savaresi & Spelta
  2007): below the crossover frequency w_f (theta2_ddot^2 <= w_f^2*theta2_dot^2) on when
  theta2_dot*theta_dot > 0 (skyhook), above it on when theta2_ddot*theta_dot > 0 (ADD);
  theta2_ddot = (-k*theta - T_hat)/J from the model. It approximates the lower envelope of the
  soft and the hard passive damper at every frequency.
* ``groundhook``: T* = -c_ground*theta1_dot, a damper to the ground on the road/wheel side.
* ``torque-tracking``: follows a given T*(t), or a band-limited random fraction r(t) of the
  feasible band, T* = T(0) + r(t)*(T(i_max) - T(0)) (for testing the inverse).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import numpy as np


class CycleState(Protocol):
    """What a law reads from the controller each cycle."""

    time_s: float
    theta_rad: float
    theta_dot_rad_s: float
    body_dot_rad_s: float
    body_ddot_rad_s2: float
    road_dot_rad_s: float
    band_lo_nm: float
    band_hi_nm: float


class Law:
    """Base: ``direct`` laws return a current, the others a desired torque."""

    name = "law"
    direct = False

    def output(self, state: CycleState) -> float:
        raise NotImplementedError


class Passive(Law):
    name = "passive"
    direct = True

    def __init__(self, current_a: float):
        self.current_a = float(current_a)

    def output(self, state: CycleState) -> float:
        return self.current_a


class TargetDamping(Law):
    name = "target-damping"

    def __init__(self, c_target: float):
        self.c_target = float(c_target)

    def output(self, state: CycleState) -> float:
        return self.c_target * state.theta_dot_rad_s


class Skyhook(Law):
    name = "skyhook"

    def __init__(self, c_sky: float):
        self.c_sky = float(c_sky)

    def output(self, state: CycleState) -> float:
        return self.c_sky * state.body_dot_rad_s


class SkyhookOnOff(Law):
    name = "skyhook-onoff"
    direct = True

    def __init__(self, current_on_a: float, current_off_a: float = 0.0):
        self.on, self.off = float(current_on_a), float(current_off_a)

    def output(self, state: CycleState) -> float:
        return self.on if state.body_dot_rad_s * state.theta_dot_rad_s > 0.0 else self.off


class SkyhookAdd(Law):
    name = "skyhook-add"
    direct = True

    def __init__(self, crossover_rad_s: float, current_on_a: float, current_off_a: float = 0.0):
        self.w2 = float(crossover_rad_s) ** 2
        self.on, self.off = float(current_on_a), float(current_off_a)

    def output(self, state: CycleState) -> float:
        vb, ab, v = state.body_dot_rad_s, state.body_ddot_rad_s2, state.theta_dot_rad_s
        if ab * ab <= self.w2 * vb * vb:
            return self.on if vb * v > 0.0 else self.off
        return self.on if ab * v > 0.0 else self.off


class Groundhook(Law):
    name = "groundhook"

    def __init__(self, c_ground: float):
        self.c_ground = float(c_ground)

    def output(self, state: CycleState) -> float:
        return -self.c_ground * state.road_dot_rad_s


def band_limited_fraction(
    bandwidth_hz: float, low: float, high: float, seed: int = 0, rate_hz: float = 1000.0, duration_s: float = 60.0
) -> np.ndarray:
    """A seeded random signal in [low, high], low-passed to ``bandwidth_hz`` (periodic table).

    White Gaussian noise through a periodic (FFT) brick-wall low-pass, then scaled so that its
    extremes are ``low`` and ``high``.
    """
    n = int(round(duration_s * rate_hz))
    rng = np.random.default_rng(seed)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    freqs = np.fft.rfftfreq(n, 1.0 / rate_hz)
    spectrum[freqs > bandwidth_hz] = 0.0
    spectrum[0] = 0.0
    signal = np.fft.irfft(spectrum, n)
    signal = (signal - signal.min()) / (signal.max() - signal.min())
    return low + (high - low) * signal


class TorqueTracking(Law):
    """T*(t) from a callable, or a band-limited random fraction of the feasible band."""

    name = "torque-tracking"

    def __init__(
        self,
        torque: Callable[[float], float] | None = None,
        fraction: np.ndarray | None = None,
        rate_hz: float = 1000.0,
    ):
        if (torque is None) == (fraction is None):
            raise ValueError("torque-tracking needs exactly one of a torque signal T*(t) or a band fraction table")
        self.torque = torque
        self.fraction = None if fraction is None else [float(x) for x in fraction]
        self.rate_hz = float(rate_hz)

    def output(self, state: CycleState) -> float:
        if self.torque is not None:
            return self.torque(state.time_s)
        table = self.fraction
        assert table is not None  # __init__ sets exactly one of torque, fraction
        r = table[int(state.time_s * self.rate_hz) % len(table)]
        return state.band_lo_nm + r * (state.band_hi_nm - state.band_lo_nm)


def damping_for_ratio(zeta: float, k: float, J: float) -> float:
    """c = 2*zeta*sqrt(k*J): the linear damping of damping ratio ``zeta`` for the arm on its spring."""
    return 2.0 * zeta * math.sqrt(k * J)
