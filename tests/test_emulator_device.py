"""The emulated interface board on simulated time: pacing, watchdog, operator, faults."""

from __future__ import annotations

import math

import pytest

from sashil.drivers import rig_parts
from sashil.drivers.emulator import Faults, HostConsole, Operator, build_device
from sashil.drivers.emulator.runner import Emulator
from sashil.drivers.emulator.transports import DeviceTransport, corrupt_frame
from sashil.drivers.interface import FLAG_HELD, FLAG_STUCK_SENSOR, FLAG_WATCHDOG, RigCommand
from sashil.drivers.messages import (
    CMD_ENABLE,
    FAULT_BAD_CONFIGURE,
    PACING_DEVICE,
    PACING_HOST,
    PROTOCOL_VERSION,
    Command,
    Configure,
    Hello,
    RoadSpeed,
    Sample,
    Status,
    Version,
)
from sashil.drivers.serial_codec import StreamDecoder, encode_frame
from sashil.drivers.sim import SimulatedRig
from sashil.engine.resolve import default_config

MS = 1_000_000


def samples(out):
    return [msg for _, msg in out if isinstance(msg, Sample)]


def run_ticks(device, start_ns, stop_ns, step_ns=MS, command=None):
    got = []
    for t in range(start_ns, stop_ns, step_ns):
        if command is not None:
            got += device.handle(command, t)
        got += device.tick(t)
    return got


def test_hello_and_configure_answers():
    device = build_device(default_config())
    assert device.handle(Hello(PROTOCOL_VERSION), 0) == [(1, Version(PROTOCOL_VERSION, 4096, 1.0))]
    ((_, status),) = device.handle(Configure(1000, 50, PACING_DEVICE), 0)
    assert status == Status(0, 0, 0, 0)
    fixed = build_device(default_config(), fixed_rate_hz=500)
    ((_, refused),) = fixed.handle(Configure(1000, 50, PACING_DEVICE), 0)
    assert refused.fault_code == FAULT_BAD_CONFIGURE and not fixed.configured


def test_device_pacing_streams_one_sample_per_period():
    device = build_device(default_config())
    assert run_ticks(device, 0, 5 * MS) == []  # nothing before Configure
    device.handle(Configure(1000, 50, PACING_DEVICE), 5 * MS)
    got = samples(run_ticks(device, 5 * MS, 105 * MS, step_ns=MS // 4))
    assert len(got) == 100
    assert [s.device_time_us for s in got[:3]] == [5000, 6000, 7000]


def test_host_pacing_answers_each_command_with_one_sample():
    device = build_device(default_config())
    device.handle(Configure(1000, 50, PACING_HOST), 0)
    assert run_ticks(device, 0, 10 * MS) == []
    got = run_ticks(device, 10 * MS, 20 * MS, command=Command(0.2, CMD_ENABLE))
    assert len(samples(got)) == 10


def test_samples_are_the_simulated_rig_sensor_model():
    """The board adds no physics: same plant, same times -> the same encoder counts."""
    config = default_config()
    device = build_device(config)
    reference = SimulatedRig.from_parts(rig_parts(config, "sim"))
    reference.configure(), reference.activate()
    device.handle(Configure(1000, 1000, PACING_DEVICE), 0)
    reference.read(0, 0)
    device.rig.plant.state.theta_rad = reference.plant.state.theta_rad = math.radians(3.0)
    for k in range(1, 300):
        t = k * MS
        current = 0.5 if k > 100 else 0.0
        device.handle(Command(current, CMD_ENABLE), t)  # the plant ran under the old command up to t
        sample = samples(device.tick(t))[0]
        expected = reference.read(t, MS)
        reference.write(RigCommand(current), t, MS)
        assert (sample.arm_counts, sample.road_counts) == (expected.arm_counts, expected.road_counts)
        assert abs(sample.current_a - expected.current_a) < 1e-12


def test_watchdog_cuts_the_current_within_its_time_plus_one_cycle():
    device = build_device(default_config())
    drive_log = []
    device.on_drive = lambda t, i: drive_log.append((t, i))
    device.handle(Configure(1000, 50, PACING_DEVICE), 0)
    run_ticks(device, 0, 20 * MS, command=Command(0.8, CMD_ENABLE))  # last command at 19 ms
    assert device.drive_a == 0.8
    got = run_ticks(device, 20 * MS, 100 * MS)
    assert drive_log[-1][1] == 0.0
    assert drive_log[-1][0] <= 19 * MS + 50 * MS + 1 * MS
    assert device.watchdog_trips == 1
    statuses = [msg for _, msg in got if isinstance(msg, Status)]
    assert statuses and statuses[0].flags & FLAG_WATCHDOG
    flagged = [s for s in samples(got) if s.flags & FLAG_WATCHDOG]
    assert flagged and flagged[0].device_time_us <= (19 + 51) * 1000
    # the next valid command clears the flag and drives again
    got = run_ticks(device, 100 * MS, 102 * MS, command=Command(0.3, CMD_ENABLE))
    assert not samples(got)[-1].flags & FLAG_WATCHDOG and device.drive_a == 0.3


def test_watchdog_trips_at_exactly_its_time_not_a_cycle_later():
    device = build_device(default_config())
    device.handle(Configure(1000, 50, PACING_DEVICE), 0)
    device.handle(Command(0.8, CMD_ENABLE), 10 * MS)
    device.tick(10 * MS + 50 * MS - 1)
    assert device.drive_a == 0.8 and device.watchdog_trips == 0
    device.tick(10 * MS + 50 * MS)
    assert device.drive_a == 0.0 and device.watchdog_trips == 1


def test_configure_accepts_a_watchdog_of_1_ms_and_refuses_0():
    device = build_device(default_config())
    ((_, status),) = device.handle(Configure(1000, 1, PACING_DEVICE), 0)
    assert status.fault_code == 0 and device.watchdog_ns == MS
    other = build_device(default_config())
    ((_, refused),) = other.handle(Configure(1000, 0, PACING_DEVICE), 0)
    assert refused.fault_code == FAULT_BAD_CONFIGURE and not other.configured


def test_command_without_enable_drives_zero():
    device = build_device(default_config())
    device.handle(Configure(1000, 50, PACING_DEVICE), 0)
    device.handle(Command(0.9, 0), MS)
    assert device.drive_a == 0.0
    device.handle(Command(5.0, CMD_ENABLE), 2 * MS)
    assert device.drive_a == 1.0  # clamped to rig.current_max_a


def test_operator_holds_then_releases_from_configure():
    device = build_device(default_config(), operator=Operator(-5.0, 0.5))
    run_ticks(device, 0, 200 * MS)  # before the host connects: nothing held
    device.handle(Configure(1000, 1000, PACING_DEVICE), 200 * MS)
    got = samples(run_ticks(device, 200 * MS, 1200 * MS, command=Command(0.0, CMD_ENABLE)))
    held = [s for s in got if s.flags & FLAG_HELD]
    assert 495 <= len(held) <= 501
    hold_counts = round(math.radians(-5.0) * 4096 / (2 * math.pi))
    assert all(s.arm_counts == hold_counts for s in held)
    assert got[-1].arm_counts != hold_counts  # let go: the arm swings


def test_operator_holds_at_each_angle_in_turn_one_per_configure():
    device = build_device(default_config(), operator=Operator(-5.0, 10.0, (-2.5,)))
    counts = []
    for session in range(3):  # -5, -2.5, then round again to -5
        start = session * 100 * MS
        device.handle(Configure(1000, 1000, PACING_DEVICE), start)
        got = samples(run_ticks(device, start, start + 50 * MS, command=Command(0.0, CMD_ENABLE)))
        assert all(s.flags & FLAG_HELD for s in got)
        counts.append(got[-1].arm_counts)
    per_deg = 4096 / 360
    assert counts == [round(-5.0 * per_deg), round(-2.5 * per_deg), round(-5.0 * per_deg)]


def _held_deg(device, start_ns):
    """Configure at ``start_ns`` and the angle [deg] the operator holds the arm at (50 ms of samples)."""
    device.handle(Configure(1000, 1000, PACING_DEVICE), start_ns)
    got = samples(run_ticks(device, start_ns, start_ns + 50 * MS, command=Command(0.0, CMD_ENABLE)))
    assert got and all(s.flags & FLAG_HELD for s in got)
    return got[-1].arm_counts * 360 / 4096


def test_operator_with_the_hosts_console_holds_at_its_last_hold_prompt(tmp_path):
    console = tmp_path / "console.txt"  # not there yet: no prompt, the --hold-deg angles in turn
    device = build_device(default_config(), operator=Operator(-5.0, 10.0, (-2.5,), console=HostConsole(console)))
    held = [_held_deg(device, 0)]
    console.write_text("calibration plan: 9 runs\n  01-fit-drop: press the arm to -3.5 deg, hold it still\n")
    held.append(_held_deg(device, 100 * MS))
    held.append(_held_deg(device, 200 * MS))  # said nothing new (a repeat says it again): the same angle
    with console.open("a") as out:
        out.write("  02-fit-drop: press the arm to -2 deg, hold")  # a line still being written: not yet read
    held.append(_held_deg(device, 300 * MS))
    with console.open("a") as out:
        out.write(" it still\n  a link gap; repeating it\n")
    held.append(_held_deg(device, 400 * MS))
    console.write_text("  01-fit-drop: press the arm to -4.25 deg, hold it still\n")  # a new host run's console
    held.append(_held_deg(device, 500 * MS))
    count = 360 / 4096
    assert held == [pytest.approx(a, abs=count) for a in (-5.0, -3.5, -3.5, -3.5, -2.0, -4.25)]


def test_emulate_prompts_without_hold_deg_is_one_line_exit_2(capsys):
    from sashil.cli import main

    assert main(["emulate", "--prompts", "console.txt", "--duration", "0.1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--prompts" in err[0] and "--hold-deg" in err[0]


def test_stuck_sensor_freezes_both_encoders_and_flags_it():
    device = build_device(default_config(), operator=Operator(-5.0, 0.0), faults=Faults(stuck_sensor_after_s=0.05))
    device.handle(Configure(1000, 1000, PACING_DEVICE), 0)
    got = samples(run_ticks(device, 0, 120 * MS, command=Command(0.0, CMD_ENABLE)))
    stuck = [s for s in got if s.flags & FLAG_STUCK_SENSOR]
    assert len(stuck) == 70
    assert len({s.arm_counts for s in stuck}) == 1
    assert got[10].arm_counts != got[40].arm_counts  # it did move before


class ListTransport(DeviceTransport):
    """An in-memory link for the runner: scripted host messages in, frames out."""

    def __init__(self, script):
        super().__init__()
        self.script = script  # [(time_ns, message)]
        self.sent = []
        self.clock_ns = 0

    @property
    def bad_frames(self):
        return 0

    def receive(self, timeout_s):
        target = self.clock_ns + max(int(timeout_s * 1e9), 1000)
        first = min((t for t, _ in self.script), default=None)
        self.clock_ns = max(self.clock_ns, first) if first is not None and first <= target else target
        due = [m for t, m in self.script if t <= self.clock_ns]
        self.script = [(t, m) for t, m in self.script if t > self.clock_ns]
        return [(0, m) for m in due]

    def send(self, seq, msg, corrupt=False):
        self.sent.append((self.clock_ns, seq, msg, corrupt))

    def close(self):
        pass


def test_runner_fault_injection_on_simulated_time():
    script = [(0, Configure(1000, 50, PACING_DEVICE))] + [(k * MS, Command(0.0, CMD_ENABLE)) for k in range(1, 300)]
    link = ListTransport(script)
    device = build_device(
        default_config(),
        faults=Faults(drop_rate=0.1, corrupt_rate=0.05, latency_ms=2.0, disconnect_after_s=0.2, seed=3),
    )
    emulator = Emulator(device, link, clock=lambda: link.clock_ns)
    assert emulator.run() == "disconnect"
    sent = [s for s in link.sent if isinstance(s[2], Sample)]
    assert 150 < len(sent) < 195  # ~200 samples, ~10 % dropped
    assert 0 < sum(1 for s in sent if s[3]) < 25
    first = min(s[0] for s in sent)
    assert first >= 2 * MS  # the latency: nothing leaves before 2 ms


def test_stall_sends_nothing_after_its_time():
    link = ListTransport([(0, Configure(1000, 50, PACING_DEVICE))])
    device = build_device(default_config(), faults=Faults(stall_after_s=0.05))
    emulator = Emulator(device, link, clock=lambda: link.clock_ns)

    def wait(timeout_s):  # simulated time passes while the stalled device waits
        link.clock_ns += int(timeout_s * 1e9)
        return False

    emulator.stop_event.wait = wait
    assert emulator.run(duration_s=0.15) == "duration"
    assert emulator.stats.stalled
    assert 45 <= len(link.sent) <= 53 and max(t for t, *_ in link.sent) <= 51 * MS


def _commanded_then_silent(faults: Faults) -> tuple[ListTransport, Emulator]:
    """Configure, the road at 1 rad/s, 0.8 A commanded every ms up to 40 ms; then the host is silent."""
    script = [(0, Configure(1000, 50, PACING_DEVICE)), (MS, RoadSpeed(1.0))]
    script += [(k * MS, Command(0.8, CMD_ENABLE)) for k in range(2, 41)]
    link = ListTransport(script)
    emulator = Emulator(build_device(default_config(), faults=faults), link, clock=lambda: link.clock_ns)

    def wait(timeout_s):  # simulated time passes while the unlinked board waits
        link.clock_ns += max(int(timeout_s * 1e9), 1000)
        return False

    emulator.stop_event.wait = wait
    return link, emulator


def test_a_stalled_link_does_not_stop_the_boards_watchdog():
    link, emulator = _commanded_then_silent(Faults(stall_after_s=0.045))
    drives = []
    emulator.device.on_drive = lambda t, drive: drives.append((t, drive))
    assert emulator.run(duration_s=0.2) == "duration" and emulator.stats.stalled
    device = emulator.device
    assert device.drive_a == 0.0 and device.road.speed_rad_s == 0.0 and device.watchdog_trips == 1
    assert drives[-1] == (drives[-1][0], 0.0) and 90 * MS <= drives[-1][0] <= 91 * MS  # 40 ms + 50 ms
    assert max(t for t, *_ in link.sent) <= 46 * MS  # silent on the link all the while


def test_a_disconnect_returns_once_the_watchdog_has_put_coil_and_road_to_rest():
    link, emulator = _commanded_then_silent(Faults(disconnect_after_s=0.045))
    assert emulator.run() == "disconnect"
    device = emulator.device
    assert device.drive_a == 0.0 and device.road.speed_rad_s == 0.0 and device.watchdog_trips == 1
    assert 90 * MS <= link.clock_ns <= 92 * MS


def test_corrupted_serial_frame_fails_the_crc_only():
    frame = encode_frame(Sample(1, 2, 3, 0.0, 0), 1)
    bad = corrupt_frame(frame)
    assert bad != frame and bad.endswith(b"\x00") and 0 not in bad[:-1]
    decoder = StreamDecoder()
    assert decoder.feed(bad + frame) == [(1, Sample(1, 2, 3, 0.0, 0))]
    assert decoder.counters.bad_frames == 1


def test_road_speed_step_moves_the_road_and_kicks_the_relative_rate():
    # a speed command steps the road wheel's speed: the arm keeps its absolute rate, so the relative
    # rate theta_dot = theta2_dot - theta1_dot drops by the change (the impulse of road acceleration)
    from sashil.drivers.messages import RoadSpeed

    device = build_device(default_config())
    device.handle(Configure(1000, 50, PACING_DEVICE), 0)
    plant = device.rig.plant
    assert device.handle(RoadSpeed(0.5), 10 * MS) == []
    assert plant.state.theta_dot_rad_s == -0.5 and plant.state.theta_road_dot_rad_s == 0.5
    device.handle(RoadSpeed(0.2), 30 * MS)
    assert math.isclose(plant.state.theta_road_rad, 0.5 * 0.020, rel_tol=1e-9)  # 20 ms at 0.5 rad/s
    run_ticks(device, 30 * MS, 50 * MS)
    assert math.isclose(plant.state.theta_road_rad, 0.010 + 0.2 * 0.019, rel_tol=1e-9)  # last tick at 49 ms
    absolute = plant.state.theta_dot_rad_s + plant.state.theta_road_dot_rad_s
    device.handle(RoadSpeed(0.0), 49 * MS)  # at the plant's present time: only the step acts
    assert plant.state.theta_road_dot_rad_s == 0.0
    assert math.isclose(plant.state.theta_dot_rad_s, absolute, rel_tol=1e-12)


def test_a_link_in_use_is_refused_and_a_stale_one_replaced(tmp_path):
    import os

    import pytest

    from sashil.drivers.emulator.transports import Pty
    from sashil.errors import DriverError

    link = str(tmp_path / "rig")
    first = Pty.open(link)
    try:
        with pytest.raises(DriverError, match="in use"):
            Pty.open(link)
    finally:
        first.close()
    os.symlink(str(tmp_path / "gone"), link)  # a stale link (its pty gone) is taken over
    second = Pty.open(link)
    try:
        assert os.readlink(link) == second.path
    finally:
        second.close()
    (tmp_path / "rig").write_text("not a link")
    with pytest.raises(DriverError, match="not an emulator's link"):
        Pty.open(link)


def test_a_stop_request_from_a_signal_handler_takes_no_lock():
    # `sashil emulate` deadlocked when a second SIGTERM arrived while the first handler's
    # Event.set() held the Event's lock (seen: pkill and timeout both signalling it); the handler
    # now only sets a flag, so even inside set() a request returns at once
    import threading

    emulator = Emulator(build_device(default_config()), _NullTransport())
    done = threading.Event()

    def inside_set() -> None:
        with emulator.stop_event._cond:  # as if interrupted inside Event.set()
            emulator.request_stop()
        done.set()

    worker = threading.Thread(target=inside_set, daemon=True)
    worker.start()
    worker.join(timeout=5.0)
    assert done.is_set() and emulator.stop_requested
    assert emulator.run(duration_s=10.0) == "stop"  # the loop sees the request at its next turn


class _NullTransport(DeviceTransport):
    bad_frames = 0

    def receive(self, timeout_s):
        return []

    def send(self, seq, msg, corrupt=False):
        pass

    def close(self):
        pass
