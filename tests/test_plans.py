"""The built-in plans stand below the engine and the runtime finds them by name; the entry points
serve a lab's own plans."""

from __future__ import annotations

import pytest

from sashil.engine import assemble
from sashil.engine.resolve import ConfigSource, resolve
from sashil.engine.sashil_run import PLAN, READS
from sashil.errors import ConfigError
from sashil.lab._drop_test import drop_in_loop
from sashil.plans import BUILT_IN
from sashil.plans import run as run_plan
from sashil.plugins import PLANS_GROUP, entry_point_table
from sashil.roads.option import RoadStage
from sashil.runtime.worker import plan_builder


def test_the_runtime_builds_sashil_runs_plan_from_the_package_not_an_entry_point():
    assert plan_builder("run") is run_plan.build is BUILT_IN["run"]
    assert "run" not in entry_point_table(PLANS_GROUP)  # the entry points are for the plans not built in
    assert plan_builder("sweep") is BUILT_IN["sweep"]
    assert plan_builder("drop-test") is drop_in_loop  # an entry point
    with pytest.raises(ConfigError, match=r"cannot run a plan of kind 'nope' \(it runs run, sweep, drop-test"):
        plan_builder("nope")


def test_the_run_plan_is_the_law_on_the_runs_road_for_its_duration():
    config = resolve(ConfigSource(sets=("run.road=sine:2", "controller.law=skyhook", "controller.c_sky=2")), "run")
    spec = assemble(config, PLAN, READS)
    stage, label, road_text = run_plan.build(spec, None, print)
    assert isinstance(stage, RoadStage) and label == "skyhook" and road_text == "sine 2 Hz, 1 deg"
    assert spec.plan == {"kind": "run"} and spec.options["road"] == "sine:2"
