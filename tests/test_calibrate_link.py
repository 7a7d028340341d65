"""``sashil calibrate`` over a real link: the emulator in its own process behind a pty.

Real processes on the real clock (pyserial); they wait on real time with generous timeouts, and
the host rides through link gaps of up to 0.5 s (a shared CI machine pauses processes)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from sashil.config import load_params
from sashil.engine.resolve import default_config
from sashil.lab.calibration import calibrate_emulated

pytestmark = pytest.mark.e2e  # the emulator in a child process over a pty, on the wall clock

#: a fresh interpreter per command; the module's tests fork a warm one instead (:func:`_warm_sashil`)
COLD_SASHIL = [sys.executable, "-m", "sashil"]
SASHIL = COLD_SASHIL


@pytest.fixture(scope="module", autouse=True)
def _warm_sashil(warm_sashil):
    """This module's ``sashil`` commands fork the warm interpreter (tests/warm_sashil.py): they are
    signalled with SIGINT or SIGTERM only, which its client passes on."""
    global SASHIL
    SASHIL = warm_sashil.command
    yield
    SASHIL = COLD_SASHIL


SMALL_PLAN = {
    "currents_a": [0.0, 1.0],
    "small_currents_a": [],
    "road_currents_a": [1.0],
    "validate_currents_a": [0.5],
    "drop_duration_s": 3.0,
    "road_duration_s": 6.0,
    "road_f_start_hz": 1.2,
    "road_f_stop_hz": 2.2,
}


def test_calibrate_an_emulated_damper_over_serial(tmp_path):
    config = default_config()
    config["calibrate"].update(SMALL_PLAN)
    config["model"]["params"].update(k=100.0, c1=0.5, c2=1.0)
    params = calibrate_emulated(config, tmp_path / "cal", transport="serial")
    p = load_params(params)["params"]
    # a small plan (two drops, one road run) on a busy machine: the accuracy is tools/bench_calibrate.py's
    # business; this checks that the chain works and lands near the truth
    assert p["k"] == pytest.approx(100.0, rel=0.02)
    for i in (0.0, 1.0):
        assert p["c1"] + p["c2"] * i == pytest.approx(0.5 + 1.0 * i, rel=0.25)
    assert (tmp_path / "cal" / "validation.png").is_file()
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    runs = summary["runs"]
    assert all(r["release_estimated"] for r in runs)  # found in the data: nobody told the host
    # the emulator's operator read each attempt's prompt: every drop from its step's angle (a repeat too)
    assert all(abs(r["hold_angle_deg"] - r["theta0_deg"]) < 0.1 for r in runs)
    # each step ran in a loop process of its own (one thread), the step's stage built there from its spec
    assert all(r["loop_process"]["threads"] == 1 and r["loop_process"]["pid"] != os.getpid() for r in runs)
    road = next(r for r in runs if r["kind"] == "road")
    data = (tmp_path / "cal" / "runs" / road["name"] / "data.csv").read_text().splitlines()
    header = data[0].split(",")
    road_col = [float(line.split(",")[header.index("theta_road_rad")]) for line in data[1:]]
    assert max(road_col) - min(road_col) > 0.02  # the wheel moved (about 2 deg peak to peak)


class Emulator:
    def __init__(self, tmp: Path, *flags: str):
        self.link = str(tmp / "rig")
        self.proc = subprocess.Popen(
            [*SASHIL, "emulate", "--link", self.link, "--duration", "120", "--hold-deg", "-5", *flags],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        line = self.proc.stdout.readline()
        assert "rig on /dev/" in line, line + self.proc.stderr.read()

    def stop(self) -> str:
        """Stop the emulator; returns what it said on stderr (once: empty the second time)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        return self.proc.communicate(timeout=30)[1] or ""


@pytest.fixture
def emulator(tmp_path):
    started: list[Emulator] = []

    def start(*flags: str) -> Emulator:
        emu = Emulator(tmp_path, *flags)
        started.append(emu)
        return emu

    yield start
    for emu in started:
        emu.stop()


def calibrate(tmp_path: Path, link: str) -> tuple[subprocess.CompletedProcess, Path]:
    config = tmp_path / "link.yaml"
    config.write_text(yaml.safe_dump({"driver": {"link_lost_ms": 500.0}, "calibrate": SMALL_PLAN}))
    out = tmp_path / "cal"
    done = subprocess.run(
        [*SASHIL, "calibrate", "--driver", "serial", "--port", link, "--config", str(config), "--out", str(out), "-q"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    return done, out


def test_a_device_reporting_a_stuck_encoder_trips_the_plan_with_one_line(tmp_path, emulator):
    # the board flags the frozen encoder: the safety supervisor trips at once, exit 3
    emu = emulator("--stuck-sensor-after", "0")
    done, out = calibrate(tmp_path, emu.link)
    assert done.returncode == 3, done.stderr
    errors = [line for line in done.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and "stuck sensor" in errors[0]
    assert not (out / "params.yaml").exists()


def test_a_plan_cut_short_keeps_its_data_and_exits_1(tmp_path, emulator):
    emu = emulator("--disconnect-after", "2.5")  # 1 s held, then 1.5 s of the first drop
    done, out = calibrate(tmp_path, emu.link)
    assert done.returncode == 1, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "error" and "cut short" in summary["note"]
    first = out / "runs" / summary["runs"][0]["name"] / "data.csv"
    assert first.is_file() and len(first.read_text().splitlines()) > 500  # over a second of the drop kept
    assert not (out / "params.yaml").exists()


def test_the_emulators_operator_holds_where_the_hosts_prompt_asks(tmp_path, emulator):
    # started with --hold-deg -5, it reads the host's console: the plan's first drop asks for -3.5 deg
    console = tmp_path / "console.txt"
    console.touch()
    emu = emulator("--prompts", str(console), "--disconnect-after", "2.5")  # the first drop, then cut short
    config = tmp_path / "link.yaml"
    plan = {**SMALL_PLAN, "theta0_deg": -3.5}
    config.write_text(yaml.safe_dump({"driver": {"link_lost_ms": 500.0}, "calibrate": plan}))
    out = tmp_path / "cal"
    command = [*SASHIL, "calibrate", "--driver", "serial", "--port", emu.link, "--config", str(config), "-q"]
    with console.open("w") as host_console:
        done = subprocess.run(
            [*command, "--out", str(out)],
            stdout=subprocess.PIPE,
            stderr=host_console,
            text=True,
            timeout=300,
        )
    assert done.returncode == 1, console.read_text()
    assert "press the arm to -3.5 deg" in console.read_text()  # the prompt is on the console, -q or not
    first = json.loads((out / "summary.json").read_text())["runs"][0]
    assert first["theta0_deg"] == -3.5 and abs(first["hold_angle_deg"] + 3.5) < 0.1
    said = emu.stop()
    assert "holds the arm at -3.5 deg" in said and "as the host's last prompt asks" in said
