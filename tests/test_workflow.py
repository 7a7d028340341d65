"""--set overrides, the summary.json schema, sashil.load_run, --format parquet/mat, --road."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

import sashil
from sashil.cli import main
from sashil.drivers import rig_parts
from sashil.engine.resolve import apply_overrides, default_config
from sashil.errors import ConfigError, DataFileError
from sashil.recording.summary_schema import SCHEMA_VERSION
from sashil.roads.option import RoadParts

#: a real-clock run in-process without touching the scheduler or locking memory
QUIET_RT = ["--set", "loop.rt.priority=0", "--set", "loop.rt.mlockall=false"]
COMMON_KEYS = ("schema_version", "verb", "exit_status", "exit_code", "error", "driver", "controller", "timing", "trips")


# --set ---------------------------------------------------------------------------------------
def test_overrides_are_typed_like_the_config_file():
    config = apply_overrides(
        default_config(),
        [
            "loop.rate_hz=500",
            "controller.law=skyhook",
            "controller.c_sky=2",
            "loop.rt.cpu=null",
            "model.params.k=120",
            "safety.angle_interlock=false",
        ],
    )
    assert config["loop"]["rate_hz"] == 500.0 and isinstance(config["loop"]["rate_hz"], float)
    assert config["controller"]["law"] == "skyhook" and config["controller"]["c_sky"] == 2.0
    tracking = apply_overrides(
        default_config(), ["controller.law=torque-tracking", "controller.tracking_fraction=[0.2, 0.8]"]
    )
    assert tracking["controller"]["tracking_fraction"] == [0.2, 0.8]
    assert config["model"]["params"]["k"] == 120.0
    assert config["safety"]["angle_interlock"] is False
    assert default_config()["loop"]["rate_hz"] == 1000.0  # the input is not changed


def test_later_override_wins():
    assert apply_overrides(default_config(), ["loop.rate_hz=500", "loop.rate_hz=250"])["loop"]["rate_hz"] == 250.0


@pytest.mark.parametrize(
    "override, message",
    [
        ("loop.rate_hz=fast", "--set: loop.rate_hz: expected a number > 0 and <= 20000, got 'fast'"),
        ("loop.rate=5", "--set: loop.rate: unknown key (known keys here:"),
        ("nosuch.key=1", "--set: nosuch: unknown key"),
        ("controller.law=bogus", "--set: controller.law: unknown law 'bogus' (known: "),
        ("safety.angle_interlock=3", "--set: safety.angle_interlock: expected true or false, got 3"),
        ("model.params.foo=1", "--set: model.params.foo: not a bouc-wen parameter"),
        ("loop.rate_hz.x=1", "--set: loop.rate_hz.x: loop.rate_hz is a value, not a section"),
        ("loop", "--set 'loop': expected section.key=value"),
        ("rate_hz=5", "--set 'rate_hz=5': expected section.key=value, with a dotted key"),
    ],
)
def test_bad_override_is_one_line_naming_key_and_type(override, message):
    with pytest.raises(ConfigError) as err:
        apply_overrides(default_config(), [override])
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("verb", ["drop-test", "run", "sweep", "simulate", "calibrate"])
def test_bad_set_on_any_verb_exits_2_and_writes_nothing(tmp_path, capsys, verb):
    out = tmp_path / "out"
    assert main([verb, "--set", "loop.rate_hz=fast", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "loop.rate_hz: expected a number" in err
    assert not out.exists()


def test_set_is_in_the_resolved_config_of_the_run_folder(tmp_path):
    out = tmp_path / "drop"
    argv = ["drop-test", "--duration", "1", "--out", str(out), "-q"]
    assert main([*argv, "--set", "drop_test.settle_band_deg=0.5", "--set", "rig.encoder_counts_per_rev=8192"]) == 0
    saved = yaml.safe_load((out / "config.yaml").read_text())
    assert saved["drop_test"]["settle_band_deg"] == 0.5
    assert saved["rig"]["encoder_counts_per_rev"] == 8192
    assert json.loads((out / "summary.json").read_text())["runs"][0]["settle_band_deg"] == 0.5


# --format ------------------------------------------------------------------------------------
def test_can_trace_format_on_a_driver_without_can_frames_is_refused_before_anything_runs(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "--duration", "1", "--format", "blf", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--format blf: a CAN frame trace needs the can driver" in err and err.count("\n") == 1
    assert not out.exists()


def test_missing_library_names_the_extra(tmp_path, capsys, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pyarrow" else real(name, *a))
    out = tmp_path / "out"
    assert main(["drop-test", "--format", "parquet", "--out", str(out)]) == 2
    assert "pip install 'sashil[parquet]'" in capsys.readouterr().err
    assert not out.exists()


# load_run and the summary schema -------------------------------------------------------------
@pytest.fixture(scope="module")
def drop_runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("drops")
    single, multi = root / "single", root / "multi"
    assert (
        main(["drop-test", "--duration", "2", "--format", "parquet", "--format", "mat", "--out", str(single), "-q"])
        == 0
    )
    assert main(["drop-test", "--duration", "2", "--current", "0", "--current", "1", "--out", str(multi), "-q"]) == 0
    return single, multi


def test_every_summary_has_the_common_keys(drop_runs, tmp_path):
    single, multi = drop_runs
    sim = tmp_path / "sim"
    assert main(["simulate", "--duration", "1", "--out", str(sim)]) == 0
    for folder in (single, multi, multi / "i1.000A", sim):
        summary = json.loads((folder / "summary.json").read_text())
        assert all(key in summary for key in COMMON_KEYS), folder
        assert summary["schema_version"] == SCHEMA_VERSION
        assert isinstance(summary["exit_status"], str) and summary["exit_code"] == 0
    assert json.loads((single / "summary.json").read_text())["controller"] == "passive (constant current per run)"


def test_load_run_reads_a_drop_test_in_each_format(drop_runs):
    single, _ = drop_runs
    run = sashil.load_run(single)
    assert run.path == single and run.verb == "drop-test"
    assert run.data_file.name == "data.parquet"
    from sashil.api import read_data_file

    csv = read_data_file(single / "data.csv")
    mat = read_data_file(single / "data.mat")
    assert list(run.data) == list(csv) == list(mat)
    for name in csv:
        np.testing.assert_array_equal(run.data[name], csv[name])  # same rows, bit for bit
        np.testing.assert_array_equal(mat[name], csv[name])
    assert run.config["loop"]["rate_hz"] == 1000.0
    assert run.runs == [run]
    assert run.metrics["period_s"] == pytest.approx(0.6, abs=0.02)
    assert run.units["theta_rad"] == "rad" and run.units["current_a"] == "A"


def test_parquet_carries_units_and_config(drop_runs):
    from sashil.recording.parquet_sink import read_metadata

    meta = read_metadata(drop_runs[0] / "data.parquet")
    assert meta["units"]["time_s"] == "s" and meta["units"]["theta_road_rad"] == "rad"
    assert meta["config"]["model"]["params"]["k"] == 109.0
    assert meta["run"]["verb"] == "drop-test" and meta["run"]["current_a"] == 0.0


def test_load_run_of_a_multi_current_drop_test_lists_sub_runs(drop_runs):
    _, multi = drop_runs
    run = sashil.load_run(multi)
    assert [r.name for r in run.runs] == ["i0.000A", "i1.000A"]
    assert run.run("i1.000A").metrics["current_a"] == 1.0
    assert run.runs[1].data["current_cmd_a"][0] == 1.0
    peaks0 = run.runs[0].metrics["peaks_deg"][0]
    assert peaks0 > run.runs[1].metrics["peaks_deg"][0]  # 1 A damps more
    with pytest.raises(DataFileError, match="holds 2 sub-runs"):
        _ = run.data
    sub = sashil.load_run(multi / "i0.000A")  # a sub-folder is a run folder of its own
    assert sub.runs == [sub] and sub.metrics["current_a"] == 0.0


@pytest.mark.e2e  # sashil run is always on the wall clock
@pytest.mark.alone  # the default share of missed deadlines, at normal priority
def test_load_run_of_a_loop_run_with_road(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "--duration", "0.5", "-q", *QUIET_RT, "--format", "parquet", "--out", str(out)]) == 0
    run = sashil.load_run(out)
    assert run.summary["verb"] == "run" and run.summary["timing"]["cycles"] == 500
    assert run.data["seq"].dtype == np.int64
    assert np.ptp(run.data["theta_road_rad"]) > 0  # the default road excitation of the sim backend
    assert run.summary["road"] == "sine 1 Hz, 1 deg"
    assert run.timing is not None and run.timing["lateness_ns"].size == 500
    assert (out / "run.png").stat().st_size > 10_000
    assert (out / "timing.png").stat().st_size > 10_000
    assert all(key in run.summary for key in COMMON_KEYS)


def test_sweep_summaries_have_the_common_keys(tmp_path):
    chirp, stepped = tmp_path / "chirp", tmp_path / "stepped"
    assert main(["sweep", "--duration", "2", "--f-start", "1", "--f-stop", "2", "--out", str(chirp), "-q"]) == 0
    assert main(["sweep", "--stepped", "--steps", "2", "--current", "0", "--out", str(stepped), "-q"]) == 0
    for folder in (chirp, stepped, stepped / "f0.500Hz"):
        summary = sashil.load_run(folder).summary
        assert all(key in summary for key in COMMON_KEYS), folder
        assert summary["verb"] == "sweep" and summary["driver"] == "sim"


def test_load_run_of_something_else_is_one_clear_error(tmp_path):
    with pytest.raises(DataFileError, match="not a folder"):
        sashil.load_run(tmp_path / "missing")
    with pytest.raises(DataFileError, match="not a sashil run folder"):
        sashil.load_run(tmp_path)


# --road --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "spec, message",
    [
        ("square:1", "expected sine:F_HZ"),
        ("sine:x", "expected sine:F_HZ"),
        ("sine:0", "expected a frequency in (0, 100] Hz, got 0"),
        ("sine:1:45", "expected an amplitude in (0, 20] deg, got 45"),
        ("chirp:1:2:0", "expected a chirp length in seconds > 0"),
    ],
)
def test_bad_road_is_exit_2(tmp_path, capsys, spec, message):
    out = tmp_path / "out"
    assert main(["run", "--duration", "1", "--road", spec, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_road_stage_sends_the_road_speed_and_keeps_the_signals():
    from sashil.drivers.interface import RigSample
    from sashil.roads.option import RoadStage, parse_road

    profile, text = parse_road(
        "sine:2:1", RoadParts.read({**default_config(), "sweep": {**default_config()["sweep"], "ramp_s": 0}})
    )
    assert text == "sine 2 Hz, 1 deg"

    class Stage:
        z_hat = 0.5

        def step(self, sample, t_ns, dt_ns):
            from sashil.drivers.interface import RigCommand

            return RigCommand(0.3)

    stage = RoadStage(Stage(), profile)
    sample = RigSample(1, 0, 0, 0, 0, 0.0, 0, 4096)
    assert stage.step(sample, 1_000, 1_000).road_speed_rad_s == pytest.approx(2 * np.pi * 2 * np.radians(1))
    assert stage.z_hat == 0.5


# the rerun viewer -----------------------------------------------------------------------------
def test_spawned_viewer_listens_on_loopback_only(monkeypatch):
    import subprocess

    from sashil.recording import viewer

    started = []

    class FakeViewer:
        returncode = None

        def __init__(self, argv, **kwargs):
            started.append((argv, kwargs))

        def poll(self):
            return None

    calls = iter([False, False, True])  # nothing there yet; then the spawned viewer listens
    monkeypatch.setattr(viewer, "listening", lambda host, port, timeout_s=0.2: next(calls))
    monkeypatch.setattr(subprocess, "Popen", FakeViewer)
    assert viewer.spawn_viewer("/opt/rerun", 9876) is not None
    argv, kwargs = started[0]
    assert argv[argv.index("--bind") + 1] == "127.0.0.1" and argv[argv.index("--port") + 1] == "9876"
    assert kwargs["start_new_session"] is True
    assert viewer.reachable_host("0.0.0.0") == "127.0.0.1" and viewer.reachable_host("10.0.0.2") == "10.0.0.2"


def test_a_viewer_already_listening_is_reused(monkeypatch):
    from sashil.recording import viewer

    monkeypatch.setattr(viewer, "listening", lambda host, port, timeout_s=0.2: True)
    assert viewer.spawn_viewer("/nonexistent/rerun") is None


# drop test: operator prompts, labels, plots ---------------------------------------------------
class _HandRig:
    """The simulated rig, but a 'person' holds and releases the arm: the host is not told when."""

    def __init__(self, rig):
        self.rig = rig

    def __getattr__(self, name):
        return getattr(self.rig, name)

    def operator_hold(self, theta_rad, release_after_s):
        self.rig.operator_hold(theta_rad, release_after_s + 0.4)
        return False


def test_a_held_drop_test_prompts_the_operator_and_shows_the_release(config):
    from sashil.drivers import open_rig
    from sashil.lab._drop_test import run_drop_test

    lines: list[str] = []
    record = run_drop_test(config, -5.0, 0.0, 1.0, rig=_HandRig(open_rig(rig_parts(config))), notify=lines.append)
    assert record.error is None and record.release_estimated
    assert len(lines) == 3
    assert lines[0].startswith("press the arm to -5 deg (within ±0.5 deg) and hold it still")
    assert lines[1].startswith("hold detected at -5.0") and "release the arm when ready" in lines[1]
    assert lines[2].startswith("release detected: the arm left -5.0") and "recording 1 s" in lines[2]


def test_the_simulated_operator_needs_no_prompt(config):
    from sashil.lab._drop_test import run_drop_test

    lines: list[str] = []
    run_drop_test(config, -5.0, 0.0, 0.5, notify=lines.append)
    assert lines == []


def test_drop_test_under_a_controller_is_labelled_by_its_law(tmp_path, capsys):
    out = tmp_path / "td"
    argv = ["drop-test", "--duration", "2", "--out", str(out)]
    assert main([*argv, "--set", "controller.law=target-damping", "--set", "controller.zeta=0.08"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["controller"] == "target-damping"
    assert summary["runs"][0]["controller"] == "target-damping (from 0 A until the release)"
    assert "target-damping" in capsys.readouterr().err
    assert (out / "drop_test.png").stat().st_size > 20_000


def test_bad_controller_parameters_leave_no_folder(tmp_path, capsys):
    out = tmp_path / "td"
    argv = ["drop-test", "--out", str(out), "--set", "controller.law=target-damping", "--set", "controller.zeta=0.3"]
    assert main(argv) == 2
    assert "controller.zeta" in capsys.readouterr().err
    assert not out.exists()


def test_timing_plot_of_percentiles(tmp_path):
    from sashil.recording.plots import plot_timing

    rng = np.random.default_rng(1)
    lateness = rng.exponential(5_000, 20_000).astype(np.int64)
    lateness[::5000] = 3_000_000  # a few outliers
    path = plot_timing(tmp_path / "timing.png", [("a", {"lateness_ns": lateness, "compute_ns": lateness // 10})])
    assert path.stat().st_size > 20_000


def test_road_profile_file(tmp_path):
    from sashil.roads.option import parse_road

    path = tmp_path / "road.csv"
    path.write_text("time_s,theta_road_rad\n1.0,0.0\n2.0,0.01\n3.0,0.0\n")
    road, text = parse_road(str(path), RoadParts.read(default_config()))
    assert text == f"profile {path} (2 s)"
    assert road(0.5)[0] == pytest.approx(0.005) and road(0.5)[1] > 0  # from the first sample on, interpolated
    assert road(5.0) == (0.0, 0.0, 0.0)  # held at the last angle
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,theta_rad\n0,0\n1,0\n")
    with pytest.raises(ConfigError, match=r"--road .*bad\.csv: missing column"):
        parse_road(str(bad), RoadParts.read(default_config()))


def test_the_manuals_analysis_example_runs(drop_runs, capsys):
    from doc_blocks import example

    code = example("how-to/python.md", "python", "load_run")
    single, multi = drop_runs
    code = code.replace('"runs/20261124T101500Z-run"', repr(str(single)))
    code = code.replace('"runs/20261124T102000Z-drop-test"', repr(str(multi)))
    exec(compile(code, "python.md", "exec"), {})
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == ["i0.000A", "i1.000A"]


def test_set_completion_lists_the_config_keys():
    from sashil.cli.completion import set_completer

    assert set_completer("loop.rt.p") == ["loop.rt.priority="]
    assert "controller.c_sky=" in set_completer("controller.")
    assert "model.params.k=" in set_completer("model.params.")
    every = set_completer("")
    assert all(k.count(".") >= 1 and k.endswith("=") for k in every)
    from sashil.control.law_registry import known_laws

    law_params = {f"controller.{p}=" for entry in known_laws() for p in entry.cls.params()}
    for key in every:  # each completed key is one --set accepts: a config key, or a law's parameter
        if key in law_params:
            continue
        path = key[:-1].split(".")
        node = default_config()
        for part in path:
            node = node[part]


def test_report_exports_parquet_of_runs_recorded_earlier(drop_runs, tmp_path):
    import shutil

    from sashil.recording.parquet_sink import read_metadata

    multi = tmp_path / "multi"  # a copy: the module's folders stay as the drop test wrote them
    shutil.copytree(drop_runs[1], multi)
    assert main(["report", str(multi), "--format", "parquet", "--out", str(tmp_path / "rep"), "-q"]) == 0
    for sub in ("i0.000A", "i1.000A"):
        run = sashil.load_run(multi / sub)
        assert run.data_file.name == "data.parquet"
        assert read_metadata(run.data_file)["config"]["loop"]["rate_hz"] == 1000.0
    assert read_metadata(multi / "i1.000A" / "data.parquet")["run"]["verb"] == "drop-test"
