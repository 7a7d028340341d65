"""The resolution composes a config's steps once and checks its law once, on the whole config: an
error names the step that set the failing key, and a value a later step replaces is never checked."""

from __future__ import annotations

import pytest
import yaml

from sashil.config.compose import compose
from sashil.engine.resolve import ConfigSource, Option, resolve
from sashil.errors import ConfigError
from sashil.models.registry import RIG_MODELS


def _file(tmp_path, controller):
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump({"controller": controller}))
    return path


def test_compose_keeps_the_step_that_set_each_controller_key_last(tmp_path):
    path = _file(tmp_path, {"law": "skyhook", "c_sky": 2.0})
    source = ConfigSource(
        config=path,
        controller="skyhook-add",
        sets=("controller.c_sky=3",),
        options=(Option("--current", "controller.onoff_current_a", 0.4),),
    )
    composed = compose(source, "run", RIG_MODELS)
    assert composed.steps["controller.law"] == "--set"  # --controller, composed with the --set keys
    assert composed.steps["controller.c_sky"] == "--set"
    assert composed.steps["controller.onoff_current_a"] == "--current"
    assert composed.steps["controller.estimator"] == str(path)  # the file's section, defaults filled
    assert composed.config["controller"]["c_sky"] == 3
    assert composed.replaced == frozenset()  # c_sky was set again alongside the new law


def test_a_law_error_names_the_step_of_the_failing_key_not_the_last_step(tmp_path):
    path = _file(tmp_path, {"law": "skyhook", "c_sky": -1.0})
    with pytest.raises(ConfigError, match=rf"^{path}: controller.c_sky: expected a number > 0"):
        resolve(
            ConfigSource(config=path, sets=("loop.rate_hz=500",), options=(Option("--rate", "loop.rate_hz", 400.0),)),
            "run",
        )
    with pytest.raises(ConfigError, match=r"^--set: controller.c_sky: expected a number > 0"):
        resolve(ConfigSource(controller="skyhook", sets=("controller.c_sky=0", "loop.rate_hz=500")), "run")
    with pytest.raises(ConfigError, match=r"^--current: controller.current_a: "):
        resolve(ConfigSource(options=(Option("--current", "controller.current_a", -1.0),)), "run")
    with pytest.raises(ConfigError, match=r"^--controller: controller.law: unknown law 'nope'"):
        resolve(ConfigSource(controller="nope", options=(Option("--duration", "run.duration_s", 2.0),)), "run")


def test_a_parameter_the_law_does_not_declare_names_the_step_that_set_it(tmp_path):
    path = _file(tmp_path, {"law": "passive"})
    with pytest.raises(ConfigError, match=r"^--tune: controller.c_sky: law 'passive' has no parameter c_sky"):
        resolve(ConfigSource(config=path, options=(Option("--tune", "controller.c_sky", 2.0),)), "run")


def test_the_law_is_checked_once_on_the_whole_config(tmp_path):
    """A file's bad value that a later step replaces is never checked on its own."""
    path = _file(tmp_path, {"law": "skyhook", "c_sky": -1.0})
    config = resolve(ConfigSource(config=path, sets=("controller.c_sky=2",)), "run")
    assert config["controller"]["c_sky"] == 2.0
    switched = resolve(ConfigSource(config=path, controller="passive"), "run")
    assert "c_sky" not in switched["controller"]  # the replaced law's parameter went with it
    assert switched["controller"]["current_a"] == 0.0  # the new law's default, filled in


def test_a_replaced_parameter_set_again_by_a_later_step_is_kept_and_checked(tmp_path):
    path = _file(tmp_path, {"law": "skyhook", "c_sky": 2.0})
    with pytest.raises(ConfigError, match=r"^--sky: controller.c_sky: law 'passive' has no parameter c_sky"):
        resolve(
            ConfigSource(config=path, controller="passive", options=(Option("--sky", "controller.c_sky", 3.0),)), "run"
        )
    onoff = _file(tmp_path, {"law": "skyhook-add", "onoff_current_a": 0.4})
    kept = resolve(
        ConfigSource(
            config=onoff, controller="skyhook-onoff", options=(Option("--on", "controller.onoff_current_a", 0.3),)
        ),
        "run",
    )
    assert kept["controller"]["law"] == "skyhook-onoff" and kept["controller"]["onoff_current_a"] == 0.3
