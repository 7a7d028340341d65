"""Bouc-Wen z-update (seed 001 eq. 17) and damper torque (eq. 9): bounds, accuracy, physics."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from sashil.models.hysteresis import BoucWenParams, BoucWenZ

SEED = BoucWenParams()
Z = BoucWenZ.from_params(SEED)


def test_bound_is_the_analytic_one():
    # (delta / (beta + gamma))^(1/n) with the seed values, by hand: (700/874)^(1/0.099)
    assert Z.z_u == pytest.approx((700.0 / 874.0) ** (1.0 / 0.099), rel=1e-12)
    assert Z.z_u == pytest.approx(0.10620, abs=1e-5)


@pytest.mark.parametrize("dt", [1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2])
@pytest.mark.parametrize("amplitude_deg,freq_hz", [(5.0, 1.66), (0.2, 5.0), (30.0, 3.0), (0.01, 0.5)])
def test_z_finite_and_bounded_at_every_step_size(dt, amplitude_deg, freq_hz):
    t = np.arange(0.0, 2.0, dt)
    theta = math.radians(amplitude_deg) * np.sin(2 * math.pi * freq_hz * t)
    z = Z.trajectory(theta, 0.0)
    assert np.all(np.isfinite(z))
    assert np.max(np.abs(z)) <= Z.z_u * (1 + 1e-12)


@settings(max_examples=300, deadline=None)
@given(
    z0=st.floats(-1.0, 1.0),
    increments=st.lists(st.floats(-10.0, 10.0, allow_nan=False) | st.floats(-1e-9, 1e-9), min_size=1, max_size=30),
)
def test_z_finite_and_bounded_for_any_increment(z0, increments):
    z = max(-Z.z_u, min(Z.z_u, z0 * Z.z_u))
    for step in increments:
        z = Z.advance(z, step)
        assert math.isfinite(z)
        assert abs(z) <= Z.z_u * (1 + 1e-12)


def test_z_zero_is_safe():
    # |z|^(n-1) is unbounded at 0 for n < 1: the update must not divide by zero there
    # dz/dtheta = delta at z = 0 and falls as |z| grows, so 0 < z < delta * dtheta
    up = Z.advance(0.0, 1e-12)
    assert 0.5 * 700.0 * 1e-12 < up < 700.0 * 1e-12
    assert Z.advance(0.0, -1e-12) == -up
    assert Z.advance(0.0, 0.0) == 0.0


def _reference_z(z0: float, travel: float) -> float:
    """Independent solution of dzeta/du = delta - |zeta|^n (beta + gamma sign zeta) (Radau, tight)."""

    def rhs(_u, y):
        a = abs(y[0])
        return [SEED.delta - a**SEED.n * (SEED.beta + SEED.gamma * np.sign(y[0]))]

    return solve_ivp(rhs, (0.0, travel), [z0], method="Radau", rtol=1e-11, atol=1e-14).y[0, -1]


@pytest.mark.parametrize("z0_frac", [-1.0, -0.5, 0.3, 0.9])
@pytest.mark.parametrize("travel", [1e-4, 1e-3, 4e-3, 2e-2])
def test_z_matches_an_independent_ode_solution(z0_frac, travel):
    z0 = z0_frac * Z.z_u
    # in 1 ms samples at 1 rad/s, the largest the rig sees
    steps = max(1, round(travel / 1e-3))
    z = z0
    for _ in range(steps):
        z = Z.advance(z, travel / steps)
    assert z == pytest.approx(_reference_z(z0, travel), abs=2e-3 * Z.z_u)


def test_motion_direction_flips_the_state():
    # odd symmetry of eq. 17: z(-dtheta) from -z0 is -z(dtheta) from z0
    for z0 in (-0.05, 0.0, 0.08):
        assert Z.advance(-z0, -2e-3) == pytest.approx(-Z.advance(z0, 2e-3), abs=1e-15)


def _cycle(current: float, amplitude: float = math.radians(3), freq: float = 1.5, dt: float = 1e-4):
    """Torque over the last of three sinusoidal displacement cycles."""
    t = np.arange(0.0, 3.0 / freq, dt)
    theta = amplitude * np.sin(2 * math.pi * freq * t)
    theta_dot = amplitude * 2 * math.pi * freq * np.cos(2 * math.pi * freq * t)
    z = Z.trajectory(theta, 0.0)
    torque = SEED.torque(z, theta_dot, current)
    last = t >= 2.0 / freq
    return theta[last], theta_dot[last], torque[last]


@pytest.mark.parametrize("current", [0.0, 0.25, 0.5, 1.0])
def test_closed_cycle_dissipates_positive_energy(current):
    _theta, theta_dot, torque = _cycle(current)
    energy = np.trapezoid(torque * theta_dot, dx=1e-4)  # = closed integral of T dtheta
    assert energy > 0.0
    # hand estimate: viscous pi*c*w*A^2 plus the hysteretic ~ 4*alpha*z_u*A (rectangular loop)
    amplitude, omega = math.radians(3), 2 * math.pi * 1.5
    viscous = math.pi * SEED.damping(current) * omega * amplitude**2
    hysteretic = 4 * SEED.hysteretic_gain(current) * Z.z_u * amplitude
    assert energy == pytest.approx(viscous + hysteretic, rel=0.05)


def test_torque_grows_with_current_for_the_same_motion():
    energies, peaks = [], []
    for current in (0.0, 0.25, 0.5, 0.75, 1.0):
        _theta, theta_dot, torque = _cycle(current)
        energies.append(np.trapezoid(torque * theta_dot, dx=1e-4))
        peaks.append(np.max(np.abs(torque)))
    assert all(b > a for a, b in itertools.pairwise(energies))
    assert all(b > a for a, b in itertools.pairwise(peaks))


def test_torque_formula_eq9():
    # T = (alpha1 + alpha2 i) z + (c1 + c2 i) theta_dot, by hand at i = 0.5
    assert SEED.torque(0.1, 2.0, 0.5) == pytest.approx((1 + 0.5) * 0.1 + (0.7 + 0.75) * 2.0)
