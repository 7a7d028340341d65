"""The typed parts a run is built from: each a whole section read strictly, the same keys as the
schema's section, carried to a loop process as JSON and back unchanged."""

from __future__ import annotations

import json
from dataclasses import fields

import pytest

from sashil.config.frozen import freeze_config, thaw
from sashil.config.parts import RigParts, RunSpec, StageParts
from sashil.config.rtdac_section import RTDAC
from sashil.config.section_parts import (
    CalibratePart,
    ControllerPart,
    LoopRtPart,
    MismatchPart,
    ModelPart,
    RigPart,
    RtdacPart,
)
from sashil.config.sections import CALIBRATE, CONTROLLER, LOOP, MISMATCH, MODEL, RIG
from sashil.drivers import rig_parts
from sashil.drivers.mismatch import plant_parts
from sashil.engine import assemble
from sashil.engine.resolve import default_config
from sashil.errors import ConfigError


def _names(part) -> set[str]:
    return {field.name for field in fields(part)}


@pytest.mark.parametrize(
    ("part", "section"),
    [
        (ModelPart, MODEL),
        (RigPart, RIG),
        (MismatchPart, MISMATCH),
        (RtdacPart, RTDAC),
        (CalibratePart, CALIBRATE),
        (LoopRtPart, LOOP.fields["rt"]),
    ],
)
def test_a_part_has_the_keys_of_its_section(part, section):
    assert _names(part) == set(section.fields)


def test_the_controller_part_has_the_controllers_keys_and_the_laws_parameters_beside_them():
    assert _names(ControllerPart) - {"params"} == set(CONTROLLER.fields)
    section = {**default_config()["controller"], "law": "skyhook", "c_sky": 2.0}
    part = ControllerPart.read(section)
    assert part.law == "skyhook" and dict(part.params) == {"current_a": 0.0, "c_sky": 2.0}  # passive's, skyhook's
    assert part.section() == section


def test_a_missing_or_mistyped_key_is_one_error_naming_it():
    rig = dict(default_config()["rig"])
    del rig["coil_tau_s"]
    with pytest.raises(ConfigError, match=r"^rig\.coil_tau_s: missing from the resolved config$"):
        RigPart.read(rig)
    with pytest.raises(ConfigError, match=r"^rig\.encoder_counts_per_rev: expected <class 'int'>, got 4096\.5$"):
        RigPart.read({**default_config()["rig"], "encoder_counts_per_rev": 4096.5})
    with pytest.raises(ConfigError, match=r"^rtdac\.coil_output: expected"):
        RtdacPart.read({**default_config()["rtdac"], "coil_output": "relay"})


def test_the_stage_reads_strictly():
    raw = default_config()
    del raw["controller"]["tune_ramp_s"]
    with pytest.raises(ConfigError, match=r"^controller\.tune_ramp_s: missing"):
        StageParts.read(raw)
    raw = default_config()
    raw["controller"]["coil_tau_s"] = 0.02
    stage = StageParts.read(raw)
    assert stage.coil_tau_s == 0.02 and stage.controller.coil_tau_s == 0.02  # the controller's own lag first
    raw["controller"]["coil_tau_s"] = None
    assert StageParts.read(raw).coil_tau_s == raw["rig"]["coil_tau_s"]


def test_a_backend_gets_its_whole_sections_typed_and_its_keys_as_values():
    config = freeze_config(default_config())
    sim = rig_parts(config, "sim")
    assert (sim.model, sim.rig) == (ModelPart.read(config["model"]), RigPart.read(config["rig"]))
    assert sim.rtdac is None and dict(sim.values) == {}
    rtdac = rig_parts(config, "rtdac")
    assert rtdac.rtdac == RtdacPart.read(config["rtdac"]) and rtdac.model is None
    assert rtdac.values["current_max_a"] == config["rig"]["current_max_a"]
    with pytest.raises(ConfigError, match="reads the whole section 'rig' as 'plant'"):
        RigParts.read(config, "mine", {"plant": "rig"})


@pytest.mark.parametrize("backend", ["sim", "rtdac"])
def test_a_spec_with_typed_parts_crosses_to_json_and_back_unchanged(backend):
    raw = default_config()
    raw["driver"]["name"] = backend
    raw["controller"].update({"law": "skyhook", "c_sky": 1.5})
    spec = assemble(freeze_config(raw), {"kind": "run", "road": "none"})
    back = RunSpec.from_json(json.loads(json.dumps(spec.to_json())))
    assert back == spec
    assert back.stage.controller.params == {"current_a": 0.0, "c_sky": 1.5} and back.stage.model.name == "bouc-wen"


def test_the_plant_is_the_model_after_the_mismatch():
    raw = default_config()
    raw["mismatch"].update(
        {"fraction": 0.1, "pattern": "plus", "params": {"k": -0.2}, "coil_tau": 0.5, "encoder_counts_per_rev": 1024}
    )
    config = freeze_config(raw)
    model, rig = plant_parts(
        ModelPart.read(config["model"]), RigPart.read(config["rig"]), MismatchPart.read(config["mismatch"])
    )
    params = config["model"]["params"]
    assert model.params["c1"] == pytest.approx(params["c1"] * 1.1)  # the pattern's +10 %
    assert model.params["k"] == pytest.approx(params["k"] * 0.8)  # its own fraction over the pattern
    assert rig.coil_tau_s == pytest.approx(config["rig"]["coil_tau_s"] * 1.5)
    assert rig.encoder_counts_per_rev == 1024 and rig.angle_noise_rad == config["rig"]["angle_noise_rad"]
    unchanged, same = plant_parts(ModelPart.read(config["model"]), RigPart.read(config["rig"]), None)
    assert thaw(unchanged.params) == thaw(params) and same == RigPart.read(config["rig"])
