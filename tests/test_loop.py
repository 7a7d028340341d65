"""The control loop on a virtual clock: deadlines, overruns, lifecycle and the safe state on faults."""

from __future__ import annotations

import json
import math
import shutil

import pytest

from sashil.control.stages import ConstantCurrent
from sashil.drivers.interface import RigCommand, RigInterface, RigSample
from sashil.engine import assemble
from sashil.errors import DeadlineMissedError, DiskSpaceError, DriverIOError
from sashil.recording.data_file import read_data_csv
from sashil.runtime import runner
from sashil.runtime.clock import VirtualClock
from sashil.runtime.loop import ControlLoop, record_columns
from sashil.runtime.session import InProcessLoop, run_session
from sashil.writer.run_folder import RunFolder

PERIOD = 1_000_000  # 1 kHz
COUNTS = 4096


class FaultyRig(RigInterface):
    """Test double (after ros2_control's test components): counts calls, fails on the Nth one."""

    name = "faulty"

    def __init__(self, fail_read_on=None, fail_write_on=None, stale_from=None, theta_deg=None):
        super().__init__()
        self.fail_read_on, self.fail_write_on = fail_read_on, fail_write_on
        self.stale_from = stale_from
        self.theta_deg = theta_deg or (lambda n: 1.0)
        self.calls = {name: 0 for name in ("configure", "activate", "read", "write", "deactivate", "close")}
        self.currents: list[float] = []
        self.read_times: list[tuple[int, int]] = []
        self.seq = 0

    def configure(self):
        self.calls["configure"] += 1

    def activate(self):
        self.calls["activate"] += 1

    def read(self, t_ns, dt_ns):
        self.calls["read"] += 1
        n = self.calls["read"]
        self.read_times.append((t_ns, dt_ns))
        if n == self.fail_read_on:
            raise DriverIOError("faulty: read failed (injected)")
        if self.stale_from is None or n < self.stale_from:
            self.seq += 1
        counts = round(math.radians(self.theta_deg(n)) * COUNTS / (2 * math.pi))
        return RigSample(self.seq, t_ns, t_ns // 1000, counts, 0, 0.1 * n, 0, COUNTS)

    def write(self, cmd, t_ns, dt_ns):
        self.calls["write"] += 1
        if self.calls["write"] == self.fail_write_on:
            raise DriverIOError("faulty: write failed (injected)")
        self.currents.append(cmd.current_a)

    def deactivate(self):
        self.calls["deactivate"] += 1
        self.currents.append(0.0)

    def close(self):
        self.calls["close"] += 1


class Stall:
    """Constant current; on cycle ``at`` the cycle takes ``stall_ns`` of (virtual) time."""

    def __init__(self, clock, at=None, stall_ns=0, current=0.5, stop=None):
        self.clock, self.at, self.stall_ns, self.stop = clock, at, stall_ns, stop
        self.command = RigCommand(current)
        self.n = 0
        self.dts: list[int] = []

    def step(self, sample, t_ns, dt_ns):
        self.n += 1
        self.dts.append(dt_ns)
        if self.n == self.at:
            self.clock.advance(self.stall_ns)
        if self.stop is not None and self.n == self.stop[0]:
            self.stop[1].request("test stop")
        return self.command


def test_deadlines_are_absolute_and_the_measured_period_is_passed():
    clock = VirtualClock(start_ns=5_000)
    rig = FaultyRig()
    stage = Stall(clock)
    result = ControlLoop(rig, stage, clock, 1000.0, duration_s=0.01).run()
    assert result.cycles == 10 and result.exit_status == "ok"
    assert [t for t, _ in rig.read_times] == [5_000 + k * PERIOD for k in range(10)]
    assert stage.dts == [0] + [PERIOD] * 9
    assert result.timing.summary()["lateness_us"]["max"] == 0.0


def test_overruns_are_counted_and_whole_periods_skipped():
    clock = VirtualClock()
    rig = FaultyRig()
    stage = Stall(clock, at=5, stall_ns=3_500_000)  # cycle 5 runs 3.5 periods long
    warnings: list[str] = []
    result = ControlLoop(rig, stage, clock, 1000.0, duration_s=0.02, warn=warnings.append).run()
    # cycle 5 started at 4 ms and ended at 7.5 ms: the deadlines 5, 6 and 7 ms are missed, the
    # next cycle runs at 7.5 ms (0.5 ms late against the 7 ms tick), then back on the grid
    times = [t for t, _ in rig.read_times]
    assert times[:6] == [0, 1e6, 2e6, 3e6, 4e6, 7.5e6]
    assert times[6:9] == [8e6, 9e6, 10e6]
    assert result.missed_deadlines == 2 and result.timing.overruns == 1
    assert stage.dts[5] == 3_500_000 and stage.dts[6] == 500_000
    assert result.cycles == 20  # the duration counts cycles run
    assert len(warnings) == 1 and "skipped 2 period(s)" in warnings[0]
    lateness = result.timing.column_us("lateness")
    assert lateness[5] == pytest.approx(2500.0)


def test_overrun_warnings_are_rate_limited():
    clock = VirtualClock()
    rig = FaultyRig()

    class EveryOther(Stall):
        def step(self, sample, t_ns, dt_ns):
            self.n += 1
            if self.n % 2 == 0:
                self.clock.advance(2_200_000)
            return self.command

    warnings: list[str] = []
    result = ControlLoop(
        rig, EveryOther(clock), clock, 1000.0, duration_s=1.0, warn=warnings.append, warn_interval_s=0.5
    ).run()
    # every even cycle stalls 2.2 periods: the next cycle misses one deadline (the last stall
    # has no next cycle in the 1000)
    assert result.timing.overruns == 499
    assert result.missed_deadlines == 499
    assert 2 <= len(warnings) <= 4  # over ~1.6 s of virtual time, one per 0.5 s
    assert "more overrun(s) since the last warning" in warnings[1]


def test_overrun_policy_fail_stops_in_the_safe_state():
    clock = VirtualClock()
    rig = FaultyRig()
    with pytest.raises(DeadlineMissedError, match="deadline missed: cycle 3"):
        ControlLoop(rig, Stall(clock, at=3, stall_ns=2_100_000), clock, 1000.0, 1.0, overrun_policy="fail").run()
    assert rig.currents[-2:] == [0.0, 0.0]  # the 0 A write, then deactivate
    assert rig.calls["deactivate"] == 1 and rig.calls["close"] == 1


def test_stage_ending_the_run_and_lifecycle_order():
    clock = VirtualClock()
    rig = FaultyRig()

    class Three:
        n = 0

        def step(self, sample, t_ns, dt_ns):
            self.n += 1
            return None if self.n > 3 else RigCommand(0.3)

    result = ControlLoop(rig, Three(), clock, 500.0).run()
    assert result.cycles == 3 and result.exit_status == "ok"
    assert rig.calls == {"configure": 1, "activate": 1, "read": 4, "write": 4, "deactivate": 1, "close": 1}
    assert rig.currents == [0.3, 0.3, 0.3, 0.0, 0.0]


def test_compute_time_is_measured_on_the_virtual_clock():
    clock = VirtualClock()

    class Busy(Stall):
        def step(self, sample, t_ns, dt_ns):
            self.clock.advance(40_000)
            return self.command

    loop = ControlLoop(FaultyRig(), Busy(clock), clock, 1000.0, 0.05)
    loop.run()
    stats = loop.timing.summary()
    assert stats["compute_us"] == {"p50": 40.0, "p99": 40.0, "p99_9": 40.0, "max": 40.0}
    assert stats["read_us"]["max"] == 0.0 and stats["missed_deadlines"] == 0


def test_stage_signals_become_columns():
    class WithSignals(ConstantCurrent):
        def __init__(self):
            super().__init__(0.2)
            self.z_hat = 0.0
            self.torque_hat_nm = 0.0

    assert record_columns(WithSignals()) == (
        "time_s",
        "theta_rad",
        "current_a",
        "current_cmd_a",
        "theta_road_rad",
        "z_hat",
        "torque_hat_nm",
        "seq",
        "device_time_us",
        "arm_edge_us",
        "arm_edge_dir",
        "road_edge_us",
        "road_edge_dir",
        "road_speed_cmd_rad_s",
        "phase",
        "trip_code",
    )
    assert record_columns(ConstantCurrent()) == (
        "time_s",
        "theta_rad",
        "current_a",
        "current_cmd_a",
        "theta_road_rad",
        "seq",
        "device_time_us",
        "arm_edge_us",
        "arm_edge_dir",
        "road_edge_us",
        "road_edge_dir",
        "road_speed_cmd_rad_s",
        "phase",
        "trip_code",
    )


# faults through a whole session (recorder + safety + summary) ----------------------------------


def _session(tmp_path, config, rig, stage=None, duration_s=0.1):
    config["loop"]["rt"]["priority"] = 0
    clock = VirtualClock()
    folder = RunFolder(tmp_path / "run")
    folder.path.mkdir()
    lines: list[str] = []
    loop = InProcessLoop(assemble(config), rig, stage or ConstantCurrent(0.5), clock, realtime=False)
    outcome = run_session(loop, config, folder, duration_s, say=lines.append)
    summary = json.loads((folder.path / "summary.json").read_text())
    assert (folder.path / "config.yaml").exists()
    assert summary["exit_status"] == outcome.exit_status
    assert rig.calls["deactivate"] == 1 and rig.calls["close"] == 1
    return outcome, summary, folder.path


def _rows(path):
    return read_data_csv(path / "data.csv", required=("time_s", "theta_rad", "current_a", "current_cmd_a"), min_rows=0)


def test_session_ok_writes_every_row(tmp_path, config):
    rig = FaultyRig()
    outcome, summary, path = _session(tmp_path, config, rig)
    assert outcome.exit_code == 0 and summary["exit_status"] == "ok"
    data = _rows(path)
    assert len(data["time_s"]) == 101  # every cycle, then the safe state the shutdown sent
    assert data["time_s"][:3].tolist() == [0.0, 0.001, 0.002] and data["time_s"][-1] == pytest.approx(0.1)
    assert set(data["current_cmd_a"][:-1].tolist()) == {0.5} and data["current_cmd_a"][-1] == 0.0
    assert data["road_speed_cmd_rad_s"][-1] == 0.0 and data["trip_code"][-1] == 0
    assert data["seq"].tolist() == [*range(1, 101), 100]  # the last sample the shutdown saw
    assert summary["timing"]["cycles"] == 100 and summary["trips"] == []
    for key in ("rate_hz", "cycles", "missed_deadlines", "lateness_us", "compute_us"):
        assert key in summary["timing"]
    assert set(summary["timing"]["lateness_us"]) == {"p50", "p99", "p99_9", "max"}


def test_read_raising_on_the_nth_call(tmp_path, config):
    rig = FaultyRig(fail_read_on=7)
    outcome, summary, path = _session(tmp_path, config, rig)
    assert outcome.exit_code == 1 and summary["exit_status"] == "error"
    assert "read failed" in summary["error"]
    assert rig.currents[-2:] == [0.0, 0.0]
    data = _rows(path)
    assert len(data["time_s"]) == 6 + 1 and data["current_cmd_a"][-1] == 0.0  # the cycles before the fault, 0 A


def test_write_raising(tmp_path, config):
    rig = FaultyRig(fail_write_on=4)
    outcome, _summary, path = _session(tmp_path, config, rig)
    assert outcome.exit_code == 1 and isinstance(outcome.error, DriverIOError)
    assert rig.currents[-1] == 0.0 and rig.calls["write"] == 5  # 3 good, the failed one, the 0 A write
    assert len(_rows(path)["time_s"]) == 4 + 1  # the row is recorded before the write; then the 0 A row


def test_stale_sensor_trips(tmp_path, config):
    config["safety"]["sensor_timeout_cycles"] = 5
    rig = FaultyRig(stale_from=10)  # seq stops advancing at the 10th read
    outcome, summary, path = _session(tmp_path, config, rig)
    assert outcome.exit_code == 3 and summary["exit_status"] == "safety_trip"
    (trip,) = summary["trips"]
    assert trip["kind"] == "sensor_timeout" and "5 cycles" in trip["reason"]
    assert trip["time_s"] == pytest.approx(0.013)  # reads 10..14 stale: the 14th read, at 13 ms
    data = _rows(path)
    assert len(data["time_s"]) == 14
    assert data["trip_code"][-1] == 2 and data["current_cmd_a"][-1] == 0.0
    assert rig.currents[-2:] == [0.0, 0.0]


def test_angle_past_the_interlock_trips(tmp_path, config):
    rig = FaultyRig(theta_deg=lambda n: 2.0 * n)  # 30 deg limit: 32 deg at the 16th read
    outcome, summary, path = _session(tmp_path, config, rig)
    assert outcome.exit_code == 3
    (trip,) = summary["trips"]
    assert trip["kind"] == "angle_interlock" and trip["time_s"] == pytest.approx(0.015)
    assert "beyond the limit 30 deg" in trip["reason"]
    data = _rows(path)
    assert len(data["time_s"]) == 16 and data["trip_code"].tolist() == [0] * 15 + [1]
    assert math.degrees(data["theta_rad"][-1]) == pytest.approx(32.0, abs=0.1)
    assert rig.currents[-2:] == [0.0, 0.0] and rig.currents[-3] == 0.5


def test_stop_flag_ends_cleanly_with_exit_130(tmp_path, config):
    clock = VirtualClock()
    rig = FaultyRig()

    class StopAt:
        command = RigCommand(0.2)

        def __init__(self):
            self.loop_stop = None
            self.n = 0

        def step(self, sample, t_ns, dt_ns):
            self.n += 1
            if self.n == 30:
                import signal

                signal.raise_signal(signal.SIGTERM)  # the session routes it to the stop flag
            return self.command

    config["loop"]["rt"]["priority"] = 0
    folder = RunFolder(tmp_path / "run")
    folder.path.mkdir()
    loop = InProcessLoop(assemble(config), rig, StopAt(), clock, realtime=False)
    outcome = run_session(loop, config, folder, None, say=lambda line: None)
    assert outcome.exit_code == 130 and outcome.stop_reason == "SIGTERM"
    # this rig's current never falls (0.1 A more per read): the loop reads on at 0 A for SETTLE_S, one
    # row per period, and says the safe state was not confirmed
    settled = outcome.summary["safe_state"]
    assert settled["reads"] == 500 and settled["after_s"] == pytest.approx(0.5) and not settled["confirmed"]
    assert len(_rows(folder.path)["time_s"]) == 30 + 500 + 1  # and the safe state's row
    assert rig.currents[-502:] == [0.0] * 502 and rig.calls["close"] == 1


def test_an_unexpected_error_in_the_stage_ends_at_0_a(tmp_path, config):
    class Broken(ConstantCurrent):
        n = 0

        def step(self, sample, t_ns, dt_ns):
            self.n += 1
            if self.n == 3:
                raise ZeroDivisionError("division by zero in the law")
            return self.command

    rig = FaultyRig()
    outcome, summary, path = _session(tmp_path, config, rig, Broken(0.7))
    assert outcome.exit_code == 1 and summary["exit_status"] == "error"
    assert summary["error"] == "division by zero in the law"
    assert rig.currents == [0.7, 0.7, 0.0, 0.0]
    data = _rows(path)
    assert len(data["time_s"]) == 2 + 1 and data["current_cmd_a"].tolist() == [0.7, 0.7, 0.0]


def test_real_clock_spin_margin_is_capped_at_a_quarter_period():
    from sashil.runtime.clock import RealClock

    assert RealClock.for_rate(200.0, 1000.0).spin_ns == 200_000
    assert RealClock.for_rate(200.0, 5000.0).spin_ns == 50_000
    assert RealClock.for_rate(0.0, 1000.0).spin_ns == 0


class FailingRecorder:
    """A recorder whose disk fills up after ``rows`` rows (the writer thread sets ``error``)."""

    def __init__(self, rows):
        self.rows, self.committed = rows, 0
        self.window_end_ns = None
        self.error = None
        self.path = "runs/x/data.csv"
        self._row = [0.0] * 16

    def begin_row(self):
        return self._row

    def commit_row(self):
        self.committed += 1
        if self.committed == self.rows:
            self.error = OSError(28, "No space left on device")


def test_a_recording_failure_mid_run_stops_the_loop_at_0_a():
    from sashil.errors import RecordingError, exit_code_of

    rig = FaultyRig()
    recorder = FailingRecorder(rows=25)
    loop = ControlLoop(rig, ConstantCurrent(0.8), VirtualClock(), 1000.0, 10.0, recorder=recorder)
    with pytest.raises(RecordingError) as err:
        loop.run()
    assert "runs/x/data.csv: recording failed" in str(err.value) and "No space left" in str(err.value)
    assert rig.calls["write"] == 25 and rig.currents[-2:] == [0.0, 0.0]  # 24 at 0.8 A, then 0 A, deactivate
    assert rig.calls["deactivate"] == 1 and rig.calls["close"] == 1
    assert loop.result.exit_status == "error" and exit_code_of("error", err.value) == 1


def test_a_disk_full_under_the_session_is_exit_1_and_the_rows_so_far_kept(tmp_path, config, monkeypatch):
    from sashil.recording import recorder as recorder_module

    real_write, calls = recorder_module.os.write, []

    def write(fd, data):  # the header and one batch of rows, then the disk is full
        calls.append(len(data))
        if len(calls) > 2:
            raise OSError(28, "No space left on device")
        return real_write(fd, data)

    monkeypatch.setattr(recorder_module.os, "write", write)
    rig = FaultyRig()
    config["loop"]["rt"]["priority"] = 0
    folder = RunFolder(tmp_path / "run")
    folder.path.mkdir()
    loop = InProcessLoop(assemble(config), rig, ConstantCurrent(0.5), _SlowClock(), realtime=False)
    outcome = run_session(loop, config, folder, 60.0, say=lambda line: None)
    summary = json.loads((folder.path / "summary.json").read_text())
    assert outcome.exit_code == 1 and summary["exit_status"] == "error"
    assert "No space left on device" in summary["error"]
    assert rig.currents[-1] == 0.0 and rig.calls["deactivate"] == 1
    assert outcome.timing.cycles < 60_000  # stopped when the writer failed, not at the end
    assert len(_rows(folder.path)["time_s"]) >= 1  # what reached the disk parses


class _SlowClock(VirtualClock):
    """Simulated time whose cycles take a little real time, so that the writer thread runs beside."""

    def sleep_until(self, t_ns):
        import time

        time.sleep(0)  # yield the interpreter to the writer thread (no wall-clock wait)
        super().sleep_until(t_ns)


@pytest.fixture
def disk_with_5_mb(monkeypatch):
    """The run folder's disk has 5 MB free (an hour at 1 kHz needs about 550 MB)."""
    monkeypatch.setattr(
        runner.shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**9, 10**9 - 5 * 10**6, 5 * 10**6)
    )


def test_a_disk_without_room_for_the_run_is_refused_before_the_rig_is_touched(
    tmp_path, config, monkeypatch, disk_with_5_mb
):
    rig = FaultyRig()
    with pytest.raises(DiskSpaceError) as err:
        runner.run_plan(
            assemble(config), rig, ConstantCurrent(0.5), VirtualClock(), 3600.0, data_path=tmp_path / "data.csv"
        )
    text = str(err.value)
    assert text.startswith(f"{tmp_path}: 5.0 MB free on its disk") and "3600 s at 1000 Hz" in text
    assert rig.calls["configure"] == 0 and not (tmp_path / "data.csv").exists()
    assert DiskSpaceError.exit_code == 2
    monkeypatch.setattr(runner.shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**9, 9 * 10**8, 10**8))
    assert runner.check_disk(tmp_path, 7, 1000.0, 60.0) == 60 * 7 * 1000 * runner.BYTES_PER_VALUE  # 9 MB: fits
    with pytest.raises(DiskSpaceError, match="10 minutes \\(no --duration\\) at 5000 Hz"):
        runner.check_disk(tmp_path, 40, 5000.0, None)  # 264 MB for an open-ended run: refused


def test_a_session_refused_for_its_disk_lets_the_rig_go(tmp_path, config, disk_with_5_mb):
    rig = FaultyRig()
    folder = RunFolder(tmp_path / "run")
    folder.path.mkdir()
    loop = InProcessLoop(assemble(config), rig, ConstantCurrent(0.5), VirtualClock(), realtime=False)
    with pytest.raises(DiskSpaceError):
        run_session(loop, config, folder, 3600.0, say=lambda line: None)
    assert rig.calls["configure"] == 0 and rig.calls["close"] == 1  # never energised, its port let go
    assert not (folder.path / "summary.json").exists()


def test_the_runner_compiles_the_kernels_before_the_rig_is_touched(config, monkeypatch):
    from sashil.runtime import warmup

    order: list[str] = []
    monkeypatch.setattr(warmup, "warm_up", lambda plan, say: order.append("compile"))  # the runner's, loaded on use

    class Watched(FaultyRig):
        def configure(self):
            order.append("configure")
            super().configure()

    runner.run_plan(assemble(config), Watched(), ConstantCurrent(0.1), VirtualClock(), 0.01, realtime=False)
    assert order == ["compile", "configure"]


def test_signals_are_read_from_the_stage_s_signal_source_when_it_has_them_all():
    """A plan that runs a controller names it as its ``signal_source``: the rows carry the
    controller's values; a wrapper adding a signal of its own keeps reading from itself."""
    from sashil.recording.recorder import Recorder

    class Source:
        z_hat = 0.25

    class Plan(ConstantCurrent):
        signal_names = ("z_hat",)

        def __init__(self):
            super().__init__(0.3)
            self.signal_source = Source()

        @property
        def z_hat(self):  # the slow path a signal_source saves: never read
            raise AssertionError("read through the plan")

    class Wrapper(ConstantCurrent):
        signal_names = ("z_hat", "torque_in_nm")

        def __init__(self, plan):
            super().__init__(0.3)
            self.plan, self.torque_in_nm = plan, 1.5
            self.signal_source = plan.signal_source  # forwarded, but it lacks torque_in_nm

        @property
        def z_hat(self):
            return self.plan.signal_source.z_hat

    for stage, expected in ((Plan(), {"z_hat": 0.25}), (Wrapper(Plan()), {"z_hat": 0.25, "torque_in_nm": 1.5})):
        recorder = Recorder(None, record_columns(stage), keep=True)
        ControlLoop(FaultyRig(), stage, VirtualClock(), 1000.0, 0.005, recorder=recorder).run()
        stream = recorder.stream()
        for name, value in expected.items():
            assert stream[name].tolist() == [value] * 6, name  # 5 cycles and the shutdown's row
