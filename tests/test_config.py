"""Config loading: defaults, the shipped sim.yaml, and one-line errors naming file and key."""

from __future__ import annotations

from pathlib import Path

import pytest

from sashil.config import load_params
from sashil.engine.resolve import default_config, load_config
from sashil.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def test_shipped_sim_yaml_is_the_default_config():
    assert load_config(ROOT / "configs" / "sim.yaml") == default_config()


def test_default_config_has_the_seed_parameters():
    params = default_config()["model"]["params"]
    assert params == {
        "J": 1.0,
        "k": 109.0,
        "c1": 0.7,
        "c2": 1.5,
        "alpha1": 1.0,
        "alpha2": 1.0,
        "beta": 873.0,
        "gamma": 1.0,
        "delta": 700.0,
        "n": 0.099,
    }
    assert default_config()["loop"]["rate_hz"] == 1000.0
    assert default_config()["driver"]["name"] == "sim"


def _write(tmp_path, text: str) -> Path:
    path = tmp_path / "lab.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "text,message",
    [
        ("rig:\n  coil_tau: 0.01\n", "lab.yaml: rig.coil_tau: unknown key"),
        ("rgi: {}\n", "lab.yaml: rgi: unknown key"),
        ("rig:\n  coil_tau_s: fast\n", "lab.yaml: rig.coil_tau_s: expected a number >= 0 and <= 1, got 'fast'"),
        ("rig:\n  coil_tau_s: -1\n", "lab.yaml: rig.coil_tau_s: expected a number >= 0"),
        ("rig:\n  encoder_counts_per_rev: 4096.5\n", "lab.yaml: rig.encoder_counts_per_rev: expected an integer"),
        ("loop:\n  rate_hz: 0\n", "lab.yaml: loop.rate_hz: expected a number > 0"),
        ("driver:\n  name: usb\n", "lab.yaml: driver.name: expected one of 'can', 'rtdac', 'serial', 'sim', got 'usb'"),
        ("model:\n  params:\n    kk: 1\n", "lab.yaml: model.params.kk: not a bouc-wen parameter"),
        ("model:\n  params:\n    n: -1\n", "lab.yaml: model.params.n: expected a number > 0"),
        ("model:\n  params:\n    k: true\n", "lab.yaml: model.params.k: expected a number, got True"),
        ("- a\n- b\n", "lab.yaml: expected a mapping of keys, got list"),
        ("rig: [1, 2\n", "lab.yaml: line"),
        ("rig:\n  coil_tau_s: .nan\n", "lab.yaml: rig.coil_tau_s: expected a number"),
    ],
)
def test_bad_config_gives_one_line_naming_file_and_key(tmp_path, text, message):
    with pytest.raises(ConfigError) as info:
        load_config(_write(tmp_path, text))
    text_of_error = str(info.value)
    assert message in text_of_error
    assert "\n" not in text_of_error


def test_missing_config_file(tmp_path):
    with pytest.raises(ConfigError, match=r"nope\.yaml: no such file"):
        load_config(tmp_path / "nope.yaml")


def test_partial_config_keeps_other_defaults(tmp_path):
    config = load_config(_write(tmp_path, "rig:\n  coil_tau_s: 0.02\nmodel:\n  params:\n    k: 120\n"))
    assert config["rig"]["coil_tau_s"] == 0.02
    assert config["rig"]["current_max_a"] == 1.0
    assert config["model"]["params"]["k"] == 120.0
    assert config["model"]["params"]["c1"] == 0.7


def test_a_config_file_may_hold_another_model_with_its_own_parameters(tmp_path):
    """The schema's defaults are the Bouc-Wen seed's: a Dahl section keeps the symbols it names,
    and a Bouc-Wen symbol under it is refused by name."""
    dahl = "model:\n  name: dahl\n  params: {J: 1, k: 2, c1: 3, c2: 4, kwa: 5, kwb: 6, rho: 7}\n"
    config = load_config(_write(tmp_path, dahl))
    assert config["model"] == {
        "name": "dahl",
        "params": {"J": 1.0, "k": 2.0, "c1": 3.0, "c2": 4.0, "kwa": 5.0, "kwb": 6.0, "rho": 7.0},
    }
    with pytest.raises(ConfigError, match=r"lab\.yaml: model\.params\.alpha1: not a dahl parameter"):
        load_config(_write(tmp_path, dahl.replace("rho: 7", "rho: 7, alpha1: 1")))
    with pytest.raises(ConfigError, match=r"lab\.yaml: model\.params: missing kwb, rho for model dahl"):
        load_config(_write(tmp_path, dahl.replace(", kwb: 6, rho: 7", "")))


def test_parameter_file_roundtrip_and_include(tmp_path):
    params = tmp_path / "damper.yaml"
    params.write_text(
        "model: bouc-wen\nparams: {J: 1.0, k: 100.0, c1: 0.5, c2: 1.0, alpha1: 2.0, alpha2: 1.0,\n"
        "         beta: 800.0, gamma: 2.0, delta: 600.0, n: 0.2}\nfit: {rms_rad: 0.001}\n"
    )
    section = load_params(params)
    assert section["params"]["k"] == 100.0
    config = load_config(_write(tmp_path, "include_params: damper.yaml\n"))
    assert config["model"]["params"]["delta"] == 600.0


def test_parameter_file_must_be_complete(tmp_path):
    params = tmp_path / "damper.yaml"
    params.write_text("model: bouc-wen\nparams: {k: 100.0}\n")
    with pytest.raises(ConfigError, match=r"damper\.yaml: params: missing J, c1"):
        load_params(params)
