"""The serial and CAN backends against the emulator in a thread (real pyserial / python-can stacks).

These run on the wall clock (a pty and a thread) but never sleep: they wait on samples with
generous timeouts, so a loaded machine makes them slower, not flaky.
"""

from __future__ import annotations

import can
import pytest

from sashil.drivers import open_rig, rig_parts
from sashil.drivers.can_codec import database
from sashil.drivers.emulator import EmulatorThread, Faults
from sashil.drivers.emulator import device as device_module
from sashil.drivers.emulator.transports import Pty
from sashil.drivers.firmware import compiler
from sashil.drivers.interface import RigCommand, RigState
from sashil.engine.resolve import default_config
from sashil.errors import DriverError, DriverIOError

pytestmark = pytest.mark.e2e  # wall clock, real pty/link/processes: `pytest -m "not e2e"` skips them


def host_config(driver: str, port: str, interface: str = "slcan", pacing: str = "device") -> dict:
    config = default_config()
    config["driver"].update(
        name=driver, port=port, can_interface=interface, pacing=pacing, sample_timeout_ms=500.0, connect_timeout_s=5.0
    )
    return config


LINKS = [("serial", "serial", "slcan"), ("slcan", "can", "slcan"), ("virtual", "can", "virtual")]
BOARDS = ["python", pytest.param("c", marks=pytest.mark.skipif(compiler() is None, reason="no C compiler"))]


def wait_for(rig, predicate, cycles=2000, current=0.0):
    for _ in range(cycles):
        sample = rig.read(0, 0)
        rig.write(RigCommand(current), 0, 0)
        if predicate(sample):
            return sample
    raise AssertionError("condition not reached")


@pytest.mark.parametrize("board", BOARDS)
@pytest.mark.parametrize("transport, driver, interface", LINKS)
@pytest.mark.parametrize("pacing", ["device", "host"])
def test_backend_session_drives_and_stops_the_coil(transport, driver, interface, pacing, board):
    config = default_config()
    with EmulatorThread(config, transport, channel=f"t-{transport}-{pacing}", board=board) as emu:
        with open_rig(
            rig_parts(host_config(driver, emu.port, interface, pacing))
        ) as rig:  # closed however the test ends
            rig.configure()
            assert emu.device.configured and emu.device.drive_a == 0.0
            rig.write(RigCommand(0.7), 0, 0)  # before activate(): 0 A
            rig.read(0, 0)
            assert emu.device.drive_a == 0.0
            rig.activate()
            seqs = [rig.read(0, 0).seq for _ in range(20)]
            assert seqs == sorted(seqs)
            wait_for(rig, lambda s: s.current_a > 0.3, current=0.7)  # coil lag, then the current flows
            assert emu.device.drive_a == pytest.approx(0.7, abs=0.0005)
            rig.write(RigCommand(0.7, road_speed_rad_s=1.5), 0, 0)  # the road wheel turning (a sweep)
            rig.read(0, 0)
            rig.deactivate()  # returns once a sample shows the coil at rest
            assert rig.link_stats()["safe_state_confirmed"] is True
            assert emu.device.drive_a == 0.0 and emu.device.road.speed_rad_s == 0.0
            rig.read(0, 0)
            assert emu.device.drive_a == 0.0
            rig.close()
            rig.close()  # idempotent
            assert rig.state is RigState.CLOSED
            assert rig.link_stats()["bad_frames"] == 0


def test_the_dbc_decodes_the_frames_the_can_backend_sends():
    with EmulatorThread(default_config(), "virtual", channel="t-dbc") as emu:
        with can.Bus(interface="virtual", channel="t-dbc") as listener:
            with open_rig(rig_parts(host_config("can", emu.port, "virtual"))) as rig:
                rig.configure()
                rig.activate()
                rig.read(0, 0)
                rig.write(RigCommand(0.25), 0, 0)
            emu.stop()
            seen = {}  # the emulator has stopped: drain what the listener got
            frame = listener.recv(0.0)
            while frame is not None:
                seen.setdefault(frame.arbitration_id, []).append(
                    database().decode_message(frame.arbitration_id, frame.data)
                )
                frame = listener.recv(0.0)
    assert seen[0x1F1] == [{"HelloVersion": 2}]
    assert seen[0x1F0] == [{"SampleRateHz": 1000, "WatchdogMs": 50, "Pacing": "device"}]
    assert {"CmdSeq", "CurrentCmd", "CmdFlags"} <= set(seen[0x100][0])
    assert any(d["CurrentCmd"] == 0.25 and d["CmdFlags"] == 1 for d in seen[0x100])
    assert seen[0x100][-1]["CurrentCmd"] == 0.0  # the context manager's exit commands 0 A
    assert 0x110 in seen and 0x112 in seen and 0x111 in seen


def test_wrong_protocol_version_is_refused_and_nothing_energised(monkeypatch):
    monkeypatch.setattr(device_module, "PROTOCOL_VERSION", 1)  # a board of protocol 1 (no edge times)
    with EmulatorThread(default_config(), "serial") as emu:
        with open_rig(rig_parts(host_config("serial", emu.port))) as rig:
            with pytest.raises(DriverError) as err:
                rig.configure()
            assert type(err.value) is DriverError and err.value.exit_code == 2
            assert "protocol version 1, this host speaks 2" in str(err.value) and "\n" not in str(err.value)
            assert emu.device.drive_a == 0.0 and not emu.device.configured
            rig.deactivate()


def test_missing_port_busy_port_and_silent_port():
    with pytest.raises(DriverError) as err:
        open_rig(rig_parts(host_config("serial", "/dev/does-not-exist"))).configure()
    assert err.value.exit_code == 2 and "/dev/does-not-exist" in str(err.value)
    with EmulatorThread(default_config(), "serial") as emu:
        with open_rig(rig_parts(host_config("serial", emu.port))) as first:
            first.configure()
            with pytest.raises(DriverError) as err:
                open_rig(rig_parts(host_config("serial", emu.port))).configure()
            assert err.value.exit_code == 2 and "cannot open" in str(err.value)
    pty = Pty.open()
    try:
        config = host_config("serial", pty.path)
        config["driver"]["connect_timeout_s"] = 0.1
        with pytest.raises(DriverError) as err:
            open_rig(rig_parts(config)).configure()
        assert err.value.exit_code == 2 and "no Version" in str(err.value)
    finally:
        pty.close()


def test_a_second_host_on_a_busy_slcan_port_is_refused_without_disturbing_the_first():
    with EmulatorThread(default_config(), "slcan", channel="t-busy") as emu:
        with open_rig(rig_parts(host_config("can", emu.port))) as first:
            first.configure()
            first.activate()
            before = first.link_stats()["samples"]
            second = open_rig(rig_parts(host_config("can", emu.port)))
            with pytest.raises(DriverError) as err:
                second.configure()
            second.close()
            assert err.value.exit_code == 2 and "in use by another process" in str(err.value)
            assert "\n" not in str(err.value)
            for _ in range(50):  # the first host's session goes on: no adapter reset, no lost link
                first.read(0, 0)
                first.write(RigCommand(0.2), 0, 0)
            stats = first.link_stats()
            assert stats["samples"] >= before + 50 and stats["timeouts"] == 0 and stats["bad_frames"] == 0
        with open_rig(rig_parts(host_config("can", emu.port))) as again:  # released when the first closed
            again.configure()


def test_unknown_can_interface_and_missing_port():
    with pytest.raises(DriverError) as err:
        open_rig(rig_parts(host_config("can", "can0", interface="no-such-bus"))).configure()
    assert err.value.exit_code == 2 and "no-such-bus" in str(err.value)
    config = host_config("can", "x")
    config["driver"]["port"] = None
    with pytest.raises(DriverError):
        open_rig(rig_parts(config))


@pytest.mark.parametrize("board", BOARDS)
@pytest.mark.parametrize("transport, driver", [("serial", "serial"), ("slcan", "can")])
def test_disconnect_raises_driver_io_error_and_shutdown_stays_quiet(transport, driver, board):
    emu = EmulatorThread(default_config(), transport, faults=Faults(disconnect_after_s=0.05), board=board)
    with emu:
        with open_rig(rig_parts(host_config(driver, emu.port))) as rig:
            rig.configure()
            rig.activate()
            with pytest.raises(DriverIOError):
                for _ in range(5000):
                    rig.read(0, 0)
                    rig.write(RigCommand(0.1), 0, 0)
            rig.deactivate()  # a dead link: must not raise
            rig.close()


@pytest.mark.parametrize("board", BOARDS)
def test_corrupt_frames_are_counted_and_the_run_goes_on(board):
    with EmulatorThread(default_config(), "serial", faults=Faults(corrupt_rate=0.05, seed=1), board=board) as emu:
        with open_rig(rig_parts(host_config("serial", emu.port))) as rig:
            rig.configure()
            rig.activate()
            for _ in range(400):
                rig.read(0, 0)
                rig.write(RigCommand(0.0), 0, 0)
            stats = rig.link_stats()
    assert stats["bad_frames"] > 0 and stats["bad_frames"] == stats["crc"] + stats["cobs"] + stats["length"]
    assert stats["samples_missed"] >= stats["bad_frames"] - 2  # each bad frame was a sample (or a status)
    assert emu.link.tx_corrupted >= stats["bad_frames"]
