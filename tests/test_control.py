"""Estimator, observer, inverse, laws, controller stage, registry errors, plant mismatch."""

from __future__ import annotations

import itertools
import math

import pytest

from sashil.config.parts import StageParts
from sashil.control.estimator import RigEstimator, TrackingFilter, rate_response
from sashil.control.inverse import CoilLagCompensator, HysteresisInverse
from sashil.control.laws import SkyhookOnOff, band_limited_fraction
from sashil.control.observer import BoucWenObserver
from sashil.control.registry import make_controller
from sashil.drivers import open_rig
from sashil.drivers.interface import RigSample
from sashil.drivers.mismatch import mismatch_fractions, plant_sections
from sashil.engine import assemble
from sashil.engine.resolve import default_config
from sashil.errors import ConfigError, LawError
from sashil.lab._drop_test import run_drop_test
from sashil.models.hysteresis import BoucWenParams, BoucWenZ
from sashil.runtime.clock import VirtualClock

SEED = BoucWenParams()


def sample(arm_counts: int, road_counts: int = 0, current: float = 0.0, cpr: int = 4096) -> RigSample:
    return RigSample(0, 0, 0, arm_counts, road_counts, current, 0, cpr)


# --- estimator ------------------------------------------------------------------------------
def test_alpha_beta_tracks_a_constant_rate_from_counts():
    cpr, rate = 4096, 0.8  # rad/s
    est = RigEstimator(bandwidth_hz=10.0)
    for k in range(3000):
        counts = round(rate * k * 1e-3 * cpr / (2 * math.pi))
        est.update(sample(counts, cpr=cpr), 1e-3)
    assert est.theta_dot_rad_s == pytest.approx(rate, abs=0.01)
    assert est.body_dot_rad_s == pytest.approx(rate, abs=0.01)


def test_alpha_beta_delay_matches_the_analogue_loop_2_over_w():
    gain, delay, _ = rate_response(25.0, 1000.0, 1.0, order=2)
    assert delay == pytest.approx(2.0 / (2 * math.pi * 25.0), rel=0.05)
    assert gain == pytest.approx(1.0, abs=0.01)
    _, delay3, _ = rate_response(30.0, 1000.0, 1.6, order=3)
    assert abs(delay3) < 0.5e-3


def test_model_acceleration_removes_the_lag_of_a_known_motion():
    # theta = sin(w t): with the exact acceleration the estimate follows without lag
    w, dt = 2 * math.pi * 1.6, 1e-3
    plain, aided = TrackingFilter(10.0), TrackingFilter(10.0)
    worst_plain = worst_aided = 0.0
    for k in range(4000):
        t = k * dt
        plain.update(math.sin(w * t), dt)
        aided.update(math.sin(w * t), dt, -w * w * math.sin(w * (t - 0.5 * dt)))
        if t > 1.0:
            worst_plain = max(worst_plain, abs(plain.v - w * math.cos(w * t)))
            worst_aided = max(worst_aided, abs(aided.v - w * math.cos(w * t)))
    assert worst_aided < 0.02 * w < worst_plain


# --- observer -------------------------------------------------------------------------------
def test_observer_z_is_the_model_z_update_and_torque_is_eq9():
    obs = BoucWenObserver(SEED)
    angles = [0.01 * math.sin(0.01 * k) for k in range(800)]
    expected = BoucWenZ.from_params(SEED).trajectory(angles)
    for angle in angles:
        obs.update(angle, 0.3, 0.4)
    assert obs.z == pytest.approx(float(expected[-1]), rel=1e-12)
    assert obs.torque_nm == pytest.approx((1 + 0.4) * obs.z + (0.7 + 1.5 * 0.4) * 0.3, rel=1e-12)
    by_increment = BoucWenObserver(SEED)
    for before, after in itertools.pairwise(angles):
        by_increment.update_increment(after - before, -0.2, 0.0)
    assert by_increment.z == pytest.approx(obs.z, rel=1e-12)
    assert by_increment.torque_nm == pytest.approx(obs.z - 0.7 * 0.2, rel=1e-12)
    # the controller's call goes straight to the compiled z-update: bit for bit the model's own step
    law, z = BoucWenZ.from_params(SEED), 0.0
    direct = BoucWenObserver(SEED)
    for before, after in itertools.pairwise(angles):
        z = law.advance(z, after - before)
        assert direct.update_increment(after - before, 0.3, 0.4) == SEED.torque(z, 0.3, 0.4)
        assert direct.z == z


# --- inverse --------------------------------------------------------------------------------
def test_inverse_hand_values_band_and_clipping():
    inv = HysteresisInverse(SEED, 1.0)
    # z = 0.1, v = 1: T(0) = 0.1 + 0.7 = 0.8, T(1) = 0.2 + 2.2 = 2.4, slope 1.6
    assert inv.current(1.6, 0.1, 1.0) == pytest.approx(0.5)
    assert (inv.band_lo_nm, inv.band_hi_nm) == pytest.approx((0.8, 2.4))
    assert inv.current(3.0, 0.1, 1.0) == 1.0 and inv.clipped and inv.clip_count == 1
    assert inv.current(0.5, 0.1, 1.0) == 0.0 and inv.clip_count == 2
    assert inv.current(-1.0, 0.1, 1.0) == 0.0 and inv.clip_count == 3  # below the band: its nearer end
    assert inv.current(0.01, -0.0015, 0.001) == 0.0 and inv.passive_count == 1  # |alpha2 z + c2 v| < 1e-3
    assert inv.current(float("nan"), 0.1, 1.0) == 0.0  # never a NaN current


def test_inverse_picks_the_band_current_closest_to_the_target_just_after_a_reversal():
    # v = 0.05 > 0 but z = -0.1 has not followed yet: T(0) = -0.1 + 0.035 = -0.065,
    # T(1) = -0.2 + 0.11 = -0.09, slope -0.025 N m/A. T* = -0.08 lies inside the band at
    # i = (-0.08 + 0.065) / -0.025 = 0.6 A; the T*·v rule would have commanded 0 A (-0.065 N m).
    full, rule = HysteresisInverse(SEED, 1.0), HysteresisInverse(SEED, 1.0, mode="rule")
    assert full.current(-0.08, -0.1, 0.05) == pytest.approx(0.6)
    assert (full.band_lo_nm, full.band_hi_nm) == pytest.approx((-0.065, -0.09))
    assert rule.current(-0.08, -0.1, 0.05) == 0.0 and rule.passive_count == 1
    # outside the band the nearer end: -0.2 is beyond T(1) = -0.09, so 1 A
    assert full.current(-0.2, -0.1, 0.05) == 1.0 and full.clipped


@pytest.mark.parametrize("target", [-3.0, -0.5, 0.0, 0.3, 0.9, 1.7, 2.4, 5.0])
@pytest.mark.parametrize(("z", "v"), [(0.1, 1.0), (-0.1, 0.05), (0.05, -0.4), (-0.1, -2.0)])
def test_inverse_current_minimises_the_torque_error_over_the_current_range(target, z, v):
    inv = HysteresisInverse(SEED, 1.0)
    i = inv.current(target, z, v)
    grid = [k / 1000 for k in range(1001)]
    best = min(abs(SEED.torque(z, v, c) - target) for c in grid)
    assert abs(SEED.torque(z, v, i) - target) <= best + 1e-12


@pytest.mark.parametrize("mode", ["full", "rule", "viscous"])
def test_solving_on_the_band_set_this_cycle_is_the_inverse_current(mode):
    """The controller sets the band once a cycle and solves on its line: the same current, clip and
    passive counts as ``current`` recomputing the band, bit for bit."""
    once, twice = HysteresisInverse(SEED, 1.0, mode=mode), HysteresisInverse(SEED, 1.0, mode=mode)
    for target in (-3.0, -0.08, 0.0, 0.3, 1.6, 5.0, float("nan")):
        for z, v in ((0.1, 1.0), (-0.1, 0.05), (0.05, -0.4), (-0.0015, 0.001)):
            at_zero, authority = once.band(z, v)
            solved = once.solve(target, at_zero, authority, v)
            assert solved == twice.current(target, z, v)  # a NaN target: 0 A from both
            assert (once.clipped, once.clip_count, once.passive_count) == (
                twice.clipped,
                twice.clip_count,
                twice.passive_count,
            )


def test_viscous_only_inverse_ignores_alpha():
    inv = HysteresisInverse(SEED, 1.0, mode="viscous")
    assert inv.current(1.45, 0.1, 1.0) == pytest.approx(0.5)  # (1.45 - 0.7) / 1.5
    assert inv.current(-1.0, 0.1, 1.0) == 0.0 and inv.passive_count == 1  # keeps the T*·v rule
    with pytest.raises(ValueError, match="inverse mode"):
        HysteresisInverse(SEED, 1.0, mode="exact")


def test_coil_lead_speeds_up_the_coil_current():
    tau, horizon, dt = 0.01, 0.003, 1e-3
    lead = CoilLagCompensator(tau, horizon, 1.0)
    assert lead.gain == pytest.approx(1.0 / (1.0 - math.exp(-0.3)))
    # one period with the command held: the current closes gain*(1 - exp(-dt/tau)) of the gap
    cmd = lead.command(0.3, 0.2)
    after = cmd + (0.2 - cmd) * math.exp(-dt / tau)
    assert after - 0.2 == pytest.approx(0.1 * lead.gain * (1 - math.exp(-dt / tau)))
    current, plain = 0.2, 0.2
    for _ in range(3):
        cmd = lead.command(0.3, current)
        current = cmd + (current - cmd) * math.exp(-dt / tau)
        plain = 0.3 + (plain - 0.3) * math.exp(-dt / tau)
    assert abs(0.3 - current) < 0.35 * abs(0.3 - plain)
    assert lead.command(5.0, 0.2) == 1.0 and lead.command(-1.0, 0.2) == 0.0  # clipped to [0, i_max]
    assert CoilLagCompensator(tau, 0.0, 1.0).command(0.6, 0.2) == 0.6


# --- laws, controller -----------------------------------------------------------------------
class _State:
    def __init__(self, v, vb):
        self.theta_dot_rad_s, self.body_dot_rad_s = v, vb


def test_skyhook_onoff_switches_on_the_sign_of_body_times_relative_rate():
    law = SkyhookOnOff(onoff_current_a=1.0)
    assert law.current(_State(0.2, 0.5)) == 1.0
    assert law.current(_State(-0.2, 0.5)) == 0.0


def test_band_limited_fraction_stays_in_its_range_and_band():
    table = band_limited_fraction(2.0, 0.1, 0.9, seed=3)
    assert table.min() == pytest.approx(0.1) and table.max() == pytest.approx(0.9)
    import numpy as np

    spectrum = np.abs(np.fft.rfft(table - table.mean()))
    freqs = np.fft.rfftfreq(table.size, 1e-3)
    assert spectrum[freqs > 2.01].max() < 1e-9 * spectrum.max()


def test_a_nan_target_is_a_law_error_naming_the_law():
    config = default_config()
    ctl = make_controller(
        "torque-tracking", StageParts.read(config), torque=lambda t: float("nan") if t > 0.0015 else 1.0
    )
    ctl.step(sample(0, 0, 0.3), 0, 1_000_000)
    ctl.step(sample(1, 0, 0.3), 1_000_000, 1_000_000)
    with pytest.raises(LawError, match=r"law 'torque-tracking' \(built-in\) failed at t = 0\.0020 s: returned nan"):
        ctl.step(sample(2, 0, 0.3), 2_000_000, 1_000_000)


def test_the_estimator_steps_over_the_samples_period_on_the_device_clock():
    """A link's late cycle reads the newest of several samples: the estimator advances by the
    device clock's period between the samples it took (4 ms), not the host's cycle (1 ms); the
    host's finer period where the two agree within the device clock's 1 us, and where the device
    clock did not advance (a sample read again)."""
    ctl = make_controller("skyhook-add", StageParts.read(default_config()))
    periods: list[float] = []

    class Recorded:  # the controller's estimator, noting each period it is given
        def __init__(self, inner):
            self.inner = inner

        def update(self, smp, dt, *rest):
            periods.append(dt)
            self.inner.update(smp, dt, *rest)

        def __getattr__(self, name):
            return getattr(self.inner, name)

    ctl.estimator = Recorded(ctl.estimator)
    device_us = [0, 1000, 5000, 5000, 6001]
    host_dt_ns = [1_000_000, 1_000_000, 1_000_000, 1_000_000, 1_000_400]
    t_ns = 0
    for k, (dev, dt_ns) in enumerate(zip(device_us, host_dt_ns, strict=True)):
        t_ns += dt_ns
        ctl.step(RigSample(k, t_ns, dev, 0, 0, 0.0, 0, 4096), t_ns, dt_ns)
    assert periods == pytest.approx([1e-3, 1e-3, 4e-3, 1e-3, 1.0004e-3], rel=1e-12)


def mismatched(pattern="alternate"):
    config = default_config()
    config["mismatch"].update(fraction=0.1, coil_tau=0.1, pattern=pattern)
    config["controller"]["zeta"] = 0.07
    return config


def zetas(metrics):
    return [d / math.sqrt(4 * math.pi**2 + d * d) for d in metrics.log_decrements]


def test_target_damping_drop_decays_exponentially_with_mismatch_and_constant_current_does_not():
    config = mismatched()
    ctl = make_controller("target-damping", StageParts.read(config))
    record = run_drop_test(
        config, -5.0, 0.5, 6.0, rig=open_rig(assemble(config).rig), clock=VirtualClock(), controller=ctl
    )
    controlled = zetas(record.metrics)
    assert len(controlled) >= 4
    assert all(abs(z / 0.07 - 1.0) <= 0.10 for z in controlled), controlled
    constant = zetas(
        run_drop_test(config, -5.0, 0.5, 6.0, rig=open_rig(assemble(config).rig), clock=VirtualClock()).metrics
    )
    assert constant[-1] / constant[0] > 1.2, constant  # Coulomb-like hysteresis: decrement grows as it decays
    assert record.data["current_cmd_a"].max() > record.data["current_cmd_a"].min()  # the controller commanded


# --- registry errors --------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name, update, message",
    [
        ("bogus", {}, "controller.law: unknown law 'bogus'"),
        ("skyhook", {}, "controller.c_sky: law 'skyhook' needs c_sky"),
        ("groundhook", {}, "controller.c_ground"),
        ("target-damping", {}, "controller.zeta: law 'target-damping' needs zeta"),
        ("target-damping", {"zeta": 0.2}, "controller.zeta: 0.2 is outside what the damper can do"),
        ("target-damping", {"c_target": 5.0}, "controller.c_target: 5 N m s/rad is outside"),
        ("passive", {"current_a": 3.0}, "controller.current_a"),
        ("torque-tracking", {"tracking_fraction": [0.9, 0.1]}, "controller.tracking_fraction"),
    ],
)
def test_bad_controller_input_is_one_line_naming_the_key(name, update, message):
    config = default_config()
    config["controller"].update(update)
    with pytest.raises(ConfigError) as err:
        make_controller(name, StageParts.read(config))
    assert message in str(err.value) and "\n" not in str(err.value)


# --- mismatch ---------------------------------------------------------------------------------
def test_mismatch_patterns_and_overrides():
    fr = mismatch_fractions({"fraction": 0.1, "pattern": "alternate", "params": {"k": 0.05}})
    assert fr["J"] == 0.1 and fr["c1"] == 0.1 and fr["c2"] == -0.1 and fr["k"] == 0.05
    config = default_config()
    config["mismatch"].update(fraction=0.1, pattern="plus", coil_tau=0.5, encoder_counts_per_rev=1024)
    model, rig = plant_sections(config["model"], config["rig"], config["mismatch"])
    assert model["params"]["c1"] == pytest.approx(0.77)
    assert rig["coil_tau_s"] == pytest.approx(0.015)
    assert rig["encoder_counts_per_rev"] == 1024
    assert config["model"]["params"]["c1"] == 0.7  # the controller's model is untouched
    with pytest.raises(ConfigError, match=r"mismatch\.params\.q: not a bouc-wen parameter"):
        mismatch_fractions({"params": {"q": 0.1}})
