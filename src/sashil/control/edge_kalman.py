"""The rig-model Kalman filter's cycle with encoder edge events (``controller.edge_timing``).

The state and the model are those of :mod:`sashil.control.kalman` (x = [theta, theta_dot, theta1,
theta1_dot, theta1_ddot, b], seed 001 eq. 13 for the arm's modelled acceleration u). What changes
is what a sample tells: besides the counts, each encoder's last count change (protocol.md "Encoder
edges"). At its time t_e the encoder's angle was exactly on the boundary it crossed, (n - dir/2) q.
Such an event is older than the sample (tau = t_k - t_e >= 0): it is fused as a measurement of the
state at t_k through the model's transition over -tau,

    theta2(t_k - tau) = theta2 - tau theta2_dot + tau^2/2 (u + b)          (arm: theta2 = theta + theta1)
    theta1(t_k - tau) = theta1 - tau theta1_dot + tau^2/2 (theta1_ddot + a_cmd)       (road)

whose rows are exact for the model (its acceleration is constant over a period), with a variance of
the timing error times the rate squared plus the process noise over tau (accel_psd tau^3 / 3). The
gains follow from the covariance P, propagated each period (P = F P F^T + Q, Q scaled to the
measured period) and updated one scalar measurement at a time: the events come at any time, so no
steady-state gain fits them.

The counts are read as the angle plus white noise, as without events, but for an encoder that had
events with a variance far above the quantisation's q^2/12 (``kalman.EDGE_COUNT_SIGMA_COUNTS``): the
events say where in its cell the angle is, and a count read at q^2/12 every cycle would pull the
estimate towards the middle of the cell, by up to half a count, against them. An estimate that
leaves the count's cell all the same (the model drifting while no event comes: an arm stuck by the
damper's yield, where the model's acceleration is off and the arm moves by less than a count) is put
back to the cell's edge at q^2/12. Measured over the benchmark's eleven dampers (exact model, six
conditions): the cell alone (no correction inside it) let the estimate drift across it (a drop on
one damper: 34 % tracking error against 25 % without events); the count at q^2/12 cost the sines (1 Hz
up to 12.6 %); the weak count alone, with an identified model, let a stuck arm's estimate drift by 13
counts (a false fallback to 0 A); weak count and cell together: every condition below 8 % with the
exact model. An encoder that does not move has no new event: its count (the old information) is all
the filter gets from it; one that never moved is read at q^2/12, as without events.

:func:`edge_cycle` is one cycle (predict, the events, the counts) compiled with numba.
"""

from __future__ import annotations

import numpy as np

from sashil.models._jit import jit, loop_kernel

#: a measurement's variance never goes below this share of a count squared (keeps P positive)
VARIANCE_FLOOR_COUNTS2 = 1e-6


def _state() -> tuple[np.ndarray, np.ndarray]:
    """A state vector and a covariance of the types a cycle passes (float64, C order)."""
    return np.zeros(6), np.eye(6)


@loop_kernel(lambda: (*_state(), np.ones(6), 0.0, 1.0, np.zeros(6)))
@jit
def _scalar_update(
    x: np.ndarray, p: np.ndarray, h: np.ndarray, innovation: float, variance: float, ph: np.ndarray
) -> None:
    """x += K e, P -= K h P with K = P h / (h P h + r): one scalar measurement (``ph``: room for P h,
    the caller's, so a cycle's updates share one)."""
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += p[i, j] * h[j]
        ph[i] = acc
    s = variance
    for i in range(6):
        s += h[i] * ph[i]
    for i in range(6):
        x[i] += ph[i] * innovation / s
    for i in range(6):
        for j in range(6):
            p[i, j] -= ph[i] * ph[j] / s


@loop_kernel(lambda: (0.0, 1.0))
@jit
def _cell(innovation: float, zone: float) -> float:
    """The distance from the prediction to the count's cell of half-width ``zone`` (0 inside it)."""
    if innovation > zone:
        return innovation - zone
    if innovation < -zone:
        return innovation + zone
    return 0.0


@loop_kernel(
    lambda: (*_state(), np.eye(6), 1.0, 1e-3, 0.0, 0.0, 0.0, 0.0, 1e-4, 0.0, 1e-4, 0.0, 1e-7, 1e-7, 1e-3, 1e-11, 1e-4)
)
@jit
def edge_cycle(
    x: np.ndarray,
    p: np.ndarray,
    q: np.ndarray,
    q_scale: float,
    dt: float,
    body_accel: float,
    road_accel: float,
    arm: float,
    road: float,
    arm_tau: float,
    arm_boundary: float,
    road_tau: float,
    road_boundary: float,
    arm_var: float,
    road_var: float,
    half_count: float,
    time_var: float,
    accel_psd: float,
) -> float:
    """One cycle of the filter on ``x``/``p`` (in place); returns the prediction's largest miss [rad]
    (of a count's cell, or of an event's boundary), for the innovation check.

    ``q``: the process noise of the nominal period, times ``q_scale`` for this one; ``body_accel``:
    the model's arm acceleration u; ``road_accel``: the commanded road acceleration (0: none);
    ``arm``/``road``: the counts' angles; ``*_tau``: the age of a new edge event [s] (< 0: none) and
    ``*_boundary`` the angle it crossed; ``*_var``: the variance a count is read with (q^2/12 for an
    encoder that never had an event, much more for one that had); ``half_count``: q/2 [rad] (the
    innovation check measures a miss from the count's cell); ``time_var``: the variance of an event's time [s^2].
    """
    theta, v, r, rv, ra, b = x[0], x[1], x[2], x[3], x[4], x[5]
    ra_eff = ra + road_accel
    accel = body_accel + b - ra_eff
    half = 0.5 * dt * dt
    x[0] = theta + dt * v + half * accel
    x[1] = v + dt * accel
    x[2] = r + dt * rv + half * ra_eff
    x[3] = rv + dt * ra_eff
    f = np.eye(6)
    f[0, 1] = dt
    f[0, 4] = -half
    f[0, 5] = half
    f[1, 4] = -dt
    f[1, 5] = dt
    f[2, 3] = dt
    f[2, 4] = half
    f[3, 4] = dt
    fpf = (f @ p) @ f.T
    for i in range(6):
        for j in range(6):
            p[i, j] = fpf[i, j] + q_scale * q[i, j]
    floor = VARIANCE_FLOOR_COUNTS2 * 4.0 * half_count * half_count
    # the innovation check sees the prediction's miss of each count's cell and of each event's
    # boundary, before any measurement of this cycle moves it
    worst = max(abs(_cell(arm - (x[0] + x[2]), half_count)), abs(_cell(road - x[2], half_count)))
    h = np.zeros(6)
    ph = np.empty(6)
    if arm_tau >= 0.0:
        tau = arm_tau
        h[0], h[1], h[2], h[3], h[4], h[5] = 1.0, -tau, 1.0, -tau, 0.0, 0.5 * tau * tau
        rate = x[1] + x[3]
        predicted = x[0] + x[2] - tau * rate + 0.5 * tau * tau * (body_accel + x[5])
        variance = time_var * rate * rate + accel_psd * tau * tau * tau / 3.0 + floor
        worst = max(worst, abs(arm_boundary - predicted))
        _scalar_update(x, p, h, arm_boundary - predicted, variance, ph)
    if road_tau >= 0.0:
        tau = road_tau
        h[0], h[1], h[2], h[3], h[4], h[5] = 0.0, 0.0, 1.0, -tau, 0.5 * tau * tau, 0.0
        rate = x[3]
        predicted = x[2] - tau * rate + 0.5 * tau * tau * (x[4] + road_accel)
        variance = time_var * rate * rate + floor
        worst = max(worst, abs(road_boundary - predicted))
        _scalar_update(x, p, h, road_boundary - predicted, variance, ph)
    cell_var = 4.0 * half_count * half_count / 12.0
    h[0], h[1], h[2], h[3], h[4], h[5] = 1.0, 0.0, 1.0, 0.0, 0.0, 0.0
    _scalar_update(x, p, h, arm - (x[0] + x[2]), arm_var, ph)
    e_cell = _cell(arm - (x[0] + x[2]), half_count)
    if e_cell != 0.0:  # outside the count's cell: back to its edge, at the quantisation's variance
        _scalar_update(x, p, h, e_cell, cell_var, ph)
    h[0], h[1], h[2], h[3], h[4], h[5] = 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
    _scalar_update(x, p, h, road - x[2], road_var, ph)
    e_cell = _cell(road - x[2], half_count)
    if e_cell != 0.0:
        _scalar_update(x, p, h, e_cell, cell_var, ph)
    for i in range(6):  # keep P symmetric against rounding
        for j in range(i + 1, 6):
            mean = 0.5 * (p[i, j] + p[j, i])
            p[i, j] = mean
            p[j, i] = mean
    return worst
