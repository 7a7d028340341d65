"""Dahl, LuGre, Bingham, the friction-damper laws and the compiled rig simulator, against
hand-derived values and direct integration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sashil.identify import kernels
from sashil.models.bingham import BinghamParams, bingham_velocity_step
from sashil.models.dahl import DahlParams, dahl_w_advance
from sashil.models.friction_damper import (
    FrictionDamperParams,
    bouc_wen_friction_rate,
    coulomb_friction,
    mstv_friction,
    stv_slipping,
)
from sashil.models.hysteresis import BoucWenParams, BoucWenZ
from sashil.models.lugre import LuGreParams, lugre_z_advance


def _integrate(rate, s0, dtheta):
    sol = solve_ivp(lambda u, y: [rate(y[0])], (0.0, abs(dtheta)), [s0], rtol=1e-11, atol=1e-13)
    return sol.y[0, -1]


@pytest.mark.parametrize("w0,dtheta", [(0.0, 0.01), (-1.0, 0.3), (0.7, -0.05), (0.2, 0.0)])
def test_dahl_exact_update_matches_integration(w0, dtheta):
    rho = 12.0
    s = math.copysign(1.0, dtheta) if dtheta else 1.0
    expected = _integrate(lambda w: rho * (s - w), w0, dtheta) if dtheta else w0  # dw/d|dtheta|
    assert dahl_w_advance(w0, dtheta, rho) == pytest.approx(expected, abs=1e-9)
    assert abs(dahl_w_advance(w0, 10.0 * (dtheta or 1.0), rho)) <= 1.0 + 1e-12


@pytest.mark.parametrize("z0,dtheta", [(0.0, 0.02), (0.05, -0.1), (-0.01, 0.004)])
def test_lugre_exact_update_matches_integration(z0, dtheta):
    p = LuGreParams(sigma0=5.0, a0=4.0)
    s = math.copysign(1.0, dtheta)
    expected = _integrate(lambda z: s * (1.0 - p.r * s * z), z0, dtheta)
    assert lugre_z_advance(z0, dtheta, p.r) == pytest.approx(expected, abs=1e-10)
    # eq. 8 at a state: z_dot = theta_dot - r|theta_dot| z
    assert p.z_dot(0.01, -2.0) == pytest.approx(-2.0 - 20.0 * 2.0 * 0.01)


def test_dahl_and_lugre_torque_formulas():
    d = DahlParams(c1=0.2, c2=0.3, kwa=0.6, kwb=2.8)
    assert d.torque(0.5, 2.0, 1.0) == pytest.approx((0.2 + 0.3) * 2.0 + (0.6 + 2.8) * 0.5)
    g = LuGreParams(sigma_a=10, sigma_b=1.5, sigma0=10, sigma1=0.01, sigma2=0.7, a0=10)
    z, v, i = 0.002, 0.5, 0.4
    expected = 10 * z + 10 * z * i + 0.01 * (v - 100 * abs(v) * z) + 0.7 * v + 1.5 * v * i
    assert g.torque(z, v, i) == pytest.approx(expected)


def test_bingham_stick_and_slip():
    # free step cannot overcome friction -> stick
    assert bingham_velocity_step(0.0, 1e-3, other_torque=0.5, J=1.0, c=0.0, fc=1.0) == 0.0
    # slip: v' = (v + h*(T - fc))/(1 + h*c/J)
    v = bingham_velocity_step(1.0, 1e-3, other_torque=2.0, J=1.0, c=0.5, fc=1.0)
    assert v == pytest.approx((1.0 + 1e-3 * 2.0) / (1 + 0.5e-3) - 1e-3 * 1.0 / (1 + 0.5e-3))
    assert BinghamParams(c0=1, c0_i=2, fc=0.3, fc_i=0.1, f0=0.05).torque(-2.0, 0.5) == pytest.approx(-0.35 - 4.0 + 0.05)


def test_compiled_bouc_wen_update_matches_reference_class():
    p = BoucWenParams(beta=600.0, gamma=50.0, delta=500.0, n=0.2)
    ref = BoucWenZ.from_params(p)
    zu = p.z_bound
    rng = np.random.default_rng(3)
    z = 0.0
    for dtheta in rng.normal(0.0, 2e-3, 300):
        expected = ref.advance(z, float(dtheta))
        got = kernels.bw_advance(z, float(dtheta), p.beta, p.gamma, p.delta, p.n, zu)
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-12 * zu)
        z = expected


def test_compiled_rig_simulation_matches_free_oscillation_without_damper():
    # k only (c = alpha = 0): theta = theta0*cos(sqrt(k/J) t) up to the integrator's O(h^2) phase error
    p = np.array([1.0, 100.0, 0.0, 0.0, 0.0, 0.0, 10.0, 0.0, 10.0, 1.0])
    t = np.arange(2001) * 1e-3
    zeros = np.zeros_like(t)
    theta = kernels.simulate_rig(0, p, t, zeros, zeros, zeros, 0.05, 0.0, 0.0, 1e-3)
    assert np.max(np.abs(theta - 0.05 * np.cos(10.0 * t))) < 0.05 * 0.02


def test_compiled_rig_simulation_close_to_rig_plant():
    from sashil.identify.data import record_from_columns
    from sashil.identify.rig_models import MODELS
    from sashil.identify.synthetic import drop_test_columns

    truth = BoucWenParams(k=95, c1=0.5, c2=1.2, alpha1=1.3, alpha2=0.8, beta=600, gamma=50, delta=500, n=0.2)
    cols = drop_test_columns(truth, -5.0, 0.5, duration_s=4.0, counts_per_rev=0)
    record = record_from_columns("plant", cols)
    sim = MODELS["bouc-wen"].simulate(truth.as_dict(), record)
    assert np.sqrt(np.mean((sim - cols["theta_rad"]) ** 2)) < 0.005 * np.std(cols["theta_rad"])


def test_friction_laws_hand_values():
    assert coulomb_friction(2.0, 44.0) == -44.0 and coulomb_friction(-1.0, 44.0) == 44.0
    assert stv_slipping(x_dot=3.0, y_dot=4.0)  # |Y'-X'| = 1 <= 3
    assert not stv_slipping(x_dot=1.0, y_dot=4.0)
    assert mstv_friction(3.0, 4.0, 40.0) == -40.0
    assert mstv_friction(1.0, 4.0, 40.0, 0.001) == pytest.approx(-1.0 / 3.001 * 40.0)
    p = FrictionDamperParams()
    zu = p.z_bound
    # loading at the bound: z' = 0 (eq. 8 equilibrium)
    assert bouc_wen_friction_rate(zu, 1.0, p.A, p.beta, p.gamma, p.n) == pytest.approx(0.0, abs=1e-9)


def test_friction_damper_sticks_below_f_max():
    # Coulomb friction, force k1*(Y - X) never reaches F_max: X sticks at 0, F = k1*Y + c1*Y'
    from sashil.identify.friction import simulate_harmonic

    p = FrictionDamperParams(k1=100.0, c1=0.5, c2=0.5, f_max=44.0)
    _t, Y, Yd, X, F = simulate_harmonic(p, "coulomb", 1.0, 0.3)
    assert np.max(np.abs(X)) == 0.0
    np.testing.assert_allclose(F, 100.0 * Y + 0.5 * Yd, atol=1e-9)
