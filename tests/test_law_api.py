"""The public law API: Param and Law, finding a law, its parameters as config keys, and a law that
misbehaves ending the run at 0 A."""

from __future__ import annotations

import json
import math
import textwrap

import pytest

from sashil.cli import main
from sashil.config.parts import StageParts
from sashil.control import Law, LawState, Param
from sashil.control.law_registry import find_law, law_names
from sashil.control.registry import make_controller
from sashil.drivers.interface import RigSample
from sashil.engine.resolve import apply_overrides, default_config, load_config
from sashil.errors import ConfigError, LawError

BUILT_INS = {
    "passive",
    "target-damping",
    "skyhook",
    "skyhook-onoff",
    "skyhook-add",
    "groundhook",
    "torque-tracking",
    "clipped-optimal",
    "lqr-clipped",
    "pdd",
    "groundhook-hybrid",
    "preview-optimal",
}


class Soft(Law):
    name = "soft"
    c_sky = Param(1.0, unit="N m s/rad", low=0.0, doc="sky damping")
    gain = Param(low=0.0, low_open=True, high=5.0)

    def parameters_changed(self) -> None:
        self.product = self.c_sky * self.gain

    def torque(self, state):
        return self.product * state.body_dot_rad_s


def state(**values) -> LawState:
    s = LawState()
    for key, value in values.items():
        setattr(s, key, value)
    return s


# --- Param and Law ------------------------------------------------------------------------------
def test_parameters_take_defaults_are_checked_and_derive_in_the_hook():
    law = Soft(gain=2.0)
    assert law.c_sky == 1.0 and law.gain == 2.0 and law.product == 2.0
    assert law.torque(state(body_dot_rad_s=0.5)) == 1.0
    assert Soft.output_kind() == "torque" and list(Soft.params()) == ["c_sky", "gain"]
    law.set_parameters({"c_sky": 3.0})  # a later change re-runs parameters_changed
    assert law.product == 6.0
    assert isinstance(Soft.c_sky, Param) and Soft.c_sky.unit == "N m s/rad"


@pytest.mark.parametrize(
    "params, message",
    [
        (
            {},
            "controller.gain: law 'soft' needs gain: add --set controller.gain=VALUE or set it in the config's controller: section",
        ),
        ({"gain": 0.0}, "controller.gain: expected a number > 0 and <= 5, got 0.0"),
        ({"gain": 6}, "controller.gain: expected a number > 0 and <= 5, got 6"),
        ({"gain": "big"}, "controller.gain: expected a number > 0 and <= 5, got 'big'"),
        ({"gain": 1.0, "c_sky": -1}, "controller.c_sky: expected a number >= 0, got -1"),
        (
            {"gain": 1.0, "c_skyy": 1},
            "controller.c_skyy: law 'soft' has no parameter c_skyy (its parameters: c_sky, gain)",
        ),
    ],
)
def test_bad_parameters_are_one_line_naming_controller_key(params, message):
    with pytest.raises(ConfigError) as err:
        Soft(**params)
    assert str(err.value) == message


def test_output_kind_is_the_one_output_a_class_implements():
    class Both(Law):
        name = "both"

        def torque(self, state):
            return 0.0

        def current(self, state):
            return 0.0

    class Neither(Law):
        name = "neither"

    class Amps(Law):
        name = "amps"

        def current(self, state):
            return 0.5

    assert (Both.output_kind(), Neither.output_kind(), Amps.output_kind()) == ("", "", "current")


# --- finding a law ------------------------------------------------------------------------------
def test_the_built_in_laws_come_through_the_entry_point_group():
    assert BUILT_INS <= set(law_names())
    for name in BUILT_INS:
        entry = find_law(name)
        assert entry.cls.name == name and entry.origin == "built-in"


def write_law(tmp_path, body: str, name: str = "mylaw.py"):
    path = tmp_path / name
    path.write_text("from sashil.control import Law, Param\n\n" + textwrap.dedent(body))
    return path


def test_a_law_from_a_file_and_from_a_module(tmp_path, monkeypatch):
    path = write_law(
        tmp_path,
        """
        class Mine(Law):
            name = "mine"
            c = Param(2.0, low=0.0)

            def torque(self, state):
                return self.c * state.theta_dot_rad_s
        """,
    )
    entry = find_law(f"{path}:Mine")
    assert entry.cls.name == "mine" and entry.origin == f"file {path}"
    monkeypatch.syspath_prepend(str(tmp_path))
    assert find_law("mylaw:Mine").origin == "module mylaw"


@pytest.mark.parametrize(
    "body, spec, message",
    [
        ("", "bogus", "controller.law: unknown law 'bogus' (known: "),
        (
            "raise RuntimeError('no numpy here\\nsecond line')\n",
            "{path}:X",
            "does not import: RuntimeError: no numpy here",
        ),
        ("import no_such_module_xyz\n", "{path}:X", "No module named 'no_such_module_xyz'"),
        ("class X:\n    name = 'x'\n", "{path}:X", "is not a sashil.control.Law"),
        ("class X(Law):\n    name = 'x'\n", "{path}:X", "implements neither torque(state) nor current(state)"),
        ("", "{path}:Missing", "has no class Missing"),
        (
            "class X(Law):\n    name = 'skyhook'\n    def torque(self, s):\n        return 0.0\n",
            "{path}:X",
            "claims the name 'skyhook', which sashil.control.laws:Skyhook (built-in) already has",
        ),
        (
            "class X(Law):\n    name = 'x'\n    inverse = Param(1.0)\n    def torque(self, s):\n        return 0.0\n",
            "{path}:X",
            "declares a parameter 'inverse', which is the controller's own key controller.inverse",
        ),
        (
            "class X(Law):\n    name = 'x'\n    context = Param(1.0)\n    def torque(self, s):\n        return 0.0\n",
            "{path}:X",
            "declares a parameter 'context', a name the Law API uses",
        ),
    ],
)
def test_a_law_that_cannot_run_is_refused_in_one_line_and_nothing_is_written(tmp_path, capsys, body, spec, message):
    path = write_law(tmp_path, body, "bad.py")
    out = tmp_path / "out"
    code = main(["run", "--controller", spec.format(path=path), "--duration", "1", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err, err
    assert "sashil run: error: --controller: controller.law: " in err
    assert not out.exists()


def test_law_parameters_are_config_keys_checked_like_any_other(tmp_path):
    config = apply_overrides(default_config(), ["controller.law=skyhook", "controller.c_sky=2"])
    assert config["controller"]["law"] == "skyhook" and config["controller"]["c_sky"] == 2.0
    assert "current_a" not in config["controller"]  # the previous law's parameter went with it
    with pytest.raises(ConfigError, match=r"^--set: controller.c_sky: expected a number > 0, got 0$"):
        apply_overrides(default_config(), ["controller.law=skyhook", "controller.c_sky=0"])
    # a parameter both laws declare keeps its value across a switch; the old law's others go
    onoff = apply_overrides(default_config(), ["controller.law=skyhook-add", "controller.onoff_current_a=0.4"])
    switched = apply_overrides(onoff, ["controller.law=skyhook-onoff"])
    assert switched["controller"]["onoff_current_a"] == 0.4 and "crossover_hz" not in switched["controller"]
    lab = tmp_path / "lab.yaml"
    lab.write_text("controller:\n  law: skyhook\n  c_sky: 2.0\n  c_ground: 1.0\n")
    with pytest.raises(ConfigError) as err:
        load_config(lab)
    assert str(err.value) == (
        f"{lab}: controller.c_ground: law 'skyhook' has no parameter c_ground (its parameters: c_sky)"
    )
    lab.write_text("controller:\n  law: skyhook\n")
    with pytest.raises(ConfigError, match=r"needs c_sky \(sky damping, N m s/rad\): add --set controller.c_sky="):
        load_config(lab)


def test_sashil_laws_lists_parameters_output_and_origin(tmp_path, capsys):
    path = write_law(
        tmp_path,
        "class Y(Law):\n    name = 'y'\n    k = Param(1.5, unit='A', high=2.0)\n    def current(self, s):\n        return self.k\n",
    )
    assert main(["laws", "--json", "--law", f"{path}:Y"]) == 0
    laws = {law["name"]: law for law in json.loads(capsys.readouterr().out)}
    assert BUILT_INS <= set(laws)
    assert laws["skyhook"]["output"] == "torque" and laws["skyhook-onoff"]["output"] == "current"
    assert laws["skyhook"]["parameters"][0] == {
        "name": "c_sky",
        "default": None,
        "required": True,
        "unit": "N m s/rad",
        "low": 0.0,
        "high": None,
        "low_open": True,
        "accepts": "a number > 0",
        "doc": "sky damping",
    }
    assert laws["y"]["origin"] == f"file {path}" and laws["y"]["parameters"][0]["default"] == 1.5
    assert main(["laws"]) == 0
    assert "controller.c_sky [N m s/rad] = required" in capsys.readouterr().out


# --- a law that misbehaves ends the run at 0 A --------------------------------------------------
def _sample(k: int) -> RigSample:
    """Sample ``k`` of a slow swing of a few counts (4096 counts/rev)."""
    return RigSample(k, 0, 0, round(3 * math.sin(k / 50)), 0, 0.0, 0, 4096)


@pytest.mark.parametrize(
    "value, what",
    [
        ("float('nan')", "returned nan (expected a finite number)"),
        ("float('inf')", "returned inf (expected a finite number)"),
        ("'1.0'", "returned '1.0' of type str (expected a number)"),
        ("None", "returned None of type NoneType (expected a number)"),
        ("1 / 0", "raised ZeroDivisionError: division by zero"),
    ],
)
def test_a_bad_output_is_a_law_error_naming_the_law(tmp_path, value, what):
    path = write_law(
        tmp_path,
        f"""
        class Bad(Law):
            name = "bad"

            def torque(self, state):
                return 1.0 if state.time_s < 0.0105 else {value}
        """,
    )
    config = default_config()
    ctl = make_controller(f"{path}:Bad", StageParts.read(config))
    for k in range(11):
        ctl.step(_sample(k), k * 1_000_000, 1_000_000)
    with pytest.raises(LawError) as err:
        ctl.step(_sample(11), 11_000_000, 1_000_000)
    assert str(err.value) == f"law 'bad' (file {path}) failed at t = 0.0110 s: {what}"


def test_numpy_numbers_are_numbers():
    import numpy as np

    class Np(Law):
        name = "np"

        def torque(self, state):
            return np.float64(0.5)

    ctl = make_controller(
        "skyhook", StageParts.read({**default_config(), "controller": {**default_config()["controller"], "c_sky": 1.0}})
    )
    ctl.law, ctl._law_output = Np(), Np().torque
    ctl.step(_sample(0), 0, 1_000_000)
    assert ctl.torque_cmd_nm == 0.5


@pytest.mark.parametrize("failure", ["raise ValueError('gain table empty')", "return float('nan')"])
def test_a_failing_law_in_a_drop_test_ends_at_zero_amps_with_exit_1_and_keeps_the_data(tmp_path, capsys, failure):
    path = write_law(
        tmp_path,
        f"""
        class Fails(Law):
            name = "fails"

            def torque(self, state):
                if state.time_s > 0.5:
                    {failure}
                return 0.2 * state.theta_dot_rad_s
        """,
    )
    out = tmp_path / "drop"
    code = main(["drop-test", "--set", f"controller.law={path}:Fails", "--duration", "2", "--out", str(out), "-q"])
    err = capsys.readouterr().err
    assert code == 1, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "error"
    run = summary["runs"][0]
    assert "law 'fails'" in run["error"] and (
        "ValueError: gain table empty" in run["error"] or "returned nan" in run["error"]
    )
    import sashil

    data = sashil.load_run(out).runs[0].data
    assert 0.05 < data["time_s"][-1] - data["time_s"][0] < 0.5  # kept up to the failing cycle, from the release


def test_a_law_clipped_in_most_cycles_gets_one_warning_with_the_share(capsys, tmp_path):
    code = main(
        [
            "run",
            "--controller",
            "skyhook",
            "--set",
            "controller.c_sky=10",
            "--duration",
            "1",
            "--out",
            str(tmp_path / "o"),
            "-q",
        ]
    )
    err = capsys.readouterr().err
    assert code == 0
    warnings = [line for line in err.splitlines() if "outside the damper's feasible band" in line]
    assert len(warnings) == 1 and "law 'skyhook'" in warnings[0] and " of 1000 cycles (" in warnings[0], err
    inside = ["--controller", "torque-tracking"]  # T* inside the band by construction
    quiet = main(["run", *inside, "--duration", "1", "--out", str(tmp_path / "p"), "-q"])
    assert quiet == 0 and "feasible band" not in capsys.readouterr().err


def test_a_refused_change_leaves_the_law_as_it_was():
    class Bounded(Law):
        name = "bounded"
        a = Param(1.0)
        b = Param(2.0)

        def parameters_changed(self) -> None:
            if self.a > self.b:
                raise ConfigError("controller.a: expected a <= b")
            self.gap = self.b - self.a

        def torque(self, state):
            return self.gap

    law = Bounded()
    with pytest.raises(ConfigError, match="expected a <= b"):
        law.set_parameters({"a": 5.0})
    assert (law.a, law.b, law.gap) == (1.0, 2.0, 1.0)
    with pytest.raises(ConfigError, match=r"controller\.b: expected a number"):
        law.set_parameters({"b": "x"})
    assert law.b == 2.0
    law.set_parameters({"a": 1.5})
    assert law.gap == 0.5


def test_a_run_is_labelled_by_its_laws_own_label(tmp_path):
    from sashil.control.registry import law_run_label, make_stage

    passive = apply_overrides(default_config(), ["controller.law=passive", "controller.current_a=0.75"])
    assert (
        law_run_label(StageParts.read(passive)) == "passive 0.75 A"
        and make_stage(StageParts.read(passive))[0] == "passive 0.75 A"
    )
    skyhook = apply_overrides(default_config(), ["controller.law=skyhook", "controller.c_sky=2"])
    assert law_run_label(StageParts.read(skyhook)) == "skyhook" and make_stage(StageParts.read(skyhook))[0] == "skyhook"
    path = write_law(
        tmp_path,
        """
        class Mine(Law):
            name = "mine"
            c = Param(2.0, low=0.0)

            def label(self):
                return f"mine c={self.c:g}"

            def torque(self, state):
                return self.c * state.theta_dot_rad_s
        """,
    )
    mine = apply_overrides(default_config(), [f"controller.law={path}:Mine", "controller.c=3"])
    # a law that reads the state runs in a controller, and is labelled as it says, not by its path
    label, stage = make_stage(StageParts.read(mine))
    assert label == law_run_label(StageParts.read(mine)) == "mine c=3" and stage.law.c == 3.0
