"""Angle and angular-rate estimation from quantised encoder counts (model-aided tracking filters).

Each encoder angle y_k (radians, quantised to one count) feeds a critically damped tracking
filter with the measured period T of the cycle and the filter bandwidth f_b
(``rho = exp(-2*pi*f_b*T)``, the closed-loop poles of the tracking loop all sit at rho):

* **alpha-beta with a known acceleration** (the relative angle theta = theta2 - theta1 across the
  damper)::

      predict:  x_p = x + T*v + T^2/2*a_model,  v_p = v + T*a_model,  r = y_k - x_p
      correct:  x = x_p + g*r,  v = v_p + (h/T)*r,    g = 1 - rho^2,  h = (1 - rho)^2

  a_model is the arm's acceleration predicted by the rig model from the previous cycle
  (seed 001 eq. 13: J*theta_ddot = -k*theta - T_damper - J*theta1_ddot); this is the steady-state
  Kalman filter of a constant-velocity model with the model's acceleration as its input. Without
  the model (a_model = 0) the rate estimate is the rate of the samples low-passed by
  ``w^2 / (s^2 + 2 w s + w^2)``, w = 2*pi*f_b: a delay of 2/w (12.7 ms at 25 Hz); with it, only the
  part of the acceleration the model gets wrong (the plant mismatch, ~10 %) sees that delay.
* **alpha-beta-gamma** (the road-side angle theta1, whose acceleration nobody models)::

      g = 1 - rho^3,  h = 1.5*(1 - rho)^2*(1 + rho),  k = 0.5*(1 - rho)^3,  a = a + (2k/T^2)*r

  It tracks a constant acceleration without lag.

Lag and noise at 1 kHz (computed by :func:`rate_response`; quantisation 2*pi/4096 rad taken as
white noise of variance q^2/12):

==================  ===========================  ============================  ============
filter, f_b          rate delay at 1.6 Hz          rate delay / gain at 5 Hz     rate noise
==================  ===========================  ============================  ============
alpha-beta, 10 Hz    31.1 ms (no model)            29.0 ms / 0.80                0.0035 rad/s
alpha-beta, 25 Hz    12.2 ms (no model)            12.1 ms / 0.96                0.014 rad/s
a-b-gamma, 30 Hz     0.11 ms, gain 1.008           0.92 ms / 1.07                0.046 rad/s
==================  ===========================  ============================  ============

Defaults: relative and body channels alpha-beta at 10 Hz with the model acceleration, road channel
alpha-beta-gamma at 30 Hz. Measured on the simulated rig (tools/bench_control.py conditions, 4096
counts/rev, 10 % plant mismatch) the rate error is ~0.02 rad/s RMS; most of it comes from the road
channel's quantised acceleration feeding the relative channel, the rest from the model mismatch.

The rig needs the relative angle theta (damper), its rate, and the body (arm) rate
theta2_dot = theta_dot + theta1_dot when the road-side encoder moves (sweeps).
"""

from __future__ import annotations

import cmath
import math

import numpy as np

from sashil.drivers.interface import TWO_PI, RigSample


class TrackingFilter:
    """One angle channel: angle, rate (and with ``order=3`` acceleration) from quantised samples."""

    __slots__ = ("_dt", "_g", "_h", "_k", "a", "bandwidth_hz", "order", "started", "v", "x")

    def __init__(self, bandwidth_hz: float = 10.0, order: int = 2):
        if not bandwidth_hz > 0.0:
            raise ValueError(f"tracking-filter bandwidth must be > 0 Hz, got {bandwidth_hz!r}")
        if order not in (2, 3):
            raise ValueError(f"tracking-filter order must be 2 (alpha-beta) or 3 (alpha-beta-gamma), got {order!r}")
        self.bandwidth_hz = float(bandwidth_hz)
        self.order = order
        self.x = self.v = self.a = 0.0
        self._dt = -1.0
        self._g = self._h = self._k = 0.0
        self.started = False

    def reset(self, angle: float, rate: float = 0.0) -> None:
        self.x, self.v, self.a, self.started = float(angle), float(rate), 0.0, True

    def _gains(self, dt: float) -> None:
        rho = math.exp(-TWO_PI * self.bandwidth_hz * dt)
        if self.order == 2:
            self._g = 1.0 - rho * rho
            self._h = (1.0 - rho) ** 2 / dt
            self._k = 0.0
        else:
            self._g = 1.0 - rho**3
            self._h = 1.5 * (1.0 - rho) ** 2 * (1.0 + rho) / dt
            self._k = (1.0 - rho) ** 3 / (dt * dt)
        self._dt = dt

    def update(self, angle: float, dt: float, accel: float = 0.0) -> float:
        """Take one sample ``angle`` [rad] ``dt`` [s] after the previous one; returns the rate.

        ``accel`` is the known (modelled) acceleration over the period; order 3 adds its own
        estimate of the rest (the whole acceleration without a model, the model's error with one).
        """
        if not self.started:
            self.reset(angle)
            return 0.0
        if dt <= 0.0:
            return self.v
        if dt != self._dt:  # gains for this period (cached: the loop period rarely changes)
            self._gains(dt)
        if self.order == 3:
            accel += self.a  # the filter's own acceleration (or the model's error, when aided)
        predicted = self.x + dt * (self.v + 0.5 * dt * accel)
        residual = angle - predicted
        self.x = predicted + self._g * residual
        self.v += dt * accel + self._h * residual
        if self.order == 3:
            self.a += self._k * residual
        return self.v


def rate_response(bandwidth_hz: float, rate_hz: float, f_hz: float, order: int = 2) -> tuple[float, float, float]:
    """(gain, delay_s, noise) of the rate estimate without a model acceleration.

    Gain and delay for a sampled sinusoid at ``f_hz`` (ideal 1, 0): the filter's transfer function
    from y_k to v_k on the unit circle over the exact derivative at the sample instants. ``noise``:
    rate standard deviation [rad/s] for white angle noise of one 4096-count quantisation step.
    """
    dt = 1.0 / rate_hz
    flt = TrackingFilter(bandwidth_hz, order)
    flt._gains(dt)
    transition = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    gain = np.array([flt._g, flt._h, flt._k])
    if order == 2:
        transition[:, 2] = 0.0
    a = (np.eye(3) - np.outer(gain, [1.0, 0.0, 0.0])) @ transition
    w = TWO_PI * f_hz
    response = np.linalg.solve(np.eye(3) - a * cmath.exp(-1j * w * dt), gain)[1] / (1j * w)
    state, total = gain.copy(), 0.0
    for _ in range(20000):
        total += state[1] ** 2
        state = a @ state
    q = TWO_PI / 4096
    return abs(response), -cmath.phase(response) / w, math.sqrt(total) * q / math.sqrt(12.0)


class EstimatorOutputs:
    """What every rig estimator sets each cycle, for the controller and the recorder to read."""

    __slots__ = (
        "body_dot_rad_s",
        "road_ddot_rad_s2",
        "road_dot_rad_s",
        "theta_dot_rad_s",
        "theta_rad",
        "theta_road_rad",
    )

    def __init__(self) -> None:
        self.theta_rad = 0.0
        self.theta_dot_rad_s = 0.0
        self.theta_road_rad = 0.0
        self.road_dot_rad_s = 0.0
        self.road_ddot_rad_s2 = 0.0
        self.body_dot_rad_s = 0.0


class RigEstimator(EstimatorOutputs):
    """theta, theta_dot (relative, damper), theta1 rate/acceleration (road), theta2_dot (body).

    Three channels: the relative angle (arm minus road counts) and the body angle (arm counts)
    each through a model-aided alpha-beta filter, the road angle through an alpha-beta-gamma filter.
    ``update(sample, dt, body_accel)``: ``body_accel`` is the model's arm acceleration
    (-k*theta - T_hat)/J from the previous cycle (or 0); the relative channel gets
    ``body_accel - theta1_ddot``. The body rate comes from the arm encoder itself (not as the
    difference of two filtered rates), so it stays right when the body barely moves (above the
    resonance) while the road moves a lot.
    """

    __slots__ = ("body", "relative", "road")

    def __init__(
        self,
        bandwidth_hz: float = 10.0,
        road_bandwidth_hz: float = 30.0,
        body_bandwidth_hz: float | None = None,
        order: int = 2,
    ):
        self.relative = TrackingFilter(bandwidth_hz, order=order)
        self.road = TrackingFilter(road_bandwidth_hz, order=3)
        self.body = TrackingFilter(body_bandwidth_hz or bandwidth_hz, order=order)
        super().__init__()

    def update(self, sample: RigSample, dt: float, body_accel: float = 0.0, road_accel: float | None = None) -> None:
        """``road_accel`` (the commanded road acceleration) is not used: the road filter infers it."""
        scale = TWO_PI / sample.counts_per_rev
        road_counts = sample.road_counts
        road = self.road
        road.update(road_counts * scale, dt)
        self.theta_road_rad = road.x
        self.road_dot_rad_s = road.v
        self.road_ddot_rad_s2 = road.a
        rel = self.relative
        rel.update((sample.arm_counts - road_counts) * scale, dt, body_accel - road.a)
        self.theta_rad = rel.x
        self.theta_dot_rad_s = rel.v
        self.body_dot_rad_s = self.body.update(sample.arm_counts * scale, dt, body_accel)
