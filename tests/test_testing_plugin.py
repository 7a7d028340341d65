"""sashil.testing: the simulated rig a lab's CI runs its law on, the law contract check and the
comparisons, all on the virtual clock with seeded noise."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from sashil.control import Law, Param
from sashil.control.laws import Skyhook
from sashil.errors import ConfigError
from sashil.testing import SimRig, check_law, compare_with_passive, run_law


class Raising(Law):
    name = "raising"

    def torque(self, state):
        if state.time_s > 0.5:
            raise ZeroDivisionError("the law divided by zero")
        return 0.0


class ReturnsNan(Law):
    name = "returns-nan"

    def torque(self, state):
        return math.nan if state.time_s > 1.0 else 0.1


class ReturnsInfinity(Law):
    name = "returns-infinity"

    def current(self, state):
        return math.inf if state.time_s > 1.0 else 0.5


class KeepsStateInItsClass(Law):
    """Counts its calls in the class, which outlives a run: the second run starts elsewhere."""

    name = "keeps-state"
    calls = 0

    def torque(self, state):
        type(self).calls += 1
        return 1e-4 * (self.calls % 1000)


class UnseededRandom(Law):
    name = "unseeded-random"

    def current(self, state):
        return random.random()  # an unseeded generator: the fault under test


class ManualClock:
    """An integer-ns clock that only the code under test moves."""

    def __init__(self) -> None:
        self.now_ns = 0

    def __call__(self) -> int:
        return self.now_ns


CLOCK = ManualClock()


class Slow(Law):
    """Takes 500 µs of CLOCK per call (the budget is checked on the clock it is given)."""

    name = "slow"

    def torque(self, state):
        CLOCK.now_ns += 500_000
        return 0.0


class Undocumented(Law):
    name = "undocumented"
    gain = Param(1.0)

    def torque(self, state):
        return self.gain * state.body_dot_rad_s


def _only_fault(law, **kwargs):
    report = check_law(law, **kwargs)
    assert len(report.faults) == 1, report.faults
    assert report.faults[0].startswith(f"{law.name}: ")
    return report, report.faults[0]


def test_a_law_that_raises_is_one_line_naming_it_and_ends_at_zero_amps():
    report, fault = _only_fault(Raising)
    assert "raised ZeroDivisionError: the law divided by zero" in fault and "t = 0.5" in fault
    assert report.run is not None and report.run.data["current_cmd_a"][-1] == 0.0


def test_a_law_that_returns_nan_is_caught():
    report, fault = _only_fault(ReturnsNan)
    assert "returned nan" in fault and "t = 1.0" in fault
    assert report.run is not None and report.run.data["current_cmd_a"][-1] == 0.0


def test_a_current_law_that_returns_an_infinity_is_caught():
    _, fault = _only_fault(ReturnsInfinity)
    assert "returned inf" in fault


def test_a_law_that_keeps_state_in_its_class_is_not_deterministic():
    _, fault = _only_fault(KeepsStateInItsClass)
    assert "not deterministic under seed 0" in fault


def test_a_law_on_an_unseeded_random_generator_is_not_deterministic():
    _, fault = _only_fault(UnseededRandom)
    assert "not deterministic" in fault


def test_a_slow_law_is_over_its_budget_on_the_clock_it_is_given():
    report, fault = _only_fault(Slow, timer=CLOCK, budget_us=100.0)
    assert "compute per cycle p99 500.0 µs" in fault and "budget of 100 µs" in fault
    assert report.compute_us["max"] == pytest.approx(500.0)


def test_an_undeclared_parameter_and_a_missing_output_are_faults_before_any_run():
    report = check_law(Undocumented)
    assert report.run is None
    assert report.faults == (
        "undocumented: parameter gain has no doc (what it means, for `sashil laws` and the config reference)",
        "undocumented: parameter gain has no bound (low= or high=): any number would be accepted",
    )


def test_a_parameter_the_law_refuses_is_a_fault_naming_the_key():
    _, fault = _only_fault(Skyhook, params={"c_sky": -1.0})
    assert fault.startswith("skyhook: parameters:") and "controller.c_sky" in fault


def test_a_good_law_meets_the_contract_within_its_budget():
    report = check_law(Skyhook, params={"c_sky": 2.0}, timer=CLOCK)  # a clock the law leaves alone: 0 µs
    assert report.ok, report.faults
    assert report.compute_us == {"p50": 0.0, "p99": 0.0, "max": 0.0}
    assert report.run is not None and report.run.summary["exit_status"] == "ok"
    assert str(report) == "skyhook: meets the contract (compute p99 0.0 µs)"


def test_run_law_gives_the_run_load_run_gives_deterministic_under_its_seed(tmp_path):
    rig = SimRig(seed=3, out=tmp_path)
    first = run_law(Skyhook, road="sine:1.2:1", duration_s=3.0, params={"c_sky": 2.0}, rig=rig)
    again = rig.run(Skyhook, road="sine:1.2:1", duration_s=3.0, c_sky=2.0)
    other = rig.with_seed(4).run(Skyhook, road="sine:1.2:1", duration_s=3.0, c_sky=2.0)
    assert first.path.parent == tmp_path and first.path != again.path
    assert first.summary["exit_status"] == "ok" and first.config["driver"]["clock"] == "virtual"
    assert first.config["controller"]["c_sky"] == 2.0 and first.config["rig"]["noise_seed"] == 3
    assert first.data["time_s"].size == 3001  # 3000 cycles at 1 kHz, then the shutdown's row at 0 A
    np.testing.assert_array_equal(first.data["current_cmd_a"], again.data["current_cmd_a"])
    assert not np.array_equal(first.data["current_cmd_a"], other.data["current_cmd_a"])
    assert set(first.metrics) >= {"rms_accel_rad_s2", "rms_theta_deg", "peak_current_a", "coil_energy_j"}


def test_the_damper_of_the_labs_choice_reaches_plant_and_observer(tmp_path):
    run = SimRig(damper={"c2": 3.0}, out=tmp_path).run(Skyhook, duration_s=2.5, c_sky=1.0)
    assert run.config["model"]["params"]["c2"] == 3.0


def test_bad_input_is_a_config_error_before_anything_runs(tmp_path):
    with pytest.raises(ConfigError, match="road"):
        run_law(Skyhook, road="washboard:3", params={"c_sky": 1.0}, rig=SimRig(out=tmp_path))
    assert not any(tmp_path.iterdir())


def test_the_fixture_is_a_seeded_rig_writing_into_the_tests_folder(sashil_rig, tmp_path):
    assert sashil_rig.seed == 0 and sashil_rig.out is not None and sashil_rig.out.parent == tmp_path


def test_comparison_against_constant_currents_and_the_bound(tmp_path):
    rig = SimRig(out=tmp_path, sets={"compare.settle_s": 1.0})
    run = rig.run(Skyhook, road="iso8608:C", duration_s=4.0, c_sky=2.0)
    comparison = compare_with_passive(run, currents_a=[0.0, 1.0])
    assert comparison.law == "skyhook"
    assert comparison.comfort_current_a in (0.0, 1.0) and comparison.travel_current_a in (0.0, 1.0)
    expected = 100.0 * (1.0 - run.metrics["rms_accel_rad_s2"] / comparison.comfort_rms_accel_rad_s2)
    assert comparison.comfort_gain_pct == pytest.approx(expected)
    assert comparison.bound_gain_pct > 0.0
    assert comparison.share_of_bound_pct == pytest.approx(100.0 * expected / comparison.bound_gain_pct)
    passive = rig.run("passive", road="iso8608:C", duration_s=4.0, current_a=comparison.comfort_current_a)
    assert passive.metrics["rms_accel_rad_s2"] == pytest.approx(comparison.comfort_rms_accel_rad_s2)
