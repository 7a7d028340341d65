"""The rig-model Kalman estimator, the road feed-forward and the estimator fallback."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sashil.config.parts import StageParts
from sashil.control.kalman import KalmanRigEstimator, discrete_model, steady_state_gain
from sashil.control.registry import make_controller
from sashil.drivers.interface import TWO_PI, RigCommand, RigSample
from sashil.drivers.sim import SimulatedRig
from sashil.engine.resolve import default_config
from sashil.errors import ConfigError
from sashil.lab._sweep import sine_profile
from sashil.models.hysteresis import BoucWenParams
from sashil.models.plant import RigPlant


def sample(arm_counts: int, road_counts: int = 0, cpr: int = 4096) -> RigSample:
    return RigSample(0, 0, 0, arm_counts, road_counts, 0.0, 0, cpr)


def test_discrete_model_is_the_hand_derived_transition_and_noise():
    dt, s_a = 1e-3, 2.0
    f, q = discrete_model(dt, s_a, 1e-12, 1e-12)
    # theta += dt*v + dt^2/2*(b - theta1_ddot); theta1 += dt*theta1_dot + dt^2/2*theta1_ddot
    assert f[0] == pytest.approx([1.0, dt, 0.0, 0.0, -0.5 * dt * dt, 0.5 * dt * dt], abs=1e-15)
    assert f[1] == pytest.approx([0.0, 1.0, 0.0, 0.0, -dt, dt], abs=1e-15)
    assert f[2] == pytest.approx([0.0, 0.0, 1.0, dt, 0.5 * dt * dt, 0.0], abs=1e-15)
    # white acceleration noise S on a double integrator: S*[[dt^3/3, dt^2/2], [dt^2/2, dt]]
    assert q[0, 0] == pytest.approx(s_a * dt**3 / 3, rel=1e-6)
    assert q[0, 1] == pytest.approx(s_a * dt**2 / 2, rel=1e-6)
    assert q[1, 1] == pytest.approx(s_a * dt, rel=1e-6)
    assert np.allclose(q, q.T) and np.all(np.linalg.eigvalsh(q) > -1e-20)


def test_gain_grows_as_the_encoder_gets_finer():
    coarse = steady_state_gain(1e-3, (TWO_PI / 4096) ** 2 / 12, 1.0, 100.0, 1.0)
    fine = steady_state_gain(1e-3, (TWO_PI / 65536) ** 2 / 12, 1.0, 100.0, 1.0)
    assert fine[1, 0] > 3 * coarse[1, 0] > 0.0  # rate gain on the arm encoder


@pytest.mark.parametrize("quantisation", ["noise", "cell"])
def test_constant_rate_from_quantised_counts(quantisation):
    cpr, rate = 4096, 0.8
    est = KalmanRigEstimator(1e-3, quantisation=quantisation)
    for k in range(4000):
        est.update(sample(round(rate * k * 1e-3 * cpr / TWO_PI), cpr=cpr), 1e-3)
    assert est.theta_dot_rad_s == pytest.approx(rate, abs=0.01)
    assert est.body_dot_rad_s == pytest.approx(rate, abs=0.01)
    assert not est.diverged  # the start (at rest, the counts already moving) is not a divergence


def test_cell_model_does_not_correct_a_prediction_inside_the_count():
    est = KalmanRigEstimator(1e-3, quantisation="cell")
    est.update(sample(100), 1e-3)
    before = list(est.x)
    est.update(sample(100), 1e-3)  # predicted angle = the count's centre: inside its cell
    assert est.x == before
    est.update(sample(102), 1e-3)  # two counts away: beyond the one-count zone, corrected towards it
    assert est.x[0] > before[0] and est.x[1] > 0.0


def test_auto_quantisation_picks_the_model_by_resolution():
    coarse, fine = KalmanRigEstimator(1e-3, quantisation="auto"), KalmanRigEstimator(1e-3, quantisation="auto")
    coarse.update(sample(0, cpr=4096), 1e-3)
    fine.update(sample(0, cpr=65536), 1e-3)
    assert coarse.deadzone > 0.0 and fine.deadzone == 0.0
    with pytest.raises(ValueError, match="quantisation"):
        KalmanRigEstimator(1e-3, quantisation="dither")


def test_model_acceleration_lets_the_filter_follow_a_known_motion_without_lag():
    # theta = A sin(w t) at 1.6 Hz, 4096 counts: with the true acceleration the rate error stays
    # a fraction of the motion's rate; without it (a = 0) the low-noise filter lags far behind
    cpr, w, amp, dt = 4096, TWO_PI * 1.6, 0.05, 1e-3
    aided, blind = KalmanRigEstimator(dt), KalmanRigEstimator(dt)
    err_aided = err_blind = 0.0
    for k in range(3000):
        t = k * dt
        counts = round(amp * math.sin(w * t) * cpr / TWO_PI)
        aided.update(sample(counts, cpr=cpr), dt, -w * w * amp * math.sin(w * (t - 0.5 * dt)))
        blind.update(sample(counts, cpr=cpr), dt, 0.0)
        if t > 1.0:
            truth = amp * w * math.cos(w * t)
            err_aided = max(err_aided, abs(aided.theta_dot_rad_s - truth))
            err_blind = max(err_blind, abs(blind.theta_dot_rad_s - truth))
    assert err_aided < 0.05 * amp * w < err_blind


def _run(config: dict, true: BoucWenParams, seconds: float, road=None, command_road: bool = True, drop: bool = False):
    """The controller stage against the simulated rig on simulated time; returns (controller, errors, currents).
    ``road``: the road wheel follows its speed; ``command_road``: the controller is told that speed
    (the plan's command carries it) or not (the road moves unannounced)."""
    plant = RigPlant(true)
    rig = SimulatedRig(plant, counts_per_rev=config["rig"]["encoder_counts_per_rev"])
    ctl = make_controller("torque-tracking", StageParts.read(config))
    rig.configure()
    rig.activate()
    if drop:
        rig.operator_hold(math.radians(-5.0), 0.2)
    rate_err, currents = [], []
    for k in range(int(seconds * 1000)):
        t_ns = k * 1_000_000
        s = rig.read(t_ns, 1_000_000)
        ctl.held = plant.held
        truth = plant.state.theta_dot_rad_s
        cmd = ctl.step(s, t_ns, 1_000_000)
        speed = road(k * 1e-3)[1] if road is not None else None
        if command_road:
            cmd.road_speed_rad_s = speed
        rig.write(RigCommand(cmd.current_a, speed), t_ns, 1_000_000)
        currents.append(cmd.current_a)
        if k > 3000:
            rate_err.append(ctl.theta_dot_rad_s - truth)
    rig.close()
    return ctl, np.asarray(rate_err), np.asarray(currents)


def test_commanded_road_speed_sharpens_the_rate_estimate():
    config = default_config()
    road = sine_profile(math.radians(1.0), 1.2, 1.0)
    _, with_ff, _ = _run(config, BoucWenParams(), 8.0, road=road)
    _, without, _ = _run(config, BoucWenParams(), 8.0, road=road, command_road=False)
    rms_with, rms_without = float(np.sqrt(np.mean(with_ff**2))), float(np.sqrt(np.mean(without**2)))
    assert rms_with < 0.5 * rms_without


@pytest.mark.parametrize("factor", [0.05, 20.0])
def test_a_wildly_wrong_inertia_falls_back_to_zero_current_counted_never_nan(factor):
    # a model J 20 times off predicts accelerations 20 times too large or too small: on a drop the
    # residual runs to 7-50 counts (about 1 with the right J) and the controller falls back to 0 A
    config = default_config()
    config["model"]["params"]["J"] = factor  # the rig's J is 1
    ctl, _, currents = _run(config, BoucWenParams(), 4.0, drop=True)
    stats = ctl.stats()
    assert stats["fallback"] and stats["fallback_cycles"] > 0 and stats["innovations_out"] >= 1
    after = int(round(stats["fallback_at_s"] * 1000)) + 1
    assert np.all(currents[after:] == 0.0) and np.all(np.isfinite(currents))
    assert math.isnan(ctl.torque_cmd_nm)


def test_the_right_inertia_never_falls_back():
    ctl, _, currents = _run(default_config(), BoucWenParams(), 4.0, drop=True)
    assert not ctl.stats()["fallback"] and ctl.estimator.innovations_out == 0
    assert ctl.estimator.innovation_max_counts < 2.0
    assert np.all((currents >= 0.0) & (currents <= 1.0))


def test_estimator_settings_are_checked_like_the_rest_of_the_config(tmp_path):
    from sashil.engine.resolve import load_config

    path = tmp_path / "bad.yaml"
    path.write_text("controller:\n  kalman_quantisation: dither\n")
    with pytest.raises(ConfigError, match=r"controller\.kalman_quantisation"):
        load_config(path)
    path.write_text("controller:\n  kalman_accel_psd: -1\n")
    with pytest.raises(ConfigError, match=r"controller\.kalman_accel_psd"):
        load_config(path)


def test_the_gains_are_ready_before_the_first_sample():
    # the first real-time cycle must not solve a Riccati equation (first cycle on time)
    ctl = make_controller("torque-tracking", StageParts.read(default_config()))
    assert ctl.estimator._counts_per_rev == 4096 and len(ctl.estimator._gain) == 6
