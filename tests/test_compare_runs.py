"""Each law of a compare is a run of its own: its folder with config.yaml (the law and its
parameters), data.csv and summary.json, which load_run, report, replay and compare --config read;
a current law's output recorded as it gave it; a law labelled by its name, its origin beside it."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pytest
import yaml

import sashil
from sashil.cli import main
from sashil.config.parts import StageParts
from sashil.recording.data_file import read_data_csv

SHORT = ["--duration", "2", "--set", "compare.settle_s=1", "--set", "road.period_s=10", "-q"]


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    """skyhook (c_sky=2) and skyhook-onoff (0.8 A) compared on the simulated rig, virtual clock."""
    out = tmp_path_factory.mktemp("cmp") / "cmp"
    laws = ["--controller", "skyhook", "--controller", "skyhook-onoff"]
    sets = ["--set", "controller.c_sky=2", "--set", "controller.onoff_current_a=0.8"]
    assert main(["compare", *SHORT, *laws, *sets, "--out", str(out)]) == 0
    return out


def test_each_law_is_a_run_folder_with_its_law_parameters_data_and_summary(compared):
    run = sashil.load_run(compared)
    assert [sub.name for sub in run.runs] == ["passive-0A", "passive-1A", "skyhook", "skyhook-onoff"]
    sky = run.run("skyhook")
    assert sky.config["controller"]["law"] == "skyhook" and sky.config["controller"]["c_sky"] == 2.0
    assert "onoff_current_a" not in sky.config["controller"]  # the other law's parameter is not its
    assert sky.summary["verb"] == "compare" and sky.summary["controller"] == "skyhook"
    assert sky.summary["controller_origin"] == "built-in" and sky.summary["parameters"] == {"c_sky": 2.0}
    assert sky.summary["timing"]["cycles"] == 2000
    assert sky.summary["metrics"]["rms_accel_rad_s2"] == pytest.approx(
        float(run.tables["metrics"]["rms_accel_rad_s2"][2]), rel=1e-12
    )
    assert sky.data["time_s"].size == 2001  # 2 s at 1 kHz and the shutdown's 0 A row
    passive = run.run("passive-1A")
    assert passive.config["controller"]["law"] == "passive" and passive.config["controller"]["current_a"] == 1.0
    assert set(passive.data["current_cmd_a"][:-1]) == {1.0}
    md = (compared / "compare.md").read_text()
    assert "| skyhook | c_sky=2 | `skyhook/` |" in md
    assert "| skyhook-onoff | onoff_current_a=0.8 | `skyhook-onoff/` |" in md
    assert "seed 001" not in md  # the paper by its authors and year
    top = (compared / "config.yaml").read_text()  # the base config says it runs none of the laws
    assert top.startswith("# The config every law of this comparison started from")
    assert "passive-0A/, passive-1A/, skyhook/, skyhook-onoff/" in top.splitlines()[1]


def test_a_current_laws_output_is_recorded_and_sent_as_it_gave_it(compared):
    data = sashil.load_run(compared / "skyhook-onoff").data
    law, sent = data["current_law_a"][:-1], data["current_cmd_a"][:-1]
    assert set(np.unique(law)) == {0.0, 0.8}
    np.testing.assert_array_equal(sent, law)  # no coil-lag lead on a current law by default
    assert "current_law_a" not in sashil.load_run(compared / "skyhook").data  # a torque law: torque_cmd_nm


def test_the_lead_on_a_current_law_is_a_key_and_the_record_keeps_both(tmp_path):
    out = tmp_path / "lead"
    sets = ["--set", "controller.onoff_current_a=0.8", "--set", "controller.lead_current_laws=true"]
    assert main(["compare", *SHORT, "--controller", "skyhook-onoff", *sets, "--out", str(out)]) == 0
    data = sashil.load_run(out / "skyhook-onoff").data
    law, sent = data["current_law_a"][:-1], data["current_cmd_a"][:-1]
    assert set(np.unique(law)) == {0.0, 0.8}  # what the law asked for, whatever was sent
    assert sent.max() == pytest.approx(1.0)  # the lead drives the coil harder at a switch-on (gain 3.86)
    assert np.all(sent[law == 0.0] <= 0.8)


def test_report_reads_a_compare_folder_and_its_law_folders(compared, tmp_path):
    out = tmp_path / "rep"
    assert main(["report", str(compared), "--out", str(out), "-q"]) == 0
    md = (out / "report.md").read_text()
    assert "compare of 4 laws" in md and "| skyhook (c_sky=2) |" in md
    assert "`cmp/skyhook-onoff`" in md and "## Compare `cmp`" in md
    assert main(["report", str(compared / "skyhook"), "--out", str(tmp_path / "one"), "-q"]) == 0


def test_replay_takes_a_law_folder_and_names_the_runs_of_the_compare_folder(compared, tmp_path, capsys):
    assert main(["replay", str(compared / "skyhook"), "--out", str(tmp_path / "r"), "-q"]) == 0
    assert sashil.load_run(tmp_path / "r").summary["replay"]["rows_replayed"] > 1000
    capsys.readouterr()
    assert main(["replay", str(compared), "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds 4 runs (passive-0A/, passive-1A/, skyhook/, skyhook-onoff/)" in err[0]
    assert f"sashil replay {compared / 'passive-0A'}" in err[0] and not (tmp_path / "never").exists()


def test_a_law_folders_config_compares_that_law_again_sample_for_sample(compared, tmp_path):
    again = tmp_path / "again"
    assert main(["compare", "--config", str(compared / "skyhook" / "config.yaml"), "--out", str(again), "-q"]) == 0
    assert [sub.name for sub in sashil.load_run(again).runs] == ["passive-0A", "passive-1A", "skyhook"]
    first = read_data_csv(compared / "skyhook" / "data.csv")
    second = read_data_csv(again / "skyhook" / "data.csv")
    for name in ("time_s", "current_cmd_a", "theta_rad"):
        assert np.array_equal(first[name], second[name]), name


def test_replaying_a_multi_current_drop_test_points_at_its_runs(tmp_path, capsys):
    drop = tmp_path / "drop"
    argv = ["drop-test", "--current", "0", "--current", "1", "--duration", "1", "--out", str(drop), "-q"]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(["replay", str(drop), "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds 2 runs (i0.000A/, i1.000A/)" in err[0] and "no data.csv" not in err[0]
    assert not (tmp_path / "never").exists()


def test_a_file_law_is_labelled_by_its_name_with_its_origin_beside_it(tmp_path):
    law = tmp_path / "bangbang.py"
    law.write_text(
        textwrap.dedent(
            """
            from sashil.control import Law

            class RateBangBang(Law):
                name = "rate-bangbang"

                def current(self, state):
                    return 0.8 if state.theta_dot_rad_s * state.body_dot_rad_s > 0 else 0.0
            """
        )
    )
    spec = f"{law}:RateBangBang"
    from sashil.control.registry import make_stage
    from sashil.engine.resolve import ConfigSource, resolve

    config = resolve(ConfigSource(controller=spec), "run")
    assert make_stage(StageParts.read(config))[0] == "rate-bangbang"  # run.png's title and summary.json's controller
    out = tmp_path / "cmp"
    assert main(["compare", *SHORT, "--controller", spec, "--out", str(out)]) == 0
    summary = sashil.load_run(out / "rate-bangbang").summary
    assert summary["controller"] == "rate-bangbang" and summary["controller_origin"] == f"file {law}"
    assert yaml.safe_load((out / "rate-bangbang" / "config.yaml").read_text())["controller"]["law"] == spec


def test_drop_test_on_a_port_that_cannot_be_opened_says_so_and_leaves_no_folder(tmp_path, capsys):
    out = tmp_path / "drop"
    assert main(["drop-test", "--driver", "serial", "--port", str(tmp_path / "ttyUSB9"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "cannot open" in err and "run folder" not in err and not out.exists()
    assert err.strip().splitlines()[-1].startswith("sashil drop-test: error: serial port")


@pytest.mark.e2e
def test_drop_test_on_an_emulator_that_holds_nothing_says_how_and_leaves_no_folder(tmp_path, capsys):
    from test_link_e2e import Emulator

    emu = Emulator(tmp_path, "serial", "python")
    out = tmp_path / "drop"
    try:
        # the link rides through a busy machine's pauses (as the link tests' normal runs do: no
        # sample, or an emulator that reads nothing, for up to 500 ms), so the run meets the missing
        # hold, not a link timeout
        patient = ["--set", "driver.sample_timeout_ms=500", "--set", "driver.link_lost_ms=500"]
        patient += ["--set", "driver.max_lost_fraction=1.0"]
        code = main(["drop-test", "--driver", "serial", "--port", emu.link, *patient, "--out", str(out)])
    finally:
        emu.stop()
    err = capsys.readouterr().err
    assert code == 2 and not out.exists(), err
    assert "press the arm" not in err and "run folder" not in err
    last = err.strip().splitlines()[-1]
    assert "is a pseudo-terminal (an emulated rig)" in last and "--hold-deg -5" in last


def test_a_drop_test_under_a_current_law_records_its_output_as_given(tmp_path):
    out = tmp_path / "drop"
    sets = ["--set", "controller.law=skyhook-onoff", "--set", "controller.onoff_current_a=0.8"]
    assert main(["drop-test", "--current", "0", "--duration", "1", *sets, "--out", str(out), "-q"]) == 0
    data = sashil.load_run(out).data
    assert set(np.unique(data["current_law_a"])) == {0.0, 0.8}
    # the law is in charge once the release is detected (the arm moved 0.5 deg, within 0.1 s): what
    # it gave is what was sent; before that the drop's own 0 A, while the law's column says what it asked
    after = data["time_s"] > 0.1
    np.testing.assert_array_equal(data["current_cmd_a"][after], data["current_law_a"][after])


def test_report_reads_an_older_compare_folder_without_law_runs(compared, tmp_path):
    """A compare folder written before each law had a run folder: its table, no traces."""
    old = tmp_path / "old"
    old.mkdir()
    for name in ("summary.json", "config.yaml", "metrics.csv", "compare.md"):
        (old / name).write_bytes((compared / name).read_bytes())
    summary = json.loads((old / "summary.json").read_text())
    summary.update(schema_version=1, runs=[])
    (old / "summary.json").write_text(json.dumps(summary))
    out = tmp_path / "rep"
    assert main(["report", str(old), "--out", str(out), "-q"]) == 0
    md = (out / "report.md").read_text()
    assert "## Compare `old`" in md and "| skyhook | " in md and "## Controllers compared" not in md


def test_a_sweep_under_a_current_law_records_its_output_as_given(tmp_path):
    out = tmp_path / "sweep"
    argv = ["sweep", "--f-start", "1", "--f-stop", "2", "--duration", "1", "--controller", "skyhook-onoff"]
    sets = ["--set", "controller.onoff_current_a=0.8", "--set", "sweep.ramp_s=0.3"]
    assert main([*argv, *sets, "--out", str(out), "-q"]) == 0
    data = sashil.load_run(out).data
    assert set(np.unique(data["current_law_a"][:-1])) == {0.0, 0.8}
    np.testing.assert_array_equal(data["current_cmd_a"][:-1], data["current_law_a"][:-1])
