"""Bad input is one line naming what and where, exit 2, nothing written, nothing energised."""

from __future__ import annotations

import math

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from sashil.cli import main
from sashil.config.sections import SCHEMA
from sashil.engine.resolve import load_config
from sashil.errors import ConfigError


def _error_lines(capsys) -> list[str]:
    return [line for line in capsys.readouterr().err.splitlines() if "error" in line]


@pytest.mark.parametrize(
    "text, message",
    [
        (b"loop:\n  rate_hz: 500\n  rate_hz: 1000\n", "key 'rate_hz' given twice"),
        (b"rig:\n  name: caf\xe9\n", "line 2: byte 0xe9 is not UTF-8"),
        (b"loop:\n  rate_hz: .inf\n", "loop.rate_hz"),
        (b"model:\n  params: {k: 1e400}\n", "model.params.k"),
        (b"loop: [1, 2]\n", "loop"),
        (b"rtdac:\n  coil_output: da\n  coil_channel: 7\n  coil_map_output: [0, 5]\n", "rtdac.coil_channel"),
        (b"rtdac:\n  coil_map_current_a: [0.0, 1.0, 0.5]\n  coil_map_output: [0, 0.5, 1]\n", "rtdac.coil_map"),
    ],
)
def test_a_bad_config_file_is_one_line_exit_2_and_no_run_folder(tmp_path, capsys, text, message):
    config = tmp_path / "bad.yaml"
    config.write_bytes(text)
    out = tmp_path / "run"
    assert main(["run", "--config", str(config), "--duration", "0.1", "--out", str(out)]) == 2
    errors = _error_lines(capsys)
    assert len(errors) == 1 and message in errors[0] and "bad.yaml" in errors[0]
    assert not out.exists()


def test_a_port_without_a_driver_is_refused_not_simulated(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "--port", "/dev/ttyUSB0", "--duration", "0.1", "--out", str(out)]) == 2
    errors = _error_lines(capsys)
    assert len(errors) == 1 and "--port /dev/ttyUSB0" in errors[0] and "--driver serial" in errors[0]
    assert not out.exists()


@pytest.mark.parametrize("verb", [["run"], ["drop-test"], ["sweep", "--f-start", "1", "--f-stop", "1"]])
def test_an_rtdac_that_is_not_there_leaves_no_run_folder(tmp_path, capsys, verb):
    out = tmp_path / "run"
    port = f"emulated:{tmp_path / 'no-board.sock'}"
    code = main([*verb, "--driver", "rtdac", "--port", port, "--duration", "1", "--out", str(out)])
    assert code == 2
    errors = _error_lines(capsys)
    assert len(errors) == 1 and "no RT-DAC/USB2 found" in errors[0], errors
    assert not out.exists()


@pytest.mark.parametrize("verb", [["run"], ["drop-test"], ["sweep", "--f-start", "1", "--f-stop", "1"]])
def test_a_port_that_cannot_be_opened_leaves_no_run_folder(tmp_path, capsys, verb):
    out = tmp_path / "run"
    code = main(
        [*verb, "--driver", "serial", "--port", str(tmp_path / "no-such-tty"), "--duration", "1", "--out", str(out)]
    )
    assert code == 2
    errors = _error_lines(capsys)
    assert len(errors) == 1 and "no-such-tty" in errors[0] and "cannot open" in errors[0]
    assert not out.exists()


_KEYS = [(section, key) for section, spec in SCHEMA.items() for key in getattr(spec, "fields", {})]
_VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.lists(st.integers(-5, 5), max_size=3),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


@settings(max_examples=150, deadline=None)
@given(key=st.sampled_from(_KEYS), value=_VALUES)
def test_any_value_for_any_key_is_taken_or_refused_with_a_config_error(tmp_path_factory, key, value):
    section, name = key
    path = tmp_path_factory.mktemp("cfg") / "config.yaml"
    path.write_text(yaml.safe_dump({section: {name: value}}), encoding="utf-8")
    try:
        config = load_config(path)
    except ConfigError as err:
        assert f"{section}.{name}" in str(err) or section in str(err)
        return
    taken = config[section][name]
    if isinstance(taken, float):
        assert math.isfinite(taken)  # a number the rig will act on is never inf or NaN
