"""End to end: ``sashil run``'s loop alone in its own process, the session reading its stream.

Real processes on the real clock (the simulated rig, and the emulated board over a pty); they
wait on what the processes say, with generous timeouts, and assert what the run folder holds.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import processes
import pytest
from processes import loop_of

import sashil
from sashil.engine.resolve import ConfigSource, Option, resolve
from sashil.engine.sashil_run import closed_loop
from sashil.recording.data_file import read_data_csv
from sashil.runtime import loop_server
from sashil.runtime.signals import StopFlag

pytestmark = pytest.mark.e2e

SASHIL = [sys.executable, "-m", "sashil"]


def _config(duration_s: float | None, *sets: str, driver: str | None = None, port: str | None = None):
    options = (Option("--duration", "run.duration_s", duration_s),)
    # the loop is measured elsewhere (tools/bench_loop.py); here a loaded machine must not fail the run
    relaxed = ("loop.max_missed_fraction=1.0", "driver.max_lost_fraction=1.0", "loop.rt.priority=0")
    return resolve(ConfigSource(sets=(*relaxed, *sets), driver=driver, port=port, options=options), "run")


def _rows(folder: Path) -> dict[str, np.ndarray]:
    return read_data_csv(folder / "data.csv", required=(), min_rows=0)


def test_the_loop_runs_in_a_process_of_its_own_with_one_python_thread(tmp_path):
    run = closed_loop(_config(0.5, "controller.current_a=0.3"), sashil.lab.Outputs(out=tmp_path / "run"), tune=True)
    summary = run.summary
    assert summary["exit_status"] == "ok", summary["error"]
    process = summary["loop_process"]
    assert process["pid"] != os.getpid() and process["threads"] == 1
    data = _rows(run.path)
    cycles = summary["timing"]["cycles"]
    assert cycles == 500 and len(data["time_s"]) == cycles + 1  # every cycle, then the safe state's row
    assert summary["recording"]["rows_written"] == cycles + 1 and summary["recording"]["rows_dropped"] == 0
    assert data["current_cmd_a"][-1] == 0.0 and np.all(data["current_cmd_a"][:-1] == 0.3)
    assert np.all(np.diff(data["seq"][:-1]) == 1)  # no row lost or repeated between the processes
    assert (run.path / "timing.npz").exists() and not list(Path("/dev/shm").glob(f"sashil-{os.getpid()}-*"))


def test_a_callers_stop_flag_stops_the_loop_process_cleanly(tmp_path):
    flag = StopFlag()
    views: list[str] = []

    class StopAfterRows:
        """A view that asks for a stop once it has seen 200 rows (what a page's STOP does)."""

        def start(self, stream, timing):
            def watch():
                while stream.rows_committed < 200:
                    time.sleep(0.005)
                views.append(f"{timing.cycles}")
                flag.request("STOP (test)")

            self.thread = threading.Thread(target=watch)
            self.thread.start()

        def close(self, trips, notes):
            self.thread.join()

    run = closed_loop(
        _config(None, "controller.current_a=0.5"),
        sashil.lab.Outputs(out=tmp_path / "run"),
        views=[StopAfterRows()],
        stop=flag,
    )
    assert run.summary["exit_status"] == "stopped" and run.summary["exit_code"] == 130
    assert run.summary["stop_reason"] == "STOP (test)"  # the caller's own words
    data = _rows(run.path)
    assert len(data["time_s"]) >= 200 and data["current_cmd_a"][-1] == 0.0
    # after the STOP the loop read on at 0 A: the measured current decays with the coil's lag to <= 0.05 A
    settled = run.summary["safe_state"]
    tail = data["current_a"][-settled["reads"] - 1 :]
    assert settled["confirmed"] and settled["after_s"] > 0.0 and tail[-1] <= 0.05
    assert tail[0] > 0.3 and np.all(np.diff(tail) <= 1e-9)  # from the 0.5 A it carried, falling all the way
    assert np.all(data["current_cmd_a"][-settled["reads"] - 1 :] == 0.0)
    assert views and int(views[0]) >= 200


def test_a_stalled_view_neither_slows_nor_stops_the_recording(tmp_path):
    class Stalled:
        def start(self, stream, timing):
            self.release = threading.Event()
            self.thread = threading.Thread(target=self.release.wait)  # reads nothing until the end
            self.thread.start()

        def close(self, trips, notes):
            self.release.set()
            self.thread.join()

    run = closed_loop(
        _config(0.4, "controller.current_a=0.2"), sashil.lab.Outputs(out=tmp_path / "run"), views=[Stalled()]
    )
    assert run.summary["exit_status"] == "ok"
    assert len(_rows(run.path)["time_s"]) == run.summary["timing"]["cycles"] + 1 == 401


def _start_run(out: Path, *args: str) -> tuple[subprocess.Popen, int]:
    """``sashil run`` in the background until its loop runs; the session's and the loop's pids."""
    proc = subprocess.Popen(
        [*SASHIL, "run", "--out", str(out), "-v", "--set", "loop.rt.priority=0", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    for line in proc.stderr:  # type: ignore[union-attr]
        if line.startswith("loop: running"):
            break
    else:
        raise AssertionError(f"the loop never ran (exit {proc.wait()})")
    return proc, loop_of(proc.pid)


def _kill_the_loop(out: Path, *args: str) -> tuple[subprocess.Popen, str]:
    """``sashil run ARGS`` whose loop process gets SIGKILL half a second into the run; the
    finished session process and its stderr."""
    proc, loop_pid = _start_run(out, *args)
    try:
        time.sleep(0.5)
        os.kill(loop_pid, signal.SIGKILL)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc, err


def _gone(pid: int, timeout_s: float = 60.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.02)
    return False


def test_kill_9_of_the_loop_keeps_the_data_and_the_summary_says_the_loop_died(tmp_path):
    out = tmp_path / "run"
    proc, err = _kill_the_loop(out, "--duration", "30", "--current", "0.4")
    assert proc.returncode == 1, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "error" and "loop process died" in summary["error"]
    assert summary["loop_process"]["died"]["exit_status"] == -signal.SIGKILL
    assert summary["loop_process"]["died"]["rig"]["note"] == "the simulated rig ended with the loop process"
    data = _rows(out)
    assert len(data["time_s"]) > 100 and np.all(np.diff(data["seq"][:-1]) == 1)  # every committed row, whole


def test_kill_9_of_the_session_ends_the_run_at_0_a_with_every_row_on_disk(tmp_path):
    out = tmp_path / "run"
    proc, loop_pid = _start_run(out, "--duration", "30", "--current", "0.4")
    try:
        time.sleep(0.5)
        proc.kill()
        proc.wait(timeout=30)
        assert _gone(loop_pid), "the loop process outlived its session"
    finally:
        proc.stderr.close()  # type: ignore[union-attr]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_status"] == "error" and summary["stop_reason"] == "the session process died"
    assert summary["loop_process"]["session_died"] is True
    data = _rows(out)
    cycles = summary["timing"]["cycles"]
    settled = summary["safe_state"]  # the loop read on at 0 A until the coil's current decayed
    assert settled["confirmed"] and settled["current_a"] <= 0.05 and settled["reads"] > 0
    assert cycles < 30_000 and len(data["time_s"]) == cycles + settled["reads"] + 1  # then the safe state's row
    assert np.all(np.diff(data["seq"][:-1]) == 1) and data["current_cmd_a"][-1] == 0.0
    assert data["road_speed_cmd_rad_s"][-1] == 0.0  # the road at rest


def test_a_script_that_runs_its_own_law_at_top_level_runs_once(tmp_path):
    script = tmp_path / "my_law.py"
    script.write_text(
        "import sys\n"
        "import sashil\n"
        "from sashil.control.law_api import Law, Param\n\n\n"
        "class Level(Law):\n"
        '    """A constant current."""\n\n'
        '    name = "level"\n'
        '    level = Param(0.2, unit="A", low=0.0, high=1.0, doc="the current")\n\n'
        "    def current(self, state):\n"
        "        return self.level\n\n\n"
        'print("top level", file=sys.stderr)\n'
        "run = sashil.run(Level, duration_s=0.2, out=sys.argv[1], set=['loop.rt.priority=0'])\n"
        'print("RESULT", run.summary["exit_status"], run.summary["loop_process"]["threads"])\n'
    )
    done = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "out")], capture_output=True, text=True, timeout=120, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["RESULT ok 1"]  # one run: the imports stopped at its call
    assert sorted(p.name for p in tmp_path.iterdir()) == ["my_law.py", "out"]
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["controller"].lower().endswith("level")


def test_a_port_that_cannot_be_opened_is_one_line_and_leaves_no_folder(tmp_path):
    done = subprocess.run(
        [*SASHIL, "run", "--driver", "serial", "--port", "/dev/ttyUSB9", "--out", str(tmp_path / "run")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2 and "/dev/ttyUSB9" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "run").exists()


def test_kill_9_of_the_loop_over_serial_the_session_reopens_the_board_and_confirms_0_a(tmp_path):
    from test_link_e2e import Emulator, relaxed_config

    emu = Emulator(tmp_path, "serial", "python")
    out = tmp_path / "run"
    try:
        link = ("--driver", "serial", "--port", emu.link, "--config", relaxed_config(tmp_path))
        proc, err = _kill_the_loop(out, *link, "--duration", "30", "--current", "0.8")
    finally:
        emu.stop()
    assert proc.returncode == 1, err
    summary = json.loads((out / "summary.json").read_text())
    rig = summary["loop_process"]["died"]["rig"]
    assert rig["reopened"] and rig["safe"] and abs(rig["current_a"]) <= 0.05, rig
    assert "the rig reopened" in err and "coil at" in err
    assert len(_rows(out)["time_s"]) > 100


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one CPU: nothing to keep off")
def test_the_session_keeps_off_the_loops_cpu_while_it_runs(tmp_path):
    before = os.sched_getaffinity(0)
    loop_cpu = max(before)
    seen: list[set[int]] = []

    class Affinity:
        def start(self, stream, timing):
            seen.append(os.sched_getaffinity(0))

        def close(self, trips, notes):
            pass

    run = closed_loop(
        _config(0.2, f"loop.rt.cpu={loop_cpu}"), sashil.lab.Outputs(out=tmp_path / "run"), views=[Affinity()]
    )
    assert run.summary["realtime"]["cpu_affinity"]["detail"] == f"CPU {loop_cpu}"
    assert run.summary["realtime"]["session"] == f"kept off CPU {loop_cpu}"
    assert seen == [before - {loop_cpu}] and os.sched_getaffinity(0) == before


def test_a_disk_too_full_for_the_run_ends_the_loop_process_before_anything_is_energised(tmp_path, monkeypatch):
    import shutil
    from collections import namedtuple

    from sashil.errors import DiskSpaceError

    def children() -> set[int]:  # this process's loop processes (a session-wide helper of the tests may be a child)
        server = loop_server.running()
        return set(processes.children(os.getpid())) - {server.pid} | set(
            processes.children(server.pid) if server else ()
        )

    before = children()
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**9, 10**9 - 10**6, 10**6))
    with pytest.raises(DiskSpaceError, match="MB free on its disk"):
        closed_loop(_config(60.0, "controller.current_a=0.5"), sashil.lab.Outputs(out=tmp_path / "run"))
    assert children() == before  # no loop process left
    assert not (tmp_path / "run" / "data.csv").exists()


def test_a_drop_test_on_the_real_clock_runs_each_drop_in_a_loop_process(tmp_path):
    """The drop's plan is built again in the loop process; the session's twin takes what it saw,
    and the record, its metrics and the views are as in one process."""
    relaxed = ("loop.max_missed_fraction=1.0", "driver.max_lost_fraction=1.0", "loop.rt.priority=0")
    sets = (*relaxed, "drop_test.currents_a=[0.0,0.8]", "drop_test.duration_s=1.5")
    views: list[tuple[str, int]] = []

    class Counting:
        def start(self, stream, timing):
            self.stream = stream
            views.append(("start", 0))

        def close(self, trips, notes):
            views.append(("close", self.stream.rows_committed))

    events: list[sashil.lab.Event] = []
    real = resolve(ConfigSource(sets=(*sets, "driver.clock=real")), "drop-test")
    run = sashil.lab.drop_test(real, sashil.lab.Outputs(out=tmp_path / "real"), events.append, views=[Counting()])
    virtual = sashil.lab.drop_test(
        resolve(ConfigSource(sets=(*sets, "driver.clock=virtual")), "drop-test"),
        sashil.lab.Outputs(out=tmp_path / "virtual"),
    )
    assert run.summary["exit_status"] == "ok", run.summary
    for entry, twin in zip(run.summary["runs"], virtual.summary["runs"], strict=True):
        process = entry["loop_process"]
        assert process["pid"] != os.getpid() and process["threads"] == 1
        assert entry["release_estimated"] is False  # the simulated operator let go, and said when
        assert entry["peaks_deg"][:2] == pytest.approx(twin["peaks_deg"][:2], abs=0.1)
        assert entry["period_s"] == pytest.approx(twin["period_s"], rel=0.02)
    assert [kind for kind, _ in views] == ["start", "close"] * 2
    # a view closes on its drop's whole stream: every row of the drop's cycles.csv, however many ran
    closed = [rows for kind, rows in views if kind == "close"]
    recorded = [len((run.path / name / "cycles.csv").read_text().splitlines()) - 1 for name in ("i0.000A", "i0.800A")]
    assert closed == recorded and min(recorded) > 0, views
    cycles = read_data_csv(run.path / "i0.800A" / "cycles.csv", required=(), min_rows=0)
    assert cycles["current_cmd_a"][-1] == 0.0 and np.all(cycles["current_cmd_a"][:-1] == 0.8)
    assert not list(Path("/dev/shm").glob(f"sashil-{os.getpid()}-*"))


def test_the_views_read_the_runs_health_while_it_runs(tmp_path):
    """Clipped cycles (and, on a link, lost samples, bad frames, watchdog samples) reach the stream's
    header about ten times a second; a view reads them without touching the loop's objects."""
    health: list[dict[str, int]] = []

    class Health:
        def start(self, stream, timing):
            self.stream = stream

        def close(self, trips, notes):
            health.append(self.stream.health())

    # a skyhook gain far beyond what the damper can give: most cycles are clipped
    config = _config(1.0, "controller.law=skyhook", "controller.c_sky=50", "run.road=sine:1.5:2")
    run = closed_loop(config, sashil.lab.Outputs(out=tmp_path / "run"), views=[Health()])
    clipped = run.summary["controller_stats"]["clipped_cycles"]
    assert clipped > 100
    assert clipped - 100 <= health[0]["clipped_cycles"] <= clipped  # written every 100 cycles at 1 kHz
    assert health[0]["samples_lost"] == health[0]["bad_frames"] == health[0]["watchdog"] == 0  # no link


@pytest.mark.alone  # the transmissibility of periods on the wall clock, which a starved loop stretches
def test_a_sweep_on_the_real_clock_runs_each_frequency_in_a_loop_process(tmp_path):
    """A stepped sine's frequencies each run in a loop process of their own: the views read the
    loop process's stream, and the transmissibility and clipping counts come back as in one process."""
    from sashil.runtime.stream import LOOP_PID_W

    relaxed = ("loop.max_missed_fraction=1.0", "driver.max_lost_fraction=1.0", "loop.rt.priority=0")
    sets = ("sweep.stepped=true", "sweep.steps=2", "sweep.f_start_hz=0.3", "sweep.f_stop_hz=5", "sweep.settle_s=1",
            "sweep.measure_s=1", "sweep.ramp_s=0.3", "controller.law=skyhook", "controller.c_sky=40")  # fmt: skip
    pids: list[int] = []

    class Pid:
        def start(self, stream, timing):
            pids.append(int(stream.header[LOOP_PID_W]))

        def close(self, trips, notes):
            pass

    real = sashil.lab.sweep(
        resolve(ConfigSource(sets=(*relaxed, *sets, "driver.clock=real")), "sweep"),
        sashil.lab.Outputs(out=tmp_path / "real"),
        views=[Pid()],
    )
    virtual = sashil.lab.sweep(
        resolve(ConfigSource(sets=(*relaxed, *sets, "driver.clock=virtual")), "sweep"),
        sashil.lab.Outputs(out=tmp_path / "v"),
    )
    assert len(pids) == 2 and os.getpid() not in pids and len(set(pids)) == 2
    # the arm follows the road well below resonance and stays behind it above (the real clock's
    # periods jitter on a loaded machine, the virtual clock's do not: the figures agree loosely)
    slow, fast = real.summary["points"]
    assert slow["transmissibility"] == pytest.approx(virtual.summary["points"][0]["transmissibility"], abs=0.1)
    assert fast["transmissibility"] < 0.9 * slow["transmissibility"]
    for point, twin in zip(real.summary["points"], virtual.summary["points"], strict=True):
        # the loop process's controller counted the clipped cycles; they came back with the run
        assert point["clipped_cycles"] == pytest.approx(twin["clipped_cycles"], rel=0.3) and point["clipped_cycles"] > 0
