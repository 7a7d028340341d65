"""Compiled (numba) simulators used inside the identification loops.

Every kernel is the compiled form of a law documented in :mod:`sashil.models`; the scalar laws of
Dahl and LuGre are compiled straight from their pure-Python definitions. ``cache=True`` keeps the
JIT cost to the first run on a machine.

Bouc-Wen runs the simulated rig's own sub-step (:func:`sashil.models.plant.rig_substep`, trapezoidal
rule). The other rig models share one integrator (seed 001 eqs. 13-17): per sub-step
h <= ``max_step`` a semi-implicit Euler step of
``J*theta_ddot = -k*theta - T_damper + T_in - J*theta1_ddot`` with the viscous part implicit, the
hysteretic state taken at the mean of its start and a predicted end, and the state advanced over
the angle increment (rate-independent laws). Model codes and parameter layouts (registry order):

    0 bouc-wen: J, k, c1, c2, alpha1, alpha2, beta, gamma, delta, n
    1 dahl:     J, k, c1, c2, kwa, kwb, rho
    2 lugre:    J, k, sigma_a, sigma_b, sigma0, sigma1, sigma2, a0
    3 bingham:  J, k, c0, c0_i, fc, fc_i, f0
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from sashil.models.bingham import bingham_velocity_step as _bingham_step_py
from sashil.models.dahl import dahl_w_advance as _dahl_py
from sashil.models.hysteresis import advance_z as bw_advance  # compiled in sashil.models (one law)
from sashil.models.lugre import lugre_z_advance as _lugre_py
from sashil.models.plant import rig_substep

BOUC_WEN, DAHL, LUGRE, BINGHAM = 0, 1, 2, 3
MODEL_CODES = {"bouc-wen": BOUC_WEN, "dahl": DAHL, "lugre": LUGRE, "bingham": BINGHAM}

dahl_w_advance = njit(cache=True)(_dahl_py)
lugre_z_advance = njit(cache=True)(_lugre_py)
bingham_velocity_step = njit(cache=True)(_bingham_step_py)


@njit(cache=True)
def state_bound(model: int, p: np.ndarray) -> float:
    """|state| bound of the model's hysteretic variable (0 for Bingham, which has none)."""
    if model == BOUC_WEN:
        return (p[8] / (p[6] + p[7])) ** (1.0 / p[9])
    if model == DAHL:
        return 1.0
    if model == LUGRE:
        return 1.0 / (p[4] * p[7])
    return 0.0


@njit(cache=True)
def state_advance(model: int, p: np.ndarray, s: float, dtheta: float, bound: float) -> float:
    """The hysteretic state after an angle increment, for any model code."""
    if model == BOUC_WEN:
        return bw_advance(s, dtheta, p[6], p[7], p[8], p[9], bound)
    if model == DAHL:
        return dahl_w_advance(s, dtheta, p[6])
    if model == LUGRE:
        return lugre_z_advance(s, dtheta, p[4] * p[7])
    return 0.0


@njit(cache=True)
def state_path(model: int, p: np.ndarray, theta: np.ndarray, s0: float) -> np.ndarray:
    """The hysteretic state at every sample of an angle path (rate-independent laws)."""
    out = np.empty(theta.size)
    bound = state_bound(model, p)
    s = s0
    prev = theta[0]
    for j in range(theta.size):
        s = state_advance(model, p, s, theta[j] - prev, bound)
        prev = theta[j]
        out[j] = s
    return out


@njit(cache=True)
def simulate_rig(
    model: int,
    p: np.ndarray,
    t: np.ndarray,
    cur: np.ndarray,
    acc_road: np.ndarray,
    torque_in: np.ndarray,
    theta0: float,
    v0: float,
    s0: float,
    max_step: float,
) -> np.ndarray:
    """Angle record of the rig with the given damper model, driven by the recorded current,
    road-side acceleration and input torque (linear between samples). Returns theta [rad]."""
    N = t.size
    out = np.empty(N)
    out[0] = theta0
    theta = theta0
    v = v0
    s = s0
    J = p[0]
    k = p[1]
    bound = state_bound(model, p)
    for j in range(N - 1):
        dt = t[j + 1] - t[j]
        count = max(1, int(math.ceil(dt / max_step - 1e-9)))
        h = dt / count
        for q in range(count):
            frac = (q + 0.5) / count
            i = cur[j] + (cur[j + 1] - cur[j]) * frac
            force = -k * theta + torque_in[j] + (torque_in[j + 1] - torque_in[j]) * frac
            force -= J * (acc_road[j] + (acc_road[j + 1] - acc_road[j]) * frac)
            if model == BINGHAM:
                c = p[2] + p[3] * i
                fc = p[4] + p[5] * i
                v = bingham_velocity_step(v, h, force - p[6], J, c, max(fc, 0.0))
                theta += h * v
                continue
            if model == BOUC_WEN:
                # exactly the simulated rig's sub-step (the recorded current needs no coil lag)
                theta, v, s, _ = rig_substep(
                    theta,
                    v,
                    s,
                    i,
                    h,
                    i,
                    0.0,
                    J,
                    k,
                    p[2],
                    p[3],
                    p[4],
                    p[5],
                    p[6],
                    p[7],
                    p[8],
                    p[9],
                    bound,
                    force + k * theta,
                )
                continue
            if model == DAHL:
                c = p[2] + p[3] * i
                g = p[4] + p[5] * i
            else:  # LuGre: sigma1*(v - r|v|z) + sigma2*v + sigma_b*v*i + (sigma_a + sigma0*i)*z
                c = p[5] + p[6] + p[3] * i
                g = p[2] + p[4] * i
            denom = 1.0 + h * c / J
            v_pred = (v + h * (force - g * s) / J) / denom
            if model == LUGRE:
                g_eff = g - p[5] * p[4] * p[7] * abs(v_pred)
            else:
                g_eff = g
            s_pred = state_advance(model, p, s, h * v_pred, bound)
            if model == LUGRE:
                g_eff = g - p[5] * p[4] * p[7] * abs(v_pred)
                v_new = (v + h * (force - g_eff * 0.5 * (s + s_pred)) / J) / denom
            else:
                v_new = (v + h * (force - g * 0.5 * (s + s_pred)) / J) / denom
            dth = h * v_new
            theta += dth
            s = state_advance(model, p, s, dth, bound)
            v = v_new
        out[j + 1] = theta
    return out
