"""A lab's own law, end to end: the example package (examples/soft_skyhook, installed by the
README's test command) on the simulated rig and over the emulated serial link, the same file by
path, and a law too slow for its period with the device's watchdog keeping the coil safe."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from doc_blocks import example
from test_link_e2e import Emulator, _warm_sashil, relaxed_config, sashil  # noqa: F401 - the fixture

import sashil as sashil_api
from sashil.control.law_registry import find_law

pytestmark = pytest.mark.e2e  # wall clock, real pty and processes

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "soft_skyhook" / "soft_skyhook.py"


def test_the_example_package_registers_its_law_by_entry_point():
    entry = find_law("soft-skyhook")
    assert entry.origin == "package sashil-soft-skyhook" and entry.spec == "soft_skyhook:SoftSkyhook"


def test_the_example_runs_on_the_simulated_rig_from_python(tmp_path):
    run = sashil_api.run(
        "soft-skyhook", duration_s=1.0, set={"controller.c_sky": 2.0, "controller.ramp_s": 0.2}, out=tmp_path / "sim"
    )
    assert run.summary["exit_status"] == "ok" and run.config["controller"]["law"] == "soft-skyhook"
    assert run.config["controller"]["c_sky"] == 2.0 and run.config["controller"]["ramp_s"] == 0.2
    torque = run.data["torque_cmd_nm"]
    assert np.all(np.isfinite(torque)) and np.ptp(run.data["current_cmd_a"]) > 0.1  # the law commanded


@pytest.mark.parametrize("law", ["soft-skyhook", f"{EXAMPLE}:SoftSkyhook"], ids=["entry-point", "file"])
def test_the_example_runs_over_the_emulated_serial_link_unchanged(tmp_path, law):
    emu = Emulator(tmp_path, "serial", "python")
    try:
        out = tmp_path / "link"
        done = sashil(
            "run",
            "--driver", "serial", "--port", emu.link, "--config", relaxed_config(tmp_path),
            "--controller", law, "--set", "controller.c_sky=2", "--road", "sine:1.2:1.0",
            "--duration", "2", "--out", str(out),
        )  # fmt: skip
    finally:
        emu.stop()
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "ok" and summary["timing"]["cycles"] >= 1800
    run = sashil_api.load_run(out)
    assert run.config["controller"]["law"] == law and np.ptp(run.data["current_cmd_a"]) > 0.1


@pytest.mark.alone  # the device watchdog timed to 50 ms + one cycle + the coil's decay
def test_a_law_slower_than_its_period_lets_the_device_watchdog_rest_the_coil(tmp_path):
    """A law that blocks for 0.2 s: the host cannot command meanwhile, so the board's watchdog
    (driver.watchdog_ms, 50 ms) cuts the coil current; the loop counts the missed deadlines."""
    from sashil.drivers.emulator import read_truth_csv

    slow = tmp_path / "slow.py"
    slow.write_text(
        "import time\nfrom sashil.control import Law\n\n\n"
        "class Slow(Law):\n    name = 'slow'\n    stalled = False\n\n"
        "    def current(self, state):\n"
        "        if state.time_s > 0.5 and not self.stalled:\n"
        "            self.stalled = True\n            time.sleep(0.2)\n"
        "        return 1.0\n"
    )
    truth_path = tmp_path / "truth.csv"
    emu = Emulator(tmp_path, "serial", "python", "--truth", str(truth_path))
    try:
        out = tmp_path / "slow"
        done = sashil(
            "run", "--driver", "serial", "--port", emu.link, "--config", relaxed_config(tmp_path),
            "--controller", f"{slow}:Slow", "--duration", "1.5", "--out", str(out),
        )  # fmt: skip
    finally:
        emu.stop()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["timing"]["missed_deadlines"] >= 150, summary["timing"]  # the stall, as missed periods
    assert done.returncode in (0, 1), done.stderr  # a link that lost samples in the stall may end the run
    truth = read_truth_csv(truth_path)
    t_us, current = truth["device_time_us"], truth["current_true_a"]
    data = sashil_api.load_run(out).data
    stall = int(np.flatnonzero(np.diff(data["time_s"]) > 0.1)[0])  # the last cycle before the law blocked
    last = int(np.flatnonzero(truth["seq"] == data["seq"][stall])[0])  # its sample in the device's truth
    assert current[last] > 0.9  # the law's 1 A was flowing
    rest = last + int(np.flatnonzero(current[last:] < 0.05)[0])
    # the emulated board is a process on a shared machine: when the VM pauses it (a gap between its
    # 1 ms ticks in the truth, up to 9 ms measured), its watchdog checks that much later on the
    # device's clock, which a board on its own core never does; the longest such gap is allowed for
    pause = max(0.0, float(np.max(np.diff(t_us[last : rest + 1]))) - 1_000)
    # at rest within the watchdog (50 ms) + one cycle + the coil's decay from 1 A to 0.05 A (3 tau, 30 ms)
    assert t_us[rest] - t_us[last] <= 50_000 + 1_000 + 35_000 + pause, ((t_us[rest] - t_us[last]) / 1e3, pause / 1e3)


def test_the_tutorials_python_example_runs(tmp_path, monkeypatch):
    code = example("tutorials/your-own-law.md", "python", "sashil.run(")
    monkeypatch.chdir(tmp_path)  # the runs' default folders land under runs/ here
    scope: dict = {}
    exec(compile(code, "your-own-law.md", "exec"), scope)
    assert scope["run"].config["controller"]["law"] == "soft-skyhook"
    assert [r.name for r in scope["drop"].runs] == ["i0.000A", "i1.000A"]
