"""Link errors that name their cause: a port in use, a board that speaks the other driver's protocol."""

from __future__ import annotations

import fcntl
import logging
import os
import pty
import select
import threading
import tty

import pytest

from sashil.cli import main
from sashil.drivers import open_rig, rig_parts
from sashil.drivers.emulator import EmulatorThread
from sashil.drivers.firmware import compiler
from sashil.drivers.messages import (
    FAULT_NO_CAN,
    PROTOCOL_VERSION,
    STATUS_CLOCK_FALLBACK,
    Configure,
    Hello,
    Status,
    Version,
)
from sashil.drivers.serial_codec import StreamDecoder, encode_frame
from sashil.engine.resolve import default_config
from sashil.errors import DriverError

pytestmark = pytest.mark.e2e  # real ptys (and the emulator in a thread)

BOARDS = ["python", pytest.param("c", marks=pytest.mark.skipif(compiler() is None, reason="no C compiler"))]


def _config(driver: str, port: str) -> dict:
    config = default_config()
    config["driver"].update(name=driver, port=port, can_interface="slcan", connect_timeout_s=0.5)
    return config


def _relaxed(config: dict) -> dict:
    """``config`` with the link's sample timeout (hence the write timeout) 250 ms and link lost 500 ms,
    for a test of what the link says rather than of its timing: the emulator's thread shares the
    test's interpreter, and a loaded machine can keep it from reading for longer than the bench
    defaults allow (the timeouts themselves are tested with the defaults)."""
    config["driver"].update(sample_timeout_ms=250.0, link_lost_ms=500.0)
    return config


@pytest.mark.parametrize("board", BOARDS)
@pytest.mark.parametrize(
    "transport, driver, answer",
    [
        ("serial", "can", "answers sashil serial frames, not the SLCAN lines of a CAN adapter (use --driver serial)"),
        (
            "slcan",
            "serial",
            "answers SLCAN, the ASCII lines of a CAN adapter, not sashil serial frames (use --driver can)",
        ),
    ],
)
def test_a_board_that_speaks_the_other_protocol_is_named(transport, driver, answer, board):
    with EmulatorThread(default_config(), transport, channel=f"wrong-{transport}", board=board) as emu:
        with open_rig(rig_parts(_config(driver, emu.port))) as rig:
            with pytest.raises(DriverError) as caught:
                rig.configure()
    message = str(caught.value)
    assert "no Version (answer to Hello) within 0.5 s: the board on this port " + answer in message
    assert "link lost" not in message


def test_a_silent_port_is_not_said_to_speak_another_protocol():
    controller, device = pty.openpty()
    try:
        for driver in ("serial", "can"):
            with open_rig(rig_parts(_config(driver, os.ttyname(device)))) as rig:
                with pytest.raises(DriverError, match=r"is a sashil rig on this port, and is it powered\?"):
                    rig.configure()
    finally:
        os.close(controller)
        os.close(device)


def test_a_serial_port_in_use_says_so(tmp_path, capsys):
    controller, device = pty.openpty()
    name = os.ttyname(device)
    holder = os.open(name, os.O_RDWR | os.O_NOCTTY)
    try:
        fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)  # what another sashil (pyserial exclusive=True) holds
        out = tmp_path / "R"
        assert main(["run", "--driver", "serial", "--port", name, "--duration", "1", "--out", str(out), "-q"]) == 2
    finally:
        for fd in (holder, controller, device):
            os.close(fd)
    err = capsys.readouterr().err.strip()
    assert err == f"sashil run: error: serial port {name}: cannot open ({name} is in use by another process)"
    assert not out.exists()


def _read_until_released(rig, emu_rig_flags_seen: list) -> None:
    from sashil.drivers.interface import FLAG_HELD, RigCommand

    rig.configure()
    rig.activate()
    for _ in range(5000):
        sample = rig.read(0, 0)
        rig.write(RigCommand(0.0), 0, 0)
        emu_rig_flags_seen.append(bool(sample.flags & FLAG_HELD))
        if emu_rig_flags_seen[0] and not emu_rig_flags_seen[-1]:
            return  # held at first, then let go
    raise AssertionError("the emulated operator never let go")


@pytest.mark.parametrize("board", BOARDS)
def test_the_emulators_hold_is_announced_and_a_host_that_runs_no_drop_test_warns(board, caplog):
    from sashil.drivers.emulator import Operator

    notices: list[str] = []
    operator = Operator(-5.0, 0.2, announce=notices.append)
    with EmulatorThread(default_config(), "serial", channel="held", board=board, operator=operator) as emu:
        with caplog.at_level("WARNING", logger="sashil"):
            with open_rig(rig_parts(_relaxed(_config("serial", emu.port)))) as rig:  # a run: nothing asked for a hold
                flags: list[bool] = []
                _read_until_released(rig, flags)
            warned = [r.getMessage() for r in caplog.records if "held by its operator" in r.getMessage()]
            assert len(warned) == 1 and "this run starts with the arm held until the operator lets go" in warned[0]
            caplog.clear()
            with open_rig(rig_parts(_relaxed(_config("serial", emu.port)))) as rig:  # a drop test asks first
                assert rig.operator_hold(-0.087, 0.2) is False
                _read_until_released(rig, [])
            assert not [r for r in caplog.records if "held by its operator" in r.getMessage()]
    assert notices == [
        f"host connected (session {n}): the operator holds the arm at -5 deg and lets go 0.2 s later, "
        "whatever the host runs (--hold-deg)"
        for n in (1, 2)
    ]


def _fake_board(controller: int, status: Status, stop: threading.Event) -> None:
    """Answers Hello with the default rig's Version and Configure with ``status`` on a pty's controller."""
    decoder, seq = StreamDecoder(), 0
    while not stop.is_set():
        if not select.select([controller], [], [], 0.02)[0]:
            continue
        for _, msg in decoder.feed(os.read(controller, 4096)):
            answer = {Hello: Version(PROTOCOL_VERSION, 4096, 1.0), Configure: status}.get(type(msg))
            if answer is not None:
                seq += 1
                os.write(controller, encode_frame(answer, seq))


@pytest.mark.parametrize(
    "status, said",
    [
        (Status(STATUS_CLOCK_FALLBACK), "the board's crystal did not start: it runs on its internal oscillator"),
        (Status(0, FAULT_NO_CAN), "the device has no CAN transmitter: it refused a CAN session"),
    ],
)
def test_a_board_on_its_internal_oscillator_is_reported_and_one_without_can_named(status, said, caplog):
    controller, device = pty.openpty()
    tty.setraw(device)
    stop = threading.Event()
    board = threading.Thread(target=_fake_board, args=(controller, status, stop), daemon=True)
    board.start()
    try:
        with open_rig(rig_parts(_config("serial", os.ttyname(device)))) as rig:
            if status.fault_code:
                with pytest.raises(DriverError, match=said):
                    rig.configure()
            else:
                with caplog.at_level(logging.WARNING):
                    rig.configure()
                assert said in caplog.text and rig.link_stats()["clock_fallback"] == 1
    finally:
        stop.set()
        board.join()
        os.close(controller)
        os.close(device)
