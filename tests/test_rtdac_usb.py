"""First contact with the RT-DAC/USB2 and recovery on the stop path, through pyusb's own core against
the emulated board in this process (its USB side at fault: :class:`UsbFaults`).

The board runs on a clock the test moves; each transfer takes 20 us of it. Every figure is
deterministic.
"""

from __future__ import annotations

import math

import pytest

from sashil.config.frozen import freeze_config
from sashil.diagnostics import OK, WARN
from sashil.diagnostics.rtdac import link_check
from sashil.drivers import rig_parts
from sashil.drivers.emulator.rtdac_board import BoardFaults, build_board
from sashil.drivers.emulator.rtdac_usb import DirectPort, EmulatedUsbBackend, UsbFaults
from sashil.drivers.interface import RigCommand
from sashil.drivers.rtdac_bus import exchange_ns, link_limits, transaction_ns, transfer_ns
from sashil.drivers.rtdac_codec import DA_ZERO, READ_REQUEST
from sashil.drivers.rtdac_rest import rest_until_confirmed
from sashil.drivers.rtdac_rig import RtdacRig
from sashil.drivers.rtdac_usb import BoardLink, UsbSettings
from sashil.engine.resolve import default_config
from sashil.errors import DriverError, DriverIOError

PERIOD_NS = 1_000_000
#: a fault's time from the claim: after configure, which waits 0.5 s for the arm to stand still
AFTER_CONFIGURE_S = 0.8


class Clock:
    def __init__(self) -> None:
        self.now = 1_000_000_000

    def __call__(self) -> int:
        self.now += 20_000
        return self.now


class Tap(DirectPort):
    """A direct port that keeps every request the host sent."""

    def __init__(self, board, clock, usb_faults=None):
        super().__init__(board, clock, usb_faults)
        self.requests: list[bytes] = []

    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        self.requests.append(bytes(request))
        return super().call(request, timeout_s)

    def writes(self) -> list[bytes]:
        return [r[2:] for r in self.requests if r[:1] == b"W"]


def board_and_port(usb: UsbFaults | None = None, faults: BoardFaults | None = None):
    clock = Clock()
    board = build_board(freeze_config(default_config()), faults=faults)
    return board, Tap(board, clock, usb), clock


def link_to(port: Tap, rate_hz: float | None = None) -> BoardLink:
    return BoardLink(UsbSettings(rate_hz=rate_hz), EmulatedUsbBackend(port))


def rig_on(port: Tap) -> RtdacRig:
    rig = RtdacRig.from_parts(rig_parts(freeze_config(default_config()), "rtdac"))
    rig.link.backend = EmulatedUsbBackend(port)
    clock = port.clock
    rig.monotonic = lambda: clock.now * 1e-9  # configure's wait for the arm's stillness on simulated time

    def sleep(seconds: float) -> None:
        clock.now += round(seconds * 1e9)

    rig.sleep = sleep
    return rig


# the bus's arithmetic (USB 2.0 section 5.11.3) ---------------------------------------------------
def test_a_full_speed_exchange_is_948_us_of_bus_time_and_leaves_room_for_844_hz():
    # 9107 + 83.54 * floor(3.167 + 64 * 8 * 7/6) = 9107 + 83.54 * 600 ns
    assert transaction_ns(2, 64) == pytest.approx(59_231.0)
    assert transaction_ns(2, 4) == pytest.approx(9107 + 83.54 * 40)  # floor(3.167 + 37.33)
    assert transfer_ns(2, 504, 64) == pytest.approx(7 * 59_231.0 + 9107 + 83.54 * 525)  # 7 x 64 + 56
    assert exchange_ns(2, 64, 64) == pytest.approx(947_613.6, abs=0.1)
    assert link_limits(2, 64, 64) == (1055, math.floor(1e9 / (947_613.6 * 1.25)))
    assert link_limits(2, 64, 64)[1] == 844
    # high speed: one 504-byte packet a frame, 55 * 8 * 2.083 + 2.083 * floor(3.167 + 4704) ns
    assert transaction_ns(3, 504) == pytest.approx(55 * 8 * 2.083 + 2.083 * 4707)
    assert link_limits(3, 512, 512)[1] == 35_647
    assert link_limits(1, 8, 8) == (0, 0)  # a low-speed device has no bulk transfers
    assert link_limits(4, 1024, 1024) == (None, None) and link_limits(None, 64, 64) == (None, None)


# first contact -----------------------------------------------------------------------------------
def test_open_reports_the_board_its_speed_and_the_rate_its_link_carries():
    _board, port, _clock = board_and_port()
    link = link_to(port, rate_hz=1000.0)
    link.open()
    assert link.speed == 3 and link.max_rate_hz == 35_647
    facts = link.facts()
    assert facts["usb_ids"] == "04b4:8613"
    assert (facts["manufacturer"], facts["product"], facts["serial"]) == ("InTeCo", "RT-DAC/USB2", "1")
    assert facts["usb_speed"] == "high-speed (480 Mbit/s)" and facts["stale_frames_discarded"] == 0
    assert link.summary() == (
        "InTeCo RT-DAC/USB2, serial '1', USB 04b4:8613 at bus 1 device 2, high-speed (480 Mbit/s): room for a "
        "35647 Hz loop (44558 exchanges a second at most); 0 stale frame(s) drained from endpoint 4"
    )
    check = link_check(link, 1000.0)
    assert check.status == OK and check.data["bus_max_rate_hz"] == 35_647
    link.close()


def test_a_full_speed_link_refuses_a_1_khz_loop_in_one_line_before_any_transfer():
    board, port, _clock = board_and_port(UsbFaults(full_speed=True))
    board.words[board.map.pwm_width_word(0)] = 1234  # what a previous host left: must stay untouched
    link = link_to(port, rate_hz=1000.0)
    with pytest.raises(DriverError) as err:
        link.open()
    assert str(err.value) == (
        "rtdac: the board is on a full-speed USB link (12 Mbit/s), which carries at most 1055 exchanges a second "
        "(948 us of bus time each, USB 2.0 section 5.11.3) and leaves room for a 844 Hz loop; loop.rate_hz is 1000: "
        "plug the board into a high-speed (USB 2.0) port with no USB 1.1 hub between, or --set loop.rate_hz=844"
    )
    assert err.value.exit_code == 2
    assert not [r for r in port.requests if r[:1] in (b"W", b"R")]  # not a transfer: nothing energised
    assert port.state["usb"].board is board and port.state.get("holder") is None  # the claim released
    assert board.words[board.map.pwm_width_word(0)] == 1234
    # the rate the link carries is accepted, and the doctor warns of a faster loop
    link = link_to(port, rate_hz=844.0)
    link.open()
    assert link.speed == 2 and link.max_rate_hz == 844
    check = link_check(link, 1000.0)
    assert check.status == WARN and "full-speed (12 Mbit/s): room for a 844 Hz loop" in check.found
    assert "--set loop.rate_hz=844" in check.fix
    link.close()


def test_the_backend_refuses_a_loop_faster_than_a_full_speed_link_before_anything_is_written():
    if "rate_hz" not in RtdacRig.reads:
        pytest.skip("the rtdac backend does not pass loop.rate_hz to its link (RtdacRig.reads['rate_hz'])")
    board, port, _clock = board_and_port(UsbFaults(full_speed=True))
    rig = rig_on(port)
    with pytest.raises(
        DriverError, match=r"^rtdac: the board is on a full-speed USB link \(12 Mbit/s\), which carries"
    ):
        rig.configure()
    assert port.writes() == [] and board.at_rest()
    rig.close()


@pytest.mark.parametrize(
    ("missing", "text"),
    [
        (
            0x84,
            "the board has no bulk IN endpoint 0x84 (frames from the FPGA) on interface 0; it offers 0x02 bulk OUT, "
            "0x06 bulk OUT, 0x88 bulk IN (is its FPGA firmware an RT-DAC/USB2's?)",
        ),
        (
            0x02,
            "the board has no bulk OUT endpoint 0x02 (frames to the FPGA) on interface 0; it offers 0x84 bulk IN, "
            "0x06 bulk OUT, 0x88 bulk IN (is its FPGA firmware an RT-DAC/USB2's?)",
        ),
    ],
)
def test_a_missing_endpoint_is_named_in_one_line_and_nothing_is_written(missing, text):
    board, port, _clock = board_and_port(UsbFaults(missing_endpoint=missing))
    rig = rig_on(port)
    with pytest.raises(DriverError) as err:
        rig.configure()
    assert str(err.value) == f"rtdac bus 1 device 2 (04b4:8613): {text}"
    assert type(err.value) is DriverError and err.value.exit_code == 2
    assert port.writes() == [] and board.at_rest() and port.state.get("holder") is None
    rig.close()


def test_stale_frames_on_endpoint_4_are_drained_so_the_first_sample_is_this_hosts():
    """Two frames an earlier host asked for (the arm at 0 deg then) wait on endpoint 4; the arm is now
    held at -5 deg. Read without the drain, configure's greeting and the first sample are those frames."""
    board, port, clock = board_and_port(UsbFaults(stale_frames=2))
    rig = rig_on(port)
    rig.configure()  # the counters zeroed at the rest the arm hangs in; then the operator presses it
    board.rig.plant.hold(math.radians(-5.0))
    assert rig.link.facts()["stale_frames_discarded"] == 2 and port.usb.stale == []
    assert port.writes()[0] == READ_REQUEST  # the drain reads only: the first transfer out is the greeting's
    clock.now += PERIOD_NS
    sample = rig.read(PERIOD_NS, PERIOD_NS)
    assert math.degrees(sample.theta_rad) == pytest.approx(-5.0, abs=0.1)
    rig.close()


# recovery on the stop path ----------------------------------------------------------------------
def rest_readback(words: tuple[int, ...]) -> bool:
    """The default wiring's outputs at rest in a read frame: PWM 0's width 0, D/A 0 at 0 V."""
    return words[22] == 0 and words[220] == DA_ZERO


def driven(usb: UsbFaults, faults: BoardFaults | None = None):
    """A rig driving the coil and the road motor until the fault ends its run (a DriverIOError)."""
    board, port, clock = board_and_port(usb, faults)
    rig = rig_on(port)
    rig.configure()
    rig.activate()
    with pytest.raises(DriverIOError) as err:
        for _ in range(500):
            clock.now += PERIOD_NS
            rig.read(clock.now, PERIOD_NS)
            rig.write(RigCommand(0.8, 1.0), clock.now, PERIOD_NS)
    assert not board.at_rest()
    return board, port, rig, str(err.value)


class FakeTime:
    """A clock in seconds that moves only when the loop pauses (and a little at each read)."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += seconds


@pytest.mark.parametrize("endpoint", [0x02, 0x84])
def test_a_halted_endpoint_is_cleared_and_the_rest_frame_then_confirmed(endpoint):
    board, port, rig, error = driven(UsbFaults(halt_after_s=AFTER_CONFIGURE_S, halt_endpoint=endpoint))
    assert f"Pipe error (endpoint 0x{endpoint:02x} halted)" in error
    rig.rest_outputs()
    fake = FakeTime()
    outcome = rest_until_confirmed(rig.exchange, rest_readback, rig.link.recover, fake, 0.3, fake.sleep)
    assert outcome.confirmed and outcome.attempts == 2 and outcome.elapsed_s == 0.0
    assert "Pipe error" in str(outcome.last_error)
    assert board.at_rest() and board.drive_a == 0.0
    assert rig.link.recoveries == {"clear_halt": 1, "reopen": 0} and port.usb.clear_halts == 2
    rig.close()


def test_a_transfer_error_only_a_reopen_cures_is_cured_by_reset_and_reopen_and_the_rest_confirmed():
    board, port, rig, error = driven(UsbFaults(wedge_after_s=AFTER_CONFIGURE_S))
    assert "Input/Output Error (the board's FIFO is stuck)" in error
    before = rig.link.dev
    rig.rest_outputs()
    fake = FakeTime()
    outcome = rest_until_confirmed(rig.exchange, rest_readback, rig.link.recover, fake, 0.3, fake.sleep)
    assert outcome.confirmed and outcome.attempts == 2
    assert board.at_rest()
    assert rig.link.recoveries == {"clear_halt": 0, "reopen": 1} and port.usb.resets >= 1
    assert rig.link.dev is not None and rig.link.dev is not before  # the same board, opened anew
    assert rig.link.facts()["serial"] == "1"
    rig.close()


class Unplugged(Tap):
    """A port whose board can be pulled from the bus: then every request answers "no such device"."""

    gone = False

    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        if self.gone:
            return b"\x01\x13No such device (it may have been disconnected)"
        return super().call(request, timeout_s)


def test_a_board_gone_from_the_bus_ends_the_loop_at_its_deadline_with_the_recoverys_one_line():
    clock = Clock()
    board = build_board(freeze_config(default_config()))
    port = Unplugged(board, clock)
    rig = rig_on(port)
    rig.configure()
    rig.activate()
    for _ in range(20):
        clock.now += PERIOD_NS
        rig.read(clock.now, PERIOD_NS)
        rig.write(RigCommand(0.8, 1.0), clock.now, PERIOD_NS)
    port.gone = True
    with pytest.raises(DriverIOError) as first:
        rig.link.recover()
    assert str(first.value) == (
        "rtdac bus 1 device 2 (04b4:8613): recover: neither clearing the endpoints' halt (No such device (it may have "
        "been disconnected)) nor a reset and reopen (no 04b4:8613 with serial '1' on the bus any more) brought it back"
    )
    rig.rest_outputs()
    fake = FakeTime()
    outcome = rest_until_confirmed(rig.exchange, rest_readback, rig.link.recover, fake, 0.25, fake.sleep, 1 / 64)
    assert not outcome.confirmed and outcome.attempts == 16 and outcome.elapsed_s == 0.25
    text = str(outcome.last_error)
    assert isinstance(outcome.last_error, DriverIOError) and "\n" not in text
    # the first recovery tried both steps; the later ones, the link let go, the reopen alone
    assert text == (
        "rtdac bus 1 device 2 (04b4:8613): recover: the reopen failed (no 04b4:8613 with serial '1' on the bus any more)"
    )
    with pytest.raises(DriverIOError) as err:
        rig.link.recover()
    assert str(err.value) == text
    assert not board.at_rest()  # the board keeps its outputs: the E-stop's to cover
    rig.close()


def test_recover_on_a_link_never_opened_says_so():
    _board, port, _clock = board_and_port()
    with pytest.raises(DriverIOError, match="recover: the board is not open"):
        link_to(port).recover()


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--stale-frames", "-1"], "--stale-frames: expected a count from 0 to 64, got -1"),
        (["--halt-after", "-0.5"], "--halt-after: expected seconds >= 0, got -0.5"),
        (["--wedge-after", "nan"], "--wedge-after: expected seconds >= 0, got nan"),
    ],
)
def test_a_bad_usb_fault_flag_is_one_line_and_exit_2_with_no_socket(tmp_path, capsys, flags, message):
    from sashil.cli import main

    link = tmp_path / "rtdac.sock"
    assert main(["emulate", "--transport", "rtdac", "--link", str(link), "--duration", "0.1", *flags]) == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert len(errors) == 1 and message in errors[0], errors
    assert not link.exists()


@pytest.mark.parametrize("usb", [UsbFaults(halt_after_s=AFTER_CONFIGURE_S), UsbFaults(wedge_after_s=AFTER_CONFIGURE_S)])
def test_deactivate_recovers_the_link_and_confirms_the_rest_from_the_readback(usb):
    board, _port, rig, _error = driven(usb)
    rig.deactivate()
    assert rig.safe_state["safe_state_confirmed"] is True and rig.safe_state["safe_state_attempts"] == 2
    assert board.at_rest()
    rig.close()


def test_a_reply_that_comes_after_its_transfer_timed_out_is_dropped_not_taken_for_the_next(tmp_path):
    """Over the board's socket, a write whose reply comes late (the board's process was descheduled)
    has timed out on the host; the late reply (``OK`` + a 2-byte count) must not be read as the
    next transfer's answer (a 504-byte frame)."""
    import socket

    from sashil.drivers.emulator.rtdac_usb import OK, SocketPort

    path = str(tmp_path / "board.sock")
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    listener.bind(path)
    listener.listen(1)
    port = SocketPort(path)
    try:
        assert port.call(b"W\x02" + bytes(8), timeout_s=0.0) is None  # no answer yet: timed out
        board, _ = listener.accept()
        with board:
            write = board.recv(1024)
            assert write[2:4] == b"W\x02"
            board.send(write[:2] + OK + (8).to_bytes(2, "little"))  # the write's answer, late
            frame = bytes(range(256)) * 2  # 512 bytes, the read's answer, tagged as the next request
            board.send((int.from_bytes(write[:2], "little") + 1).to_bytes(2, "little") + OK + frame[:504])
            assert port.call(b"R\x84" + (504).to_bytes(2, "little"), timeout_s=1.0) == OK + frame[:504]
            assert board.recv(1024)[2:4] == b"R\x84"
    finally:
        port.close()
        listener.close()
