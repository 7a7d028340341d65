"""The rig plant and the drop test against values derived by hand and an independent ODE solution."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sashil.lab._drop_test import run_drop_test
from sashil.models.hysteresis import BoucWenParams, BoucWenZ
from sashil.models.plant import RigPlant

FINE_ENCODER = 2**24  # quantisation far below what the closed-form checks resolve


def _linear_config(config, **params):
    config["model"]["params"].update(params)
    config["rig"]["encoder_counts_per_rev"] = FINE_ENCODER
    return config


def _closed_form(t, theta0, J, k, c):
    """Free response of J th'' + c th' + k th = 0 from rest at theta0 (underdamped)."""
    sigma = c / (2 * J)
    omega_d = math.sqrt(k / J - sigma**2)
    return theta0 * np.exp(-sigma * t) * (np.cos(omega_d * t) + sigma / omega_d * np.sin(omega_d * t))


@pytest.mark.parametrize("current", [0.0, 1.0])
def test_without_hysteresis_the_drop_test_is_a_damped_linear_oscillator(config, current):
    config = _linear_config(config, alpha1=0.0, alpha2=0.0)
    record = run_drop_test(config, -5.0, current, 6.0)
    c = 0.7 + 1.5 * current
    sigma, omega_d = c / 2, math.sqrt(109.0 - (c / 2) ** 2)
    # hand-derived: period 2 pi / omega_d, log decrement 2 pi sigma / omega_d
    m = record.metrics
    assert m.period_s == pytest.approx(2 * math.pi / omega_d, rel=2e-3)
    assert m.log_decrement == pytest.approx(2 * math.pi * sigma / omega_d, rel=1e-2)
    t = record.data["time_s"]
    expected = _closed_form(t, math.radians(-5.0), 1.0, 109.0, c)
    assert np.max(np.abs(record.data["theta_rad"] - expected)) < math.radians(0.002)


def test_without_damping_the_amplitude_is_kept(config):
    config = _linear_config(config, alpha1=0.0, alpha2=0.0, c1=0.0, c2=0.0)
    record = run_drop_test(config, -5.0, 0.0, 6.0)
    peaks = record.metrics.peaks_deg
    assert len(peaks) >= 9
    assert peaks == pytest.approx([5.0] * len(peaks), abs=0.01)
    assert record.metrics.period_s == pytest.approx(2 * math.pi / math.sqrt(109.0), rel=2e-3)


def _reference_drop(current: float, duration: float):
    """Independent time-domain solution of seed 001 eqs. 14-17 (LSODA, tight tolerances)."""
    p = BoucWenParams()
    z0 = BoucWenZ.from_params(p).advance(0.0, math.radians(-5.0))  # pressing the arm from 0 to -5 deg

    def rhs(_t, y):
        theta, v, z = y
        a = abs(z)
        z_dot = -p.gamma * abs(v) * math.copysign(a**p.n, z) - p.beta * v * a**p.n + p.delta * v
        return [v, (-p.k * theta - p.damping(current) * v - p.hysteretic_gain(current) * z) / p.J, z_dot]

    t = np.arange(0.0, duration, 1e-3)
    sol = solve_ivp(
        rhs,
        (0.0, duration),
        [math.radians(-5.0), 0.0, z0],
        method="LSODA",
        rtol=1e-10,
        atol=1e-12,
        t_eval=t,
        max_step=1e-4,
    )
    return t, sol.y[0]


@pytest.mark.parametrize("current", [0.0, 1.0])
def test_seed_drop_test_follows_the_model(config, current):
    record = run_drop_test(config, -5.0, current, 3.0)
    t_ref, theta_ref = _reference_drop(current, 3.0)
    n = min(len(t_ref), len(record.data["time_s"]))
    assert record.data["time_s"][:n] == pytest.approx(t_ref[:n], abs=1e-9)
    resolution = 2 * math.pi / config["rig"]["encoder_counts_per_rev"]
    error = np.abs(record.data["theta_rad"][:n] - theta_ref[:n])
    # quantisation (half a count) plus the plant's 1 ms step
    assert np.max(error) < 0.5 * resolution + math.radians(0.005)
    ref_peaks = [
        math.degrees(theta_ref[j])
        for j in range(1, n - 1)
        if theta_ref[j] > 0 and theta_ref[j] >= theta_ref[j - 1] and theta_ref[j] > theta_ref[j + 1]
    ]
    got = record.metrics.peaks_deg[: len(ref_peaks)]
    assert got == pytest.approx(ref_peaks[: len(got)], abs=math.degrees(resolution))


def test_default_drop_test_period_is_0600s(config):
    record = run_drop_test(config, -5.0, 0.0, 10.0)
    assert record.metrics.period_s == pytest.approx(0.600, rel=0.01)
    # current stiffens and damps: fewer, smaller peaks at 1 A
    one_amp = run_drop_test(config, -5.0, 1.0, 10.0)
    assert one_amp.metrics.peaks_deg[0] < record.metrics.peaks_deg[0]
    assert one_amp.metrics.settling_time_s < record.metrics.settling_time_s


def test_coil_lag_is_first_order():
    plant = RigPlant(BoucWenParams(), coil_tau_s=0.01, current_max_a=1.0, max_step_s=1e-4)
    plant.hold(0.0)
    plant.step(0.01, 1.0)  # one time constant
    assert plant.state.current_a == pytest.approx(1 - math.exp(-1), rel=1e-9)
    plant.step(1.0, 5.0)  # clipped to i_max
    assert plant.state.current_a == pytest.approx(1.0, abs=1e-12)
    plant.step(1.0, -1.0)  # clipped to 0
    assert plant.state.current_a == pytest.approx(0.0, abs=1e-12)


def test_held_arm_does_not_move_until_released():
    plant = RigPlant(BoucWenParams())
    plant.hold(math.radians(-5))
    plant.step(0.5, 0.0)
    assert plant.state.theta_rad == math.radians(-5)
    plant.release()
    plant.step(0.01, 0.0)
    # released from rest: spring k*5deg plus the saturated hysteretic torque alpha1*z_u (pressing
    # the arm down left z at -z_u) accelerate it towards 0
    acceleration = 109.0 * math.radians(5) + 1.0 * plant.hysteresis.z_u
    moved = plant.state.theta_rad - math.radians(-5)
    assert moved == pytest.approx(0.5 * acceleration * 0.01**2, rel=0.01)


def test_road_input_drives_the_relative_angle():
    # a road angle accelerating at a constant rate pushes the relative angle the other way (-J*th1'')
    plant = RigPlant(
        BoucWenParams(alpha1=0.0, alpha2=0.0, c1=0.0), max_step_s=1e-4, road=lambda t: (0.5 * 2.0 * t * t, 2.0 * t, 2.0)
    )
    plant.step(0.01, 0.0)
    assert plant.state.theta_rad == pytest.approx(-0.5 * 2.0 * 0.01**2, rel=0.02)
    assert plant.state.theta_road_rad == pytest.approx(1e-4)
