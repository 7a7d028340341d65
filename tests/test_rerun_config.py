"""A run folder's config.yaml says what ran: every verb's options land in it, and ``--config
FOLDER/config.yaml`` alone runs the same experiment again, sample for sample (simulated rig,
virtual clock)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

import sashil
from sashil.cli import main
from sashil.engine import running as engine_running
from sashil.recording.data_file import read_data_csv
from sashil.runtime.clock import VirtualClock

#: the columns that must agree: what was commanded and what the arm did
SAME = ("time_s", "current_cmd_a", "theta_rad")


def assert_same_data(first: Path, again: Path, columns: tuple[str, ...] = SAME) -> None:
    """``first/data.csv`` and ``again/data.csv`` hold the same rows of ``columns``, bit for bit."""
    a = read_data_csv(first / "data.csv", required=columns)
    b = read_data_csv(again / "data.csv", required=columns)
    for name in columns:
        assert np.array_equal(a[name], b[name]), name
    assert len(a["time_s"]) > 10


def rerun(verb: str, folder: Path, out: Path, *extra: str) -> None:
    """The verb again with the folder's config.yaml and no other option that changes the experiment."""
    assert main([verb, "--config", str(folder / "config.yaml"), "--out", str(out), *extra]) == 0


@pytest.fixture
def virtual_run_clock(monkeypatch):
    """``sashil run`` on the virtual clock (it always takes the real one), so two runs can agree; the
    runs keep their loop in this process (``loop.process: false``), where the clock is replaced."""

    class Clock:
        @staticmethod
        def for_rate(spin_margin_us: float, rate_hz: float) -> VirtualClock:
            return VirtualClock()

    monkeypatch.setattr(engine_running, "RealClock", Clock)


def test_run_config_holds_the_law_road_rate_and_duration_and_reruns_them(tmp_path, virtual_run_clock):
    first, again = tmp_path / "a", tmp_path / "b"
    argv = [
        "--controller",
        "skyhook",
        "--set",
        "controller.c_sky=2",
        "--road",
        "sine:2.2:1.5",
        "--set",
        "loop.process=false",
    ]
    assert main(["run", *argv, "--rate", "500", "--duration", "0.6", "--out", str(first), "-q"]) == 0
    config = sashil.load_run(first).config
    assert config["controller"]["law"] == "skyhook" and config["controller"]["c_sky"] == 2.0
    assert config["run"] == {"duration_s": 0.6, "road": "sine:2.2:1.5"}
    assert config["loop"]["rate_hz"] == 500.0
    rerun("run", first, again, "-q")
    assert sashil.load_run(again).config["controller"]["law"] == "skyhook"
    assert_same_data(first, again)
    assert len(read_data_csv(again / "data.csv")["time_s"]) == 300 + 1  # 0.6 s at 500 Hz, and the 0 A row
    assert len(set(read_data_csv(again / "data.csv")["current_cmd_a"])) > 2  # the law commanded


def test_run_current_is_saved_as_the_passive_law_and_its_current(tmp_path, virtual_run_clock):
    skyhook = tmp_path / "skyhook.yaml"
    skyhook.write_text("controller:\n  law: skyhook\n  c_sky: 2.0\n")
    first, again = tmp_path / "a", tmp_path / "b"
    argv = ["run", "--config", str(skyhook), "--current", "0.3", "--duration", "0.3", "--out", str(first), "-q"]
    argv += ["--set", "loop.process=false"]  # the clock is replaced in this process
    assert main(argv) == 0
    controller = sashil.load_run(first).config["controller"]
    assert (controller["law"], controller["current_a"]) == ("passive", 0.3)
    assert sashil.load_run(first).config["run"]["road"] == "sine:1.0"  # the sim backend's default, as it ran
    rerun("run", first, again, "-q")
    assert_same_data(first, again)
    assert set(read_data_csv(again / "data.csv")["current_cmd_a"][:-1]) == {0.3}  # then the 0 A row


def test_drop_test_config_holds_angle_currents_duration_and_reruns_them(tmp_path):
    first, again = tmp_path / "a", tmp_path / "b"
    argv = ["--theta0-deg", "-4", "--current", "0.2", "--current", "0.6", "--duration", "1.5"]
    assert main(["drop-test", *argv, "--set", "controller.law=target-damping", "--set", "controller.zeta=0.1",
                 "--out", str(first), "-q"]) == 0  # fmt: skip
    config = sashil.load_run(first).config
    assert config["drop_test"]["theta0_deg"] == -4.0 and config["drop_test"]["currents_a"] == [0.2, 0.6]
    assert config["drop_test"]["duration_s"] == 1.5 and config["controller"]["law"] == "target-damping"
    rerun("drop-test", first, again, "-q")
    for sub in ("i0.200A", "i0.600A"):
        assert_same_data(first / sub, again / sub)
    # each current's sub-folder is a run folder of its own: its config reruns that one drop
    single = tmp_path / "c"
    rerun("drop-test", first / "i0.600A", single, "-q")
    assert sashil.load_run(single).config["drop_test"]["currents_a"] == [0.6]
    assert_same_data(first / "i0.600A", single)


def test_sweep_chirp_config_holds_law_band_duration_amplitude_and_reruns_them(tmp_path):
    first, again = tmp_path / "a", tmp_path / "b"
    argv = ["--f-start", "1", "--f-stop", "2.5", "--duration", "1", "--amplitude-deg", "0.5"]
    argv += ["--controller", "skyhook", "--set", "controller.c_sky=3", "--set", "sweep.ramp_s=0.5"]
    assert main(["sweep", *argv, "--out", str(first), "-q"]) == 0
    config = sashil.load_run(first).config
    assert config["controller"]["law"] == "skyhook"
    sweep = config["sweep"]
    assert (sweep["f_start_hz"], sweep["f_stop_hz"], sweep["duration_s"]) == (1.0, 2.5, 1.0)
    assert (sweep["amplitude_deg"], sweep["stepped"]) == (0.5, False)
    rerun("sweep", first, again, "-q")
    assert_same_data(first, again, (*SAME, "theta_road_rad"))


def test_sweep_stepped_config_holds_the_current_and_steps_and_reruns_them(tmp_path):
    skyhook = tmp_path / "skyhook.yaml"
    skyhook.write_text("controller:\n  law: skyhook\n  c_sky: 2.0\nsweep:\n  settle_s: 0.5\n  measure_s: 1.0\n")
    first, again = tmp_path / "a", tmp_path / "b"
    argv = ["sweep", "--config", str(skyhook), "--stepped", "--steps", "2", "--f-start", "1.5", "--f-stop", "3"]
    assert main([*argv, "--current", "0.4", "--out", str(first), "-q"]) == 0
    config = sashil.load_run(first).config
    assert (config["controller"]["law"], config["controller"]["current_a"]) == ("passive", 0.4)
    assert config["sweep"]["stepped"] is True and config["sweep"]["steps"] == 2
    rerun("sweep", first, again, "-q")
    assert (first / "transmissibility.csv").read_text() == (again / "transmissibility.csv").read_text()
    for sub in ("f1.500Hz", "f3.000Hz"):
        assert_same_data(first / sub, again / sub)
        assert np.median(read_data_csv(again / sub / "data.csv")["current_cmd_a"]) == pytest.approx(0.4)
    # --no-stepped overrides the config's stepped sine
    chirp = tmp_path / "c"
    rerun("sweep", first, chirp, "-q", "--no-stepped", "--duration", "1")
    assert (chirp / "chirp.png").exists() and sashil.load_run(chirp).config["sweep"]["stepped"] is False


def test_simulate_config_holds_the_drop_test_inputs_and_reruns_them(tmp_path):
    first, again = tmp_path / "a", tmp_path / "b"
    argv = ["--theta0-deg", "-3", "--current", "0.4", "--duration", "1.5", "--start", "moving"]
    assert main(["simulate", *argv, "--out", str(first)]) == 0
    assert sashil.load_run(first).config["simulate"] == {
        "input": None,
        "theta0_deg": -3.0,
        "current_a": 0.4,
        "duration_s": 1.5,
        "start": "moving",
    }
    rerun("simulate", first, again)
    assert_same_data(first, again, ("time_s", "current_a", "theta_rad"))


def test_a_bad_value_from_the_config_names_the_key(tmp_path, capsys):
    config = tmp_path / "c.yaml"
    config.write_text("drop_test:\n  currents_a: [0.5, 3.0]\n")
    out = tmp_path / "o"
    assert main(["drop-test", "--config", str(config), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "drop_test.currents_a: expected a current in [0, 1] A" in err
    assert not out.exists()


@pytest.mark.e2e  # a whole calibration (a few seconds of fitting)
def test_calibrate_config_holds_plan_inertia_model_and_reruns_them(tmp_path):
    plan = {"currents_a": [0.0, 1.0], "small_currents_a": [], "road_currents_a": [], "drop_duration_s": 1.5}
    plan |= {"validate_currents_a": [0.5]}
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump({"calibrate": plan}))
    first, again = tmp_path / "a", tmp_path / "b"
    argv = ["calibrate", "--config", str(path), "--inertia", "1.1", "--model", "bouc-wen", "--no-profile"]
    assert main([*argv, "--out", str(first), "-q"]) == 0
    section = sashil.load_run(first).config["calibrate"]
    assert (section["inertia_kg_m2"], section["model"], section["profile_n"]) == (1.1, "bouc-wen", False)
    rerun("calibrate", first, again, "-q")
    runs = sorted(p.name for p in (first / "runs").iterdir())
    assert runs == sorted(p.name for p in (again / "runs").iterdir()) and len(runs) == 3
    for name in runs:
        assert_same_data(first / "runs" / name, again / "runs" / name)
    fitted = [yaml.safe_load((folder / "params.yaml").read_text())["params"] for folder in (first, again)]
    assert fitted[0] == fitted[1] and fitted[0]["J"] == 1.1
