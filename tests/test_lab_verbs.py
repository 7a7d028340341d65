"""``sashil.lab.simulate``, ``replay`` and ``calibrate`` called from Python, no argv: each takes a
resolved config and returns the :class:`~sashil.api.Run` of the folder it wrote; its messages
arrive as events; bad input raises before any folder exists."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from sashil.engine.resolve import ConfigSource, Option, resolve
from sashil.errors import ConfigError, DataFileError, SashilError
from sashil.lab._calibrate import calibrate
from sashil.lab._drop_test import drop_test
from sashil.lab._replay import recorded_config, replay
from sashil.lab._simulate import drop_table, simulate
from sashil.lab.metrics import drop_metrics
from sashil.models.registry import MODEL_PARAMS
from sashil.recording.outputs import Outputs

#: the seed damper of the default config
J, K, C1, C2 = 1.0, 109.0, 0.7, 1.5


def _simulate_config(**simulate_keys):
    return resolve(ConfigSource(config={"simulate": simulate_keys}), "simulate", models=tuple(MODEL_PARAMS))


@pytest.fixture(scope="module")
def skyhook_drop(tmp_path_factory):
    """A 1.5 s drop test at 0.5 A with skyhook after the release (its data.csv has the sample
    sequence a replay needs), made by the library function."""
    out = tmp_path_factory.mktemp("lab") / "drop"
    options = (Option("--current", "drop_test.currents_a", [0.5]), Option("--duration", "drop_test.duration_s", 1.5))
    source = ConfigSource(controller="skyhook", sets=("controller.c_sky=2",), options=options)
    return drop_test(resolve(source, "drop-test"), Outputs(out=out))


# simulate ------------------------------------------------------------------------------------
def test_simulated_drop_swings_at_the_damped_period_of_the_spring_and_arm(tmp_path):
    events = []
    config = _simulate_config(current_a=0.5, duration_s=3.0)
    run = simulate(config, Outputs(out=tmp_path / "s"), events.append)
    assert run.path == tmp_path / "s"
    summary, data = run.summary, run.data
    assert (summary["verb"], summary["exit_status"], summary["exit_code"], summary["model"]) == (
        "simulate",
        "ok",
        0,
        "bouc-wen",
    )
    assert summary["input"] == "drop test theta0 -5 deg, 0.5 A" and summary["driver"] is None
    assert summary["samples"] == data["time_s"].size == 3001 and "nrmse" not in summary
    assert data["theta_rad"][0] == pytest.approx(math.radians(-5.0)) and np.all(data["current_a"] == 0.5)
    # the hysteretic torque saturates within 0.01 deg of each reversal (z_u / delta): the arm swings
    # on the spring k with the viscous c(i), T = 2 pi sqrt(J/k) / sqrt(1 - zeta^2) = 0.603 s; the
    # pre-yield stiffness alpha*delta near each reversal shortens it by about 1.5 %
    zeta = (C1 + 0.5 * C2) / (2.0 * math.sqrt(K * J))
    period = 2.0 * math.pi * math.sqrt(J / K) / math.sqrt(1.0 - zeta**2)
    simulated = summary["drop_test"]["simulated"]
    assert simulated["period_s"] == pytest.approx(period, rel=0.02)
    again = drop_metrics(data["time_s"], data["theta_rad"], 0.5, 2.0 * math.pi / 4096)
    assert simulated["peaks_deg"] == pytest.approx(again.peaks_deg)
    assert run.config["simulate"] == {
        "input": None,
        "theta0_deg": -5.0,
        "current_a": 0.5,
        "duration_s": 3.0,
        "start": "rest",
    }
    assert [e.kind for e in events] == ["output", "output"]
    assert events[0].text == f"simulated bouc-wen on drop test theta0 -5 deg, 0.5 A: {tmp_path / 's'}"
    assert events[1].text.splitlines()[0].split() == ["drop", "test", "simulated"]
    assert (tmp_path / "s" / "theta.png").stat().st_size > 0


def test_simulate_on_a_recorded_drop_fits_it_and_reports_both_drops(skyhook_drop, tmp_path):
    events = []
    run = simulate(_simulate_config(input=str(skyhook_drop.path)), Outputs(out=tmp_path / "s"), events.append)
    data, summary = run.data, run.summary
    recorded = skyhook_drop.data
    assert np.array_equal(data["theta_measured_rad"], recorded["theta_rad"])
    assert np.array_equal(data["current_a"], recorded["current_a"])
    residual = data["theta_rad"] - data["theta_measured_rad"]
    assert summary["rms_rad"] == pytest.approx(float(np.sqrt(np.mean(residual**2))), rel=1e-9)
    assert summary["nrmse"] < 0.05  # the rig's own model on its own record: encoder steps and coil lag only
    assert summary["input"] == str(skyhook_drop.path / "data.csv")
    assert set(summary["drop_test"]) == {"simulated", "recorded"}
    assert summary["drop_test"]["recorded"]["peaks_deg"] == pytest.approx(skyhook_drop.metrics["peaks_deg"])
    assert events[0].text.endswith(f"(NRMSE {100 * summary['nrmse']:.3g} %)")
    header = events[1].text.splitlines()[0].split()
    assert header[-2:] == ["simulated", "recorded"]


def test_drop_table_lines_up_each_record(skyhook_drop):
    metrics = drop_metrics(skyhook_drop.data["time_s"], skyhook_drop.data["theta_rad"], 0.5, 2.0 * math.pi / 4096)
    lines = drop_table({"simulated": metrics, "recorded": metrics}).splitlines()
    assert len(lines) == 4 and len({len(line) for line in lines}) == 1
    assert lines[1].split()[-1] == f"{metrics.period_s:.3f}" and lines[3].split()[-1] == f"{metrics.damping_ratio:.4f}"


def test_simulate_bad_input_raises_and_leaves_no_folder(skyhook_drop, tmp_path):
    out = tmp_path / "never"
    two = tmp_path / "two"
    for name in ("a", "b"):
        (two / name).mkdir(parents=True)
        (two / name / "data.csv").write_text((skyhook_drop.path / "data.csv").read_text())
    with pytest.raises(ConfigError, match=r"^simulate.input .*two: a folder of 2 runs \(a, b\); simulate takes one"):
        _simulate_config(input=str(two))
    options = (Option("--duration", "simulate.duration_s", -1.0),)
    with pytest.raises(ConfigError, match=r"^--duration: simulate.duration_s: expected a number > 0"):
        resolve(ConfigSource(options=options), "simulate", models=tuple(MODEL_PARAMS))
    no_current = tmp_path / "nc.csv"
    no_current.write_text("time_s,theta_rad\n0,0\n0.001,0\n")
    with pytest.raises(ConfigError, match=r"nc\.csv: missing column current_a"):
        simulate(_simulate_config(input=str(no_current)), Outputs(out=out))
    with pytest.raises(ConfigError, match="sashil simulate writes its run folder only: --format mat"):
        simulate(_simulate_config(duration_s=1.0), Outputs(out=out, formats=("mat",)))
    assert not out.exists()


def test_simulate_config_is_read_only(tmp_path):
    config = _simulate_config(duration_s=1.0)
    with pytest.raises(TypeError):
        config["simulate"]["duration_s"] = 2.0
    simulate(config, Outputs(out=tmp_path / "s"))
    assert config["simulate"]["duration_s"] == 1.0


# replay --------------------------------------------------------------------------------------
def test_replay_with_a_constant_current_law_commands_it_on_every_row(skyhook_drop, tmp_path):
    events = []
    # the coil-lag compensation off: it answers the recorded current, which never followed the replay
    sets = ("controller.current_a=0.25", "controller.lead_horizon_s=0")
    source = ConfigSource(config=recorded_config(skyhook_drop.path), controller="passive", sets=sets)
    run = replay(resolve(source, "replay"), skyhook_drop.path, Outputs(out=tmp_path / "r"), events.append)
    data, facts = run.data, run.summary["replay"]
    recorded = skyhook_drop.data
    rows = data["replayed"] > 0
    assert rows.sum() == facts["rows_replayed"] == facts["rows"] == recorded["time_s"].size
    assert np.all(data["replay_current_cmd_a"][rows] == 0.25)
    for name in ("time_s", "theta_rad", "current_cmd_a", "seq"):
        assert np.array_equal(data[name], recorded[name])  # the recorded columns kept as they were
    expected = float(np.sqrt(np.mean((0.25 - recorded["current_cmd_a"]) ** 2)))
    assert facts["differences"]["current_cmd_a"]["rms"] == pytest.approx(expected, rel=1e-9)
    assert facts["law"]["name"] == "passive" and facts["source"] == str(skyhook_drop.path) and facts["open_loop"]
    assert run.summary["exit_status"] == "ok" and run.config["controller"]["law"] == "passive"
    assert [e.kind for e in events] == ["result", "folder"]
    assert events[0].text.startswith(f"replayed {rows.sum()} rows with passive i* differs by RMS")
    assert events[1].data == {"folder": str(tmp_path / "r")}
    assert (tmp_path / "r" / "replay.png").stat().st_size > 0


def test_replaying_the_same_law_twice_gives_the_same_commands(skyhook_drop, tmp_path):
    config = resolve(ConfigSource(config=recorded_config(skyhook_drop.path)), "replay")
    first = replay(config, skyhook_drop.path, Outputs(out=tmp_path / "a")).data
    again = replay(config, skyhook_drop.path, Outputs(out=tmp_path / "b")).data
    for name in ("replay_current_cmd_a", "replay_torque_cmd_nm", "replay_z_hat"):
        assert np.array_equal(first[name], again[name])
    assert np.any(first["replay_current_cmd_a"] > 0) and np.any(first["replay_current_cmd_a"] < 1)


def test_replay_bad_input_raises_and_leaves_no_folder(skyhook_drop, tmp_path):
    out = tmp_path / "never"
    config = resolve(ConfigSource(config=recorded_config(skyhook_drop.path)), "replay")
    with pytest.raises(DataFileError, match="not a sashil run folder"):
        replay(config, tmp_path, Outputs(out=out))
    with pytest.raises(DataFileError, match="not a sashil run folder"):
        recorded_config(tmp_path)
    source = ConfigSource(config=recorded_config(skyhook_drop.path), sets=("controller.c_sky=-1",))
    with pytest.raises(ConfigError, match=r"controller\.c_sky"):
        resolve(source, "replay")
    with pytest.raises(ConfigError, match="a live view"):
        replay(config, skyhook_drop.path, Outputs(out=out, rerun_save=str(tmp_path / "x.rrd")))
    assert not out.exists()
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "keep.txt").write_text("x")
    with pytest.raises(ConfigError, match="exists and is not an empty folder"):
        replay(config, skyhook_drop.path, Outputs(out=busy))
    assert sorted(p.name for p in busy.iterdir()) == ["keep.txt"]


# calibrate -----------------------------------------------------------------------------------
SMALL_PLAN = {
    "currents_a": [0.0, 1.0],
    "small_currents_a": [],
    "road_currents_a": [],
    "validate_currents_a": [0.5],
    "drop_duration_s": 2.0,
    "profile_n": False,
}


@pytest.mark.e2e  # a whole calibration: three drops and a fit (seconds)
def test_calibrate_recovers_the_simulated_dampers_stiffness_with_the_given_inertia(tmp_path):
    events = []
    config = resolve(
        ConfigSource(
            config={"calibrate": SMALL_PLAN, "model": {"params": {"J": 1.1, "k": 120.0}}},
            options=(Option("--inertia", "calibrate.inertia_kg_m2", 1.1),),
        ),
        "calibrate",
    )
    run = calibrate(config, Outputs(out=tmp_path / "c"), events.append)
    summary = run.summary
    assert (summary["verb"], summary["exit_status"], summary["model"], summary["inertia_given"]) == (
        "calibrate",
        "ok",
        "bouc-wen",
        True,
    )
    names = [entry["name"] for entry in summary["runs"]]
    assert len(names) == 3 and set(summary["held_out_nrmse"]) == {n for n in names if "validate" in n}
    assert all((tmp_path / "c" / "runs" / n / "data.csv").is_file() for n in names)
    from sashil.config import load_params

    params = load_params(tmp_path / "c" / "params.yaml")["params"]
    assert params["J"] == 1.1 and params["k"] == pytest.approx(120.0, rel=0.01)
    assert run.config["calibrate"]["inertia_kg_m2"] == 1.1 and run.config["calibrate"]["profile_n"] is False
    kinds = [e.kind for e in events]
    assert kinds[0] == "progress" and events[0].text.startswith("calibration plan: 3 runs")
    assert kinds[-4:] == ["output", "output", "output", "folder"] and set(kinds[:-4]) == {"progress", "prompt"}
    prompts = [e.text for e in events if e.kind == "prompt"]  # each run's hold angle, told before it runs
    assert [text.split(":")[0] for text in prompts] == names
    assert all("press the arm to" in text and "let go" in text for text in prompts)
    assert not any("relative to J = 1" in e.text for e in events)
    assert events[-2].data == {
        "params": str(tmp_path / "c" / "params.yaml"),
        "report": str(tmp_path / "c" / "report.md"),
    }
    assert events[-1].data == {"folder": str(tmp_path / "c")}


def test_calibrate_bad_input_raises_and_leaves_no_folder(tmp_path):
    out = tmp_path / "never"
    with pytest.raises(ConfigError, match=r"^--inertia: calibrate.inertia_kg_m2: expected a number > 0"):
        resolve(ConfigSource(options=(Option("--inertia", "calibrate.inertia_kg_m2", 0.0),)), "calibrate")
    with pytest.raises(ConfigError, match=r"^--extra-steps: calibrate.extra_steps: expected an integer >= 0 and <= 9"):
        resolve(ConfigSource(options=(Option("--extra-steps", "calibrate.extra_steps", 12),)), "calibrate")
    one_current = {**SMALL_PLAN, "currents_a": [0.5], "validate_currents_a": []}
    events = []
    config = resolve(ConfigSource(config={"calibrate": one_current}), "calibrate")
    with pytest.raises(ConfigError, match=r"^lab.yaml: calibrate: every run to fit is at 0.5 A"):
        calibrate(config, Outputs(out=out), events.append, source="lab.yaml")
    assert events == [] and not out.exists()
    port = str(tmp_path / "no-such-tty")
    config = resolve(ConfigSource(config={"calibrate": SMALL_PLAN}, driver="serial", port=port), "calibrate")
    with pytest.raises(SashilError, match="no-such-tty") as err:  # a port that cannot be opened: bad input
        calibrate(config, Outputs(out=out))
    assert err.value.exit_code == ConfigError.exit_code
    assert not out.exists()


# the command line -----------------------------------------------------------------------------
@pytest.mark.parametrize("verb", ["calibrate", "replay", "simulate"])
def test_verb_help_loads_no_numerics(verb):
    code = (
        "import contextlib, io, sys\n"
        "from sashil.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        f"    main([{verb!r}, '--help'])\n"
        "print(sorted(m for m in ('numpy', 'scipy', 'numba', 'matplotlib') if m in sys.modules))"
    )
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert loaded.strip() == "[]"
