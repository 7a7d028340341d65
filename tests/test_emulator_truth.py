"""``sashil emulate --truth``: the plant's true state per sample sent, joined with what the host got.

The link tests run the emulator in a thread (or, for the exit paths, as a process) and the host
over the real pyserial / python-can stacks; they wait on samples with generous timeouts and never
sleep, so a loaded machine makes them slower, not flaky.
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys

import numpy as np
import pytest

from sashil.cli import main
from sashil.drivers import open_rig, rig_parts
from sashil.drivers.emulator import TRUTH_COLUMNS, EmulatorThread, TruthLog, read_truth_csv
from sashil.drivers.firmware import compiler
from sashil.drivers.interface import TWO_PI, RigCommand
from sashil.engine.resolve import default_config
from sashil.errors import DataFileError
from sashil.models.hysteresis import rig_params
from sashil.models.plant import RigPlant
from sashil.recording.data_file import write_data_csv

SASHIL = [sys.executable, "-c", "import sys; from sashil.cli import main; sys.exit(main(sys.argv[1:]))"]

NEEDS_CC = pytest.mark.skipif(compiler() is None, reason="no C compiler")


def mismatched_config() -> dict:
    config = default_config()
    config["mismatch"].update(fraction=0.10, pattern="alternate", coil_tau=0.10)
    return config


def host_config(driver: str, port: str) -> dict:
    config = default_config()
    config["driver"].update(
        name=driver, port=port, can_interface="slcan", sample_timeout_ms=500.0, connect_timeout_s=5.0
    )
    return config


def host_session(driver: str, port: str, cycles: int) -> list:
    """Drive 0.8 A and read ``cycles`` samples; returns them (RigSample)."""
    samples = []
    with open_rig(rig_parts(host_config(driver, port))) as rig:
        rig.configure()
        rig.activate()
        for _ in range(cycles):
            samples.append(rig.read(0, 0))
            rig.write(RigCommand(0.8), 0, 0)
    return samples


def test_truth_log_grows_by_blocks_and_round_trips_through_csv(tmp_path):
    plant = RigPlant(rig_params(default_config()["model"]))
    log = TruthLog(block_rows=4)
    for k in range(10):
        plant.step(1e-3, 1.0)
        log.record(k + 1, 1000 * k, plant)
    assert len(log) == 10
    cols = log.columns()
    assert list(cols) == list(TRUTH_COLUMNS) and cols["seq"].dtype == np.int64
    assert cols["seq"].tolist() == list(range(1, 11)) and cols["device_time_us"][-1] == 9000
    assert cols["torque_true_nm"][-1] == plant.damper_torque() and cols["current_true_a"][-1] == plant.state.current_a
    back = read_truth_csv(write_data_csv(tmp_path / "truth.csv", log.columns()))
    for name in TRUTH_COLUMNS:
        assert np.array_equal(back[name], cols[name])  # repr-exact floats


def test_read_truth_csv_header_only_and_bad_header(tmp_path):
    empty = tmp_path / "empty.csv"
    empty.write_text(",".join(TRUTH_COLUMNS) + "\n")
    assert read_truth_csv(empty)["seq"].size == 0
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,theta_rad\n0,0\n")
    with pytest.raises(DataFileError) as err:
        read_truth_csv(bad)
    assert str(err.value).startswith(f"{bad}: expected the truth columns") and "\n" not in str(err.value)


@pytest.mark.e2e
@pytest.mark.parametrize("board", ["python", pytest.param("c", marks=NEEDS_CC)])
@pytest.mark.parametrize("transport, driver", [("serial", "serial"), ("slcan", "can")])
def test_truth_rows_match_the_samples_the_host_received(transport, driver, board):
    config = mismatched_config()
    truth = TruthLog()
    with EmulatorThread(config, transport, truth=truth, board=board) as emu:
        samples = host_session(driver, emu.port, 300)
        plant = emu.device.rig.plant
    # the emulator's plant is the mismatched one (SimulatedRig.from_config applies config["mismatch"])
    model = config["model"]["params"]
    assert plant.params.k == pytest.approx(0.9 * model["k"]) and plant.params.c1 == pytest.approx(1.1 * model["c1"])
    assert plant.coil_tau_s == pytest.approx(1.1 * config["rig"]["coil_tau_s"])

    cols = truth.columns()
    assert len(cols["seq"]) >= len(samples)
    assert np.all(np.diff(cols["seq"]) == 1)  # every sample taken has its row, in order
    row_of = {int(seq): k for k, seq in enumerate(cols["seq"])}
    rows = np.array([row_of[s.seq] for s in samples])  # KeyError: a host sample the truth lacks
    assert np.array_equal(cols["device_time_us"][rows], [s.device_time_us for s in samples])
    count = TWO_PI / 4096
    theta_host = np.array([s.theta_rad for s in samples])
    assert np.max(np.abs(theta_host - cols["theta_true_rad"][rows])) <= count + 1e-12  # two roundings
    assert np.allclose(
        [s.current_a for s in samples], cols["current_true_a"][rows], rtol=0, atol=0.25e-3 + 1e-9
    )  # 0.5 mA on the wire
    assert cols["current_true_a"][rows][-1] > 0.5  # the host's 0.8 A reached the coil
    # T = alpha(i) z + c(i) theta_dot of the plant's (mismatched) parameters
    p = plant.params
    i, z, v = cols["current_true_a"], cols["z_true"], cols["theta_dot_true_rad_s"]
    expected = (p.alpha1 + p.alpha2 * i) * z + (p.c1 + p.c2 * i) * v
    assert np.allclose(cols["torque_true_nm"], expected, rtol=1e-12, atol=1e-12)
    assert np.all(np.diff(cols["plant_time_s"]) > 0)


def test_bad_truth_path_is_one_line(tmp_path, capsys):
    target = tmp_path / "no-such-dir" / "truth.csv"
    rc = main(["emulate", "--truth", str(target), "--priority", "0"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and f"--truth {target}: cannot write" in err


@pytest.mark.e2e
@pytest.mark.parametrize("stop", ["sigterm", "sigint", "duration"])
def test_emulate_process_writes_the_truth_when_it_exits(tmp_path, stop):
    truth_path, link = tmp_path / "truth.csv", tmp_path / "rig"
    argv = [*SASHIL, "emulate", "--link", str(link), "--truth", str(truth_path), "--priority", "0"]
    if stop == "duration":
        argv += ["--duration", "0.5"]  # ends on its own, with no host: no samples, the header only
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    samples = []
    try:
        assert "rig on" in proc.stdout.readline()
        if stop != "duration":
            samples = host_session("serial", str(link), 50)
            proc.send_signal(signal.SIGTERM if stop == "sigterm" else signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    cols = read_truth_csv(truth_path)
    assert {s.seq for s in samples} <= set(cols["seq"].tolist())
    assert len(cols["seq"]) >= len(samples) and (stop == "duration") == (len(cols["seq"]) == 0)
    assert f"truth: {len(cols['seq'])} samples written to {truth_path}" in err
    assert math.isfinite(cols["torque_true_nm"].sum())
