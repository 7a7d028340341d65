"""End to end: ``sashil emulate`` in its own process, ``sashil drop-test``/``run`` over the pty.

Real processes on the real clock through pyserial and python-can's slcan interface; they wait
on real time with generous timeouts (no fixed sleeps). Timing on a shared CI machine is noisy, so
the normal runs ride through link gaps of up to 0.5 s (at 0 A from 2.5 ms on); the fault runs use
the defaults (0 A after 2.5 ms, the run ends after 25 ms).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sashil.drivers import rig_parts
from sashil.drivers.firmware import compiler

pytestmark = pytest.mark.e2e  # wall clock, real pty/link/processes: `pytest -m "not e2e"` skips them

#: a fresh interpreter per command; the module's tests fork a warm one instead (:func:`_warm_sashil`)
COLD_SASHIL = [sys.executable, "-c", "import sys; from sashil.cli import main; sys.exit(main(sys.argv[1:]))"]
SASHIL = COLD_SASHIL
COUNT_DEG = 360.0 / 4096  # encoder resolution (rig.encoder_counts_per_rev default)
DRIVERS = [("serial", "serial"), ("slcan", "can")]
BOARDS = ["python", pytest.param("c", marks=pytest.mark.skipif(compiler() is None, reason="no C compiler"))]


@pytest.fixture(scope="module", autouse=True)
def _warm_sashil(warm_sashil):
    """This module's ``sashil`` commands (the emulator's too) fork the warm interpreter; they are
    signalled with SIGTERM only, which its client passes on."""
    global SASHIL
    SASHIL = warm_sashil.command
    yield
    SASHIL = COLD_SASHIL


class Emulator:
    def __init__(self, tmp: Path, transport: str, board: str, *flags: str):
        self.link = str(tmp / f"rig-{transport}")
        command = [*SASHIL, "emulate", "--transport", transport, "--link", self.link, "--duration", "120"]
        self.proc = subprocess.Popen(
            [*command, "--board", board, *flags],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        line = self.proc.stdout.readline()  # "sashil emulate: serial rig on /dev/pts/N (link ...)"
        assert "rig on /dev/" in line, line + self.proc.stderr.read()
        assert f"({board} board)" in line
        assert os.path.islink(self.link)

    def stop(self) -> str:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        _, err = self.proc.communicate(timeout=30)
        return err


@pytest.fixture(params=BOARDS)
def emulator(tmp_path, request):
    """``sashil emulate`` with each board: the firmware's C logic and the Python one."""
    started = []

    def start(transport, *flags):
        emu = Emulator(tmp_path, transport, request.param, *flags)
        started.append(emu)
        return emu

    yield start
    for emu in started:
        emu.stop()


def sashil(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*SASHIL, *args], capture_output=True, text=True, timeout=timeout)


def relaxed_config(tmp: Path) -> str:
    """A config file that relaxes the link's timeouts (sample timeout, hence the write timeout, 250 ms;
    link lost 500 ms) and its loss budgets (any share of deadlines or samples): the runs that use it
    compare what they record, and a loaded machine can starve the emulator process for longer than
    the bench defaults allow (the timeouts and budgets themselves are tested with the defaults)."""
    path = tmp / "link.yaml"
    path.write_text(
        "driver:\n  sample_timeout_ms: 250.0\n  link_lost_ms: 500.0\n  max_lost_fraction: 1.0\n"
        "loop:\n  max_missed_fraction: 1.0\n"
    )
    return str(path)


def over_link(verb: str, driver: str, emu: Emulator, out: Path, *flags: str) -> subprocess.CompletedProcess:
    """``sashil VERB`` over ``driver`` to the emulator ``emu``, writing ``out``, with :func:`relaxed_config`."""
    config = relaxed_config(out.parent)
    return sashil(verb, "--driver", driver, "--port", emu.link, "--out", str(out), "--config", config, *flags)


@pytest.fixture(scope="module")
def sim_drop(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "drop"
    done = sashil("drop-test", "--duration", "3", "--out", str(out))
    assert done.returncode == 0, done.stderr
    return json.loads((out / "summary.json").read_text())["runs"][0]


@pytest.mark.parametrize("transport, driver", DRIVERS)
def test_drop_test_over_the_link_matches_the_sim_backend(transport, driver, emulator, tmp_path, sim_drop):
    emu = emulator(transport, "--hold-deg", "-5", "--release-after", "1")
    out = tmp_path / "drop"
    done = over_link("drop-test", driver, emu, out, "--duration", "3")
    assert done.returncode == 0, done.stderr
    run = json.loads((out / "summary.json").read_text())["runs"][0]
    assert run["release_estimated"]  # found from the data: nobody told the host when the operator let go
    assert abs(run["hold_angle_deg"] - sim_drop["hold_angle_deg"]) <= COUNT_DEG
    # peaks within two encoder counts, period within two loop cycles (timing jitter) and the longest
    # link gap: an emulator descheduled on a busy machine leaves a hole in the record that long, and
    # the period is known to within it
    assert np.allclose(run["peaks_deg"][:4], sim_drop["peaks_deg"][:4], atol=2 * COUNT_DEG)
    gap_s = float((run.get("link") or {}).get("gap_max_ms") or 0.0) * 1e-3
    assert abs(run["period_s"] - sim_drop["period_s"]) < 0.002 + gap_s, run.get("link")


@pytest.mark.parametrize("transport, driver", DRIVERS)
def test_run_over_the_link_with_corrupt_frames_completes_and_counts_them(transport, driver, emulator, tmp_path):
    emu = emulator(transport, "--corrupt-rate", "0.01", "--seed", "7")
    out = tmp_path / "run"
    done = over_link("run", driver, emu, out, "--duration", "3")
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["timing"]["cycles"] >= 2500
    emu_report = emu.stop()
    corrupted = int(emu_report.split("frames corrupted ")[1].split(",")[0])
    assert corrupted > 10
    # the host's count: bad frames (serial: CRC) or missing samples (CAN drops bad-CRC frames on the bus)
    counted = [line for line in done.stderr.splitlines() if "link:" in line]
    assert counted, done.stderr
    bad = int(counted[-1].split(" bad frames")[0].split(", ")[-1])
    missed = int(counted[-1].split(" samples missed")[0].split(", ")[-1])
    assert (bad if driver == "serial" else missed) > 0


@pytest.mark.alone  # the default 2.5 ms sample timeout, which a starved pty exceeds
@pytest.mark.parametrize("fault", ["--stall-after", "--disconnect-after"])
@pytest.mark.parametrize("transport, driver", DRIVERS)
def test_link_fault_trips_to_zero_within_three_cycles(fault, transport, driver, emulator, tmp_path):
    """Default sample timeout (2.5 ms = 2.5 cycles at 1 kHz): the host gives up within 3 cycles.

    On a loaded shared machine the pty itself can stall for more than 2.5 ms (its kernel worker is
    not real-time); a run that ends that way before the injected fault is retried (at most 3 tries).
    """
    for attempt in range(3):
        emu = emulator(transport, fault, "1.0")  # after the run is up (the handshake comes before the set-up)
        out = tmp_path / f"run{attempt}"
        done = sashil(
            "run", "--driver", driver, "--port", emu.link, "--duration", "10", "--current", "0.5", "--out", str(out)
        )
        emu_report = emu.stop()
        data = (out / "data.csv").read_text().splitlines()
        if len(data) > 400:
            break
    assert done.returncode == 1, done.stderr
    error_lines = [line for line in done.stderr.splitlines() if line.startswith("sashil run: error")]
    assert len(error_lines) == 1 and ("no sample" in error_lines[0] or "link lost" in error_lines[0]), done.stderr
    assert len(data) > 400, f"ended before the fault: {error_lines} / {emu_report}"  # data up to the fault kept
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] != "ok"
    assert summary["timing"]["cycles"] <= len(data) - 1 + 3
    if fault == "--stall-after":  # silence: 0 A at the sample timeout, the end only at link-lost (25 ms)
        link = summary["link"]
        assert link["timeouts"] == 1 and 2.5 <= link["zero_current_after_ms"] < 25.0


@pytest.mark.alone  # the device watchdog timed to 50 ms + one cycle
def test_host_silence_lets_the_device_watchdog_cut_the_current(emulator, tmp_path):
    """A host that stops commanding: the device's current command is 0 within 50 ms + 1 cycle."""
    from sashil.drivers import open_rig
    from sashil.drivers.interface import FLAG_WATCHDOG, RigCommand
    from sashil.engine.resolve import default_config

    emu = emulator("serial")
    config = default_config()
    config["driver"].update(name="serial", port=emu.link, sample_timeout_ms=100.0)
    with open_rig(rig_parts(config)) as rig:
        rig.configure()
        rig.activate()
        for _ in range(300):
            rig.read(0, 0)
            rig.write(RigCommand(0.8), 0, 0)
        last_command_us = rig.read(0, 0).device_time_us  # the host falls silent here
        while True:
            sample = rig.read(0, 0)
            if sample.flags & FLAG_WATCHDOG:
                break
        assert sample.device_time_us - last_command_us <= 50_000 + 1_000 + 1_000  # + one cycle + sample phase
        later = [rig.read(0, 0) for _ in range(100)]
        assert later[-1].current_a < later[0].current_a  # the coil current decays towards 0
        assert all(s.flags & FLAG_WATCHDOG for s in later)


@pytest.mark.parametrize("transport, driver", DRIVERS)
@pytest.mark.alone  # the host's estimate joined to the truth by the device's sample times, to 0.2 count
def test_sweep_over_the_link_shakes_the_road_and_joins_the_emulator_truth(transport, driver, emulator, tmp_path):
    from sashil.drivers.emulator import read_truth_csv

    truth_path = tmp_path / "truth.csv"
    emu = emulator(transport, "--truth", str(truth_path))
    out = tmp_path / "sweep"
    done = over_link(
        "sweep",
        driver,
        emu,
        out,
        "--f-start",
        "1.5",
        "--f-stop",
        "1.5",
        "--duration",
        "2",
        "--amplitude-deg",
        "1",
        "--current",
        "0.3",
    )
    assert done.returncode == 0, done.stderr
    emu.stop()
    data = np.genfromtxt(out / "data.csv", delimiter=",", names=True)
    truth = read_truth_csv(truth_path)
    # on the real clock (the link paces it): 3000 cycles over at least the 1 s ramp + 2 s, then the
    # shutdown's 0 A row
    assert len(data) == 3000 + 1 and data["time_s"][-1] >= 2.9 and data["current_cmd_a"][-1] == 0.0
    late = data["time_s"] >= 1.5  # after the ramp: the road wheel turns +-1 deg at 1.5 Hz
    road_deg = np.degrees(data["theta_road_rad"][late])
    assert 0.8 <= (road_deg.max() - road_deg.min()) / 2 <= 1.2
    # every row's seq is a sample of the truth; the host's angle is the plant's to the encoder count
    row_of = {int(seq): k for k, seq in enumerate(truth["seq"])}
    rows = np.array([row_of[int(seq)] for seq in data["seq"]])
    assert np.max(np.abs(data["theta_rad"] - truth["theta_true_rad"][rows])) <= np.radians(COUNT_DEG) + 1e-12
    assert np.ptp(np.degrees(truth["theta_true_rad"][rows][late])) > 0.5  # the road's speed steps move the arm
    # the road the board applied, read back from the road encoder's edges on the device's clock
    # (the stream of every cycle keeps them), is the emulated wheel's true angle within a fifth of
    # a count wherever the edges around a sample saw the road: a link gap longer than calibrate's
    # GAP_S (a loaded host's pause; a fit's record ends at the first one) hides the edges the road
    # crossed in it, and the commands after it reach the wheel with another delay, up to the next
    # edge. Over the whole run, gaps and all, the error is a twentieth of a count RMS.
    from sashil.identify.road import applied_road_angle, held_speed
    from sashil.lab.calibration.analysis import GAP_S

    cycles = np.genfromtxt(out / "cycles.csv", delimiter=",", names=True)[:-1]  # less the shutdown's row
    rows = np.array([row_of[int(seq)] for seq in cycles["seq"]])
    count = np.radians(COUNT_DEG)
    device_s = cycles["device_time_us"] * 1e-6
    applied = applied_road_angle(
        device_s,
        np.where(cycles["road_edge_us"] >= 0, cycles["road_edge_us"] * 1e-6, np.nan),
        cycles["road_edge_dir"],
        np.rint(cycles["theta_road_rad"] / count),
        count,
        held_speed(cycles["road_speed_cmd_rad_s"]),
    )
    true_road = truth["theta_road_true_rad"][rows]
    assert np.max(np.abs(cycles["theta_road_rad"] - true_road)) <= 0.5 * count + 1e-12
    moving = device_s >= device_s[0] + 1.0
    error = np.abs(applied - true_road)
    assert np.sqrt(np.mean(error[moving] ** 2)) <= 0.05 * count
    edge_s = np.unique(cycles["road_edge_us"][cycles["road_edge_us"] >= 0]) * 1e-6
    seen = moving.copy()
    for k in np.flatnonzero(np.diff(device_s) > GAP_S):  # samples k and k + 1 bracket a gap
        before = edge_s[edge_s <= device_s[k]]
        after = edge_s[edge_s > device_s[k + 1]]
        seen &= (device_s <= (before[-1] if before.size else -np.inf)) | (
            device_s >= (after[0] if after.size else np.inf)
        )
    assert np.mean(seen[moving]) > 0.5  # most of the run is judged
    assert np.max(error[seen]) <= 0.2 * count
