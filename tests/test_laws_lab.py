"""The lab's comparison laws: LQR gains against hand-worked cases, the clipped-optimal switching,
pdd and the hybrid, and their bad input as one line naming the key."""

from __future__ import annotations

import math

import pytest

from sashil.cli import main
from sashil.control import LawContext, LawState
from sashil.control.law_registry import find_law
from sashil.control.laws_lab import ClippedOptimal, GroundhookHybrid, LqrClipped, PowerDrivenDamper
from sashil.control.lqr import lqr_gains, scaled_weights
from sashil.errors import ConfigError
from sashil.models.hysteresis import BoucWenParams

CONTEXT = LawContext(BoucWenParams(), 1.0, 1000.0)


def state(**values: float) -> LawState:
    s = LawState()
    for key, value in values.items():
        setattr(s, key, value)
    return s


def test_lqr_of_the_double_integrator_is_the_textbook_gain():
    # J θ̈2 = −u, Q = diag(1, 0), R = 1: the textbook K = [1, √2] of ẍ = v, with u = −v
    design = lqr_gains(1.0, 0.0, 0.0, q_accel=0.0, q_theta=1.0, q_body_dot=0.0, r_torque=1.0)
    assert design.k_theta == pytest.approx(-1.0) and design.k_body == pytest.approx(-math.sqrt(2.0))


def test_lqr_of_the_spring_mass_matches_the_closed_form():
    # ẍ = −k x + v, Q = diag(q, 0), R = 1: p12 = √(k² + q) − k, p22 = √(2 p12), K_v = [p12, p22]
    k, q = 109.0, 100.0
    p12 = math.sqrt(k * k + q) - k
    design = lqr_gains(1.0, k, 0.0, q_accel=0.0, q_theta=q, q_body_dot=0.0, r_torque=1.0)
    assert design.k_theta == pytest.approx(-p12) and design.k_body == pytest.approx(-math.sqrt(2.0 * p12))
    assert all(p.real < 0 for p in design.poles)


def test_comfort_and_travel_weights_leave_a_double_integrator():
    # r = 0: the input may set θ̈2 = a freely, so the cost q_a a² + q_θ θ² is the double integrator's,
    # a* = −√(q_θ/q_a)·θ − √2·(q_θ/q_a)^¼·θ̇2, and u* = −kθ − c_n θ̇2 − a*: K = [k − √ρ, c_n − √2·ρ^¼]
    k, c_n, rho = 109.0, 0.7, 1e-4
    design = lqr_gains(1.0, k, c_n, q_accel=1.0, q_theta=rho, q_body_dot=0.0, r_torque=0.0)
    assert design.k_theta == pytest.approx(k - math.sqrt(rho))
    assert design.k_body == pytest.approx(c_n - math.sqrt(2.0) * rho**0.25)


def test_relative_weights_are_the_rigs_own_scales():
    # ω_n² = k/J = 4: the travel weight in units of ω_n⁴, the rate's in ω_n², the torque's in 1/J²
    assert scaled_weights(2.0, 8.0, 1.0, 0.5, 0.25, 3.0) == pytest.approx((1.0, 8.0, 1.0, 0.75))
    # no spring, no ω_n: the travel and rate terms vanish
    assert scaled_weights(1.0, 0.0, 1.0, 0.5, 0.25, 0.0) == (1.0, 0.0, 0.0, 0.0)


@pytest.mark.parametrize("J, k", [(0.5, 109.0), (2.0, 70.0), (1.0, 160.0)])
def test_one_set_of_weights_is_the_same_design_on_any_rig(J, k):
    # the seed rig (J 1, k 109) and another J, k at the same nominal damping ratio ζ_n: the gains in
    # the rig's units (k_θ/k, k_v/√(kJ)) and the poles over ω_n are the same
    def normalised(J: float, k: float) -> tuple[float, ...]:
        c_n = 2.0 * 0.05 * math.sqrt(k * J)
        design = lqr_gains(J, k, c_n, *scaled_weights(J, k, 1.0, 0.25, 0.1, 0.01))
        w = math.sqrt(k / J)
        poles = sorted(design.poles, key=lambda p: p.imag)
        return (
            design.k_theta / k,
            design.k_body / math.sqrt(k * J),
            *(x for p in poles for x in (p.real / w, p.imag / w)),
        )

    assert normalised(J, k) == pytest.approx(normalised(1.0, 109.0))


def test_the_laws_weights_are_relative_to_the_rig():
    # the law's gains are lqr_gains' on the scaled weights; on the seed rig (k/J = 109) q_theta 0.25
    # is an absolute travel weight of 0.25·109² 1/(rad s²)²
    law = LqrClipped(CONTEXT, q_theta=0.25, lqr_current_a=0.0)
    design = lqr_gains(1.0, 109.0, 0.7, q_accel=1.0, q_theta=0.25 * 109.0**2, q_body_dot=0.0, r_torque=0.0)
    assert (law.k_theta, law.k_body) == pytest.approx((design.k_theta, design.k_body))


@pytest.mark.parametrize(
    "params, key",
    [
        ({"q_accel": 0.0, "q_theta": 0.0, "q_body_dot": 0.0}, "controller.q_accel"),
        ({"q_accel": 0.0, "r_torque": 0.0}, "controller.r_torque"),
        ({"q_theta": -1.0}, "controller.q_theta"),
        ({"lqr_current_a": 2.0}, "controller.lqr_current_a"),
    ],
)
def test_bad_weights_are_one_line_naming_the_key(params, key):
    with pytest.raises(ConfigError) as err:
        LqrClipped(CONTEXT, **params)
    assert str(err.value).startswith(key + ":") and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "model, weights",
    [
        # comfort alone on an undamped spring-mass: cancelling the spring costs nothing, the cost sees
        # neither mode and both stay on the imaginary axis
        (BoucWenParams(c1=0.0), {"q_accel": 1.0, "q_theta": 0.0, "q_body_dot": 0.0, "r_torque": 0.0}),
        # no spring, only the rate weighted: the angle's mode (at 0) is invisible to the cost
        (BoucWenParams(k=0.0, c1=0.0), {"q_accel": 0.0, "q_theta": 0.0, "q_body_dot": 1.0, "r_torque": 1.0}),
    ],
)
def test_no_stabilising_solution_is_a_config_error(model, weights):
    with pytest.raises(ConfigError, match=r"^controller\.q_theta: the LQR has no stabilising solution"):
        LqrClipped(LawContext(model, 1.0, 1000.0), lqr_current_a=0.0, **weights)


def test_lqr_clipped_torque_is_the_design_and_clipped_optimal_switches_as_dyke():
    law = LqrClipped(CONTEXT)
    s = state(theta_rad=0.01, theta_dot_rad_s=0.2, body_dot_rad_s=0.3)
    expected = law.c_n * 0.2 - law.k_theta * 0.01 - law.k_body * 0.3
    assert law.torque(s) == pytest.approx(expected)
    assert LqrClipped.output_kind() == "torque" and ClippedOptimal.output_kind() == "current"
    co = ClippedOptimal(CONTEXT, onoff_current_a=0.8)
    t_star = co.desired(s)
    # on when T* and T̂ have the same sign and |T*| > |T̂|; off otherwise
    assert co.current(state(theta_rad=0.01, theta_dot_rad_s=0.2, body_dot_rad_s=0.3, torque_hat_nm=0.5 * t_star)) == 0.8
    assert co.current(state(theta_rad=0.01, theta_dot_rad_s=0.2, body_dot_rad_s=0.3, torque_hat_nm=2.0 * t_star)) == 0.0
    assert co.current(state(theta_rad=0.01, theta_dot_rad_s=0.2, body_dot_rad_s=0.3, torque_hat_nm=-t_star)) == 0.0
    with pytest.raises(ConfigError, match=r"^controller\.onoff_current_a:"):
        ClippedOptimal(CONTEXT, onoff_current_a=1.5)


def test_pdd_cancels_the_spring_inside_its_band_and_saturates_outside():
    law = PowerDrivenDamper(CONTEXT)  # c in [c1, c1 + c2] = [0.7, 2.2], k = 109
    # −kθ/θ̇ = 1.09 inside the band: T* = −kθ
    assert law.torque(state(theta_rad=-0.01, theta_dot_rad_s=1.0)) == pytest.approx(1.09)
    assert law.torque(state(theta_rad=-0.1, theta_dot_rad_s=1.0)) == pytest.approx(2.2)  # c_max
    assert law.torque(state(theta_rad=0.1, theta_dot_rad_s=1.0)) == pytest.approx(0.7)  # c_min
    assert law.torque(state(theta_rad=0.1, theta_dot_rad_s=0.0)) == 0.0
    with pytest.raises(ConfigError, match=r"^controller\.c_max:"):
        PowerDrivenDamper(CONTEXT, c_min=3.0, c_max=2.0)


def test_hybrid_is_skyhook_at_weight_one_and_groundhook_at_zero():
    s = state(body_dot_rad_s=0.5, road_dot_rad_s=0.2)
    assert GroundhookHybrid(CONTEXT, hybrid_weight=1.0, c_hybrid=2.0).torque(s) == pytest.approx(1.0)
    assert GroundhookHybrid(CONTEXT, hybrid_weight=0.0, c_hybrid=2.0).torque(s) == pytest.approx(-0.4)
    assert GroundhookHybrid(CONTEXT).torque(s) == pytest.approx(2.2 * (0.8 * 0.5 - 0.2 * 0.2))


@pytest.mark.parametrize("name", ["clipped-optimal", "lqr-clipped", "pdd", "groundhook-hybrid"])
def test_the_new_laws_are_built_ins(name):
    assert find_law(name).origin.startswith("built-in")


def test_a_bad_weight_on_the_command_line_is_exit_2_and_nothing_written(tmp_path, capsys):
    out = tmp_path / "never"
    code = main(
        ["run", "--controller", "lqr-clipped", "--set", "controller.q_theta=-1", "--duration", "0.1", "--out", str(out)]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and not out.exists()
    assert len(err) == 1 and "controller.q_theta" in err[0]
