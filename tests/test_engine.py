"""The engine: a run assembled once into plain parts, and the one rule for where its loop runs."""

from __future__ import annotations

import json

import pytest

from sashil.config.frozen import freeze_config
from sashil.config.parts import RunSpec, read_key
from sashil.drivers import backend_reads, open_rig
from sashil.engine import assemble, loop_in_process
from sashil.engine.resolve import default_config
from sashil.runtime.clock import RealClock, VirtualClock, default_clock
from sashil.runtime.loop_process import LoopProcess


class _Plan:
    def __init__(self, values):
        self.values = values

    def spec(self):
        return self.values


def _config(**sections):
    raw = default_config()
    for name, values in sections.items():
        raw[name].update(values)
    return freeze_config(raw)


def test_a_spec_crosses_to_json_and_back_unchanged():
    spec = assemble(_config(driver={"name": "serial", "port": "/dev/ttyUSB0"}), {"kind": "run", "road": "none"})
    text = json.dumps(spec.to_json())
    back = RunSpec.from_json(json.loads(text))
    assert back == spec
    assert back.to_json() == spec.to_json()


def test_a_backend_is_handed_exactly_the_keys_it_declares():
    config = _config(driver={"name": "serial", "port": "/dev/ttyUSB0", "baud": 115200})
    spec = assemble(config)
    assert spec.rig.backend == "serial"
    assert set(spec.rig.values) == set(backend_reads("serial"))
    assert spec.rig.values["baud"] == 115200 and spec.rig.values["port"] == "/dev/ttyUSB0"
    assert spec.rig.values["counts_per_rev"] == config["rig"]["encoder_counts_per_rev"]
    rig = open_rig(spec.rig)  # built from the values alone: nothing is opened
    try:
        assert rig.baud == 115200 and rig.settings.port == "/dev/ttyUSB0"
    finally:
        rig.close()


def test_the_parts_carry_the_configs_values():
    config = _config(
        rig={"current_max_a": 0.8, "coil_tau_s": 0.02, "angle_limit_deg": 25.0},
        safety={"slew_a_per_s": 40.0},
        loop={"rate_hz": 500.0},
    )
    spec = assemble(config)
    assert spec.stage.current_max_a == 0.8 and spec.stage.rate_hz == 500.0
    assert spec.stage.coil_tau_s == 0.02  # the rig's lag: controller.coil_tau_s is unset
    assert spec.safety.angle_limit_deg == 25.0 and spec.safety.slew_a_per_s == 40.0
    assert spec.loop.rate_hz == 500.0 and spec.loop.max_lost_fraction == config["driver"]["max_lost_fraction"]
    off = assemble(_config(safety={"angle_interlock": False}))
    assert off.safety.angle_limit_deg is None


def test_the_controllers_own_coil_lag_wins_over_the_rigs():
    raw = default_config()
    raw["controller"]["coil_tau_s"] = 0.004
    assert assemble(freeze_config(raw)).stage.coil_tau_s == 0.004


def test_the_simulated_rig_runs_on_simulated_time_unless_the_config_asks_for_the_real_clock():
    assert assemble(_config()).virtual
    assert isinstance(default_clock(assemble(_config())), VirtualClock)
    real = assemble(_config(driver={"clock": "real"}))
    assert not real.virtual and isinstance(default_clock(real), RealClock)
    assert not assemble(_config(driver={"name": "serial", "port": "/dev/ttyUSB0"})).virtual


def test_a_loop_runs_in_its_own_process_on_the_real_clock_for_a_plan_that_can_be_built_there():
    spec = assemble(_config(driver={"clock": "real"}))
    real = default_clock(spec)
    assert loop_in_process(spec, real, _Plan({"kind": "drop-test"}))
    assert loop_in_process(spec, real)  # the run's own plan
    assert not loop_in_process(spec, real, _Plan(None))  # a plan with no spec stays here
    assert not loop_in_process(spec, real, object())  # nor one that cannot say
    assert not loop_in_process(spec, VirtualClock(), _Plan({"kind": "drop-test"}))
    here = assemble(_config(driver={"clock": "real"}, loop={"process": False}))
    assert not loop_in_process(here, real, _Plan({"kind": "drop-test"}))


def test_a_loop_process_is_sent_the_assembled_run_and_no_config():
    spec = assemble(_config(driver={"clock": "real"}), {"kind": "run", "road": "none"})
    job = LoopProcess(spec, 1.0).job
    assert "config" not in job
    assert RunSpec.from_json(json.loads(json.dumps(job["spec"]))) == spec
    with pytest.raises(ValueError, match="names no plan"):
        LoopProcess(assemble(_config()), 1.0)


def test_a_missing_key_is_named():
    with pytest.raises(KeyError, match=r"driver\.nope"):
        read_key(_config(), "driver.nope")


def test_the_engine_emits_a_runs_start_and_its_stop_with_the_experiments_analysis():
    """engine.run hands the verb's subscribers the run's start (the config its folder records, the
    assembled run, the versions) before the loop, its progress, and its stop after it: the loop's summary keys,
    what ended it and the experiment's analysis (here a drop's, on simulated time)."""
    from sashil.lab._drop_test import run_drop_test
    from sashil.writer.documents import Documents, versions

    config = _config()
    seen: list[tuple[str, dict]] = []
    documents = Documents([lambda kind, fields: seen.append((kind, dict(fields)))])
    record = run_drop_test(
        config,
        -5.0,
        0.5,
        0.3,
        documents=documents,
        name="i0.500A",
        recorded_config=config,
        describe=lambda record: setattr(record, "entry", {"peaks": len(record.metrics.peaks_deg)}),
    )
    assert [kind for kind, _ in seen] == ["start", "progress", "progress", "stop"]
    start, stop = seen[0][1], seen[-1][1]
    assert start["run"] == "i0.500A" and start["config"] is config and start["versions"] == versions()
    assert isinstance(start["spec"], RunSpec) and start["spec"].rig.backend == "sim" and start["spec"].virtual
    # the stop document carries the drop's record itself: what the verb reads is what the writer reads
    assert stop["run"] == "i0.500A" and stop["record"] is record and record.error is None
    assert record.summary["exit_status"] == "ok" and record.summary["timing"]["cycles"] > 0
    assert record.entry == {"peaks": len(record.metrics.peaks_deg)} and record.data["time_s"].size > 0
