"""The built-in plans and stages stand below the engine and the runtime finds them by name; the
entry points serve a lab's own plans and stages."""

from __future__ import annotations

import math

import pytest

from sashil.config.parts import RunSpec
from sashil.drivers import rig_parts
from sashil.drivers.sim import SimulatedRig
from sashil.engine import assemble
from sashil.engine.resolve import ConfigSource, default_config, resolve
from sashil.engine.sashil_run import PLAN, READS
from sashil.errors import ConfigError
from sashil.lab._drop_test import READS as DROP_READS
from sashil.plans import BUILT_IN, BUILT_IN_STAGES
from sashil.plans import run as run_plan
from sashil.plans.calibration_step import RoadChirp, Step, StepStage
from sashil.plans.drop import CONFIG_LAW, DropTestPlan, drop_in_loop, plan_drop
from sashil.plans.stages import stage_class
from sashil.plugins import PLANS_GROUP, STAGES_GROUP, entry_point_table
from sashil.roads.option import RoadStage
from sashil.runtime.worker import plan_builder


def test_the_runtime_builds_sashil_runs_plan_from_the_package_not_an_entry_point():
    assert plan_builder("run") is run_plan.build is BUILT_IN["run"]
    assert "run" not in entry_point_table(PLANS_GROUP)  # the entry points are for the plans not built in
    assert plan_builder("sweep") is BUILT_IN["sweep"]
    assert plan_builder("drop-test") is drop_in_loop is BUILT_IN["drop-test"]
    assert "drop-test" not in entry_point_table(PLANS_GROUP)
    with pytest.raises(ConfigError, match=r"cannot run a plan of kind 'nope' \(it runs run, sweep, drop-test"):
        plan_builder("nope")


def test_the_run_plan_is_the_law_on_the_runs_road_for_its_duration():
    config = resolve(ConfigSource(sets=("run.road=sine:2", "controller.law=skyhook", "controller.c_sky=2")), "run")
    spec = assemble(config, PLAN, READS)
    stage, label, road_text = run_plan.build(spec, None, print)
    assert isinstance(stage, RoadStage) and label == "skyhook" and road_text == "sine 2 Hz, 1 deg"
    assert spec.plan == {"kind": "run"} and spec.options["road"] == "sine:2"


def test_the_calibration_step_is_a_built_in_stage_found_by_name_not_an_entry_point():
    assert stage_class("calibration-step") is StepStage is BUILT_IN_STAGES["calibration-step"]
    assert "calibration-step" not in entry_point_table(STAGES_GROUP)


def test_an_unknown_stage_kind_is_one_line_naming_the_known_ones():
    with pytest.raises(ConfigError) as caught:
        stage_class("nope")
    message = str(caught.value)
    assert message.startswith("no stage of kind 'nope'") and "(known: calibration-step" in message
    assert "\n" not in message


def _in_loop_process(run: RunSpec, plan: DropTestPlan) -> RunSpec:
    """The run as a loop process reads it: the plan's spec in the JSON job, read again."""
    return RunSpec.from_json(run.with_plan(plan.spec()).to_json())


def test_a_drop_and_its_calibration_step_are_built_again_in_the_loop_from_the_three_values_and_the_step():
    run = assemble(default_config(), reads=DROP_READS)
    chirp = RoadChirp(math.radians(1.0), 0.8, 3.0, 5.5, 1.0)
    step = Step("03-fit-road-5deg-0.50A", "fit", -5.0, 0.5, 6.0, chirp)
    plan = plan_drop(run, -5.0, 0.5, 6.0, controller=StepStage(step))
    spec = plan.spec()
    assert spec == {
        "kind": "drop-test",
        "theta0_deg": -5.0,
        "current_a": 0.5,
        "duration_s": 6.0,
        "controller": {"kind": "calibration-step", "step": {**vars(step), "road": vars(chirp)}},
    }
    rig = SimulatedRig.from_parts(rig_parts(default_config(), "sim"))
    twin, label, road_text = drop_in_loop(_in_loop_process(run, plan), rig, print)
    assert (label, road_text) == ("passive", "none")
    assert isinstance(twin.controller, StepStage) and twin.controller.step_def == step
    drop = run.options  # the hold's values in the config's degrees, the plan's in radians
    assert twin.theta0_rad == math.radians(-5.0) and twin.current_a == 0.5 and twin.duration_s == 6.0
    assert twin.hold_tolerance_rad == math.radians(drop["hold_tolerance_deg"])
    assert twin.release_threshold_rad == math.radians(drop["release_threshold_deg"])
    assert (twin.hold_time_s, twin.hold_timeout_s) == (drop["hold_time_s"], drop["hold_timeout_s"])
    assert twin.resolution == 2 * math.pi / run.stage.counts_per_rev
    # the simulated rig plays the operator: it lets go 0.1 s after the hold time (0.3 s at the least)
    assert twin.known_release_after_s == max(drop["hold_time_s"] + 0.1, 0.3)
    twin.start_ns = 1_000
    plan.absorb(twin.facts())  # what the rig decided comes back with what the plan saw
    assert plan.known_release_after_s == twin.known_release_after_s and plan.pseudo_terminal is None
    assert plan.known_release_ns == 1_000 + round(twin.known_release_after_s * 1e9)


def test_a_drop_under_the_configs_law_or_none_crosses_as_its_name_or_nothing():
    run = assemble(default_config(), reads=DROP_READS)
    assert plan_drop(run, -5.0, 0.0, 1.0).spec()["controller"] == CONFIG_LAW
    assert plan_drop(run, -5.0, 0.0, 1.0, controller=None).spec()["controller"] is None

    class NoSpec:  # a stage that cannot be built elsewhere keeps its drop in the session's process
        signal_names = ()

    assert plan_drop(run, -5.0, 0.0, 1.0, controller=NoSpec()).spec() is None


def test_a_drop_handing_over_to_an_unknown_stage_is_refused_in_the_loop_in_one_line():
    run = assemble(default_config(), reads=DROP_READS)
    spec = {"kind": "drop-test", "theta0_deg": -5.0, "current_a": 0.0, "duration_s": 1.0, "controller": {"kind": "x"}}
    rig = SimulatedRig.from_parts(rig_parts(default_config(), "sim"))
    with pytest.raises(ConfigError, match=r"^no stage of kind 'x' is built in or registered \(known: calibration-step"):
        drop_in_loop(run.with_plan(spec), rig, print)
