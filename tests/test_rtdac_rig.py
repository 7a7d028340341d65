"""The rtdac backend through pyusb's own core, against the emulated board in this process.

The board (:class:`RtdacBoard`) runs on a clock the test advances, so every figure is deterministic;
the host side is the real pyusb core and sashil's backend, with only libusb replaced by the
emulated board's pyusb backend.
"""

from __future__ import annotations

import math

import pytest

from sashil.config.frozen import freeze_config
from sashil.config.rtdac_section import WIRING_KEYS
from sashil.drivers import rig_parts
from sashil.drivers.emulator.device import Operator
from sashil.drivers.emulator.rtdac_board import BoardFaults, BoardIdentity, RtdacBoard, build_board
from sashil.drivers.emulator.rtdac_usb import DirectPort, EmulatedUsbBackend
from sashil.drivers.interface import RigCommand
from sashil.drivers.rtdac_codec import DA_ZERO, READ_REQUEST, WRITE_MARK, decode_frame
from sashil.drivers.rtdac_rig import RtdacRig
from sashil.engine.resolve import default_config
from sashil.errors import ConfigError, DriverError, DriverIOError, DriverTimeoutError, ProtocolError

PERIOD_NS = 1_000_000
#: the emulated bench's wiring as the walk confirmed it: the defaults, with the coil sensed on A/D 0
BENCH_SECTION = {"confirmed": list(WIRING_KEYS), "coil_sense_ad": 0}
BENCH = {f"rtdac.{key}": value for key, value in BENCH_SECTION.items()}


class Clock:
    """The board's clock: the test moves it a period a cycle, and each transfer takes 20 us."""

    def __init__(self) -> None:
        self.now = 1_000_000_000
        self.host = 0  # the host's loop clock

    def __call__(self) -> int:
        self.now += 20_000
        return self.now


class Tap(DirectPort):
    """A direct port that keeps every transfer the host sent to the board."""

    def __init__(self, board: RtdacBoard, clock: Clock):
        super().__init__(board, clock)
        self.sent: list[bytes] = []

    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        if request[:1] == b"W":
            self.sent.append(bytes(request[2:]))
        return super().call(request, timeout_s)


def make(
    sets: dict | None = None,
    faults: BoardFaults | None = None,
    identity: BoardIdentity | None = None,
    logic: str = "0103",
    operator: Operator | None = None,
    board_sets: dict | None = None,
) -> tuple[RtdacRig, RtdacBoard, Clock, Tap]:
    sets = {**BENCH, **(sets or {})}
    raw = default_config()
    for key, value in sets.items():
        section, name = key.split(".")
        raw[section][name] = value
    config = freeze_config(raw)
    board_raw = default_config()
    for key, value in {**sets, **(board_sets or {})}.items():
        section, name = key.split(".")
        board_raw[section][name] = value
    clock = Clock()
    board = build_board(freeze_config(board_raw), logic, identity, operator, faults)
    port = Tap(board, clock)
    rig = RtdacRig.from_parts(rig_parts(config, "rtdac"))
    rig.link.backend = EmulatedUsbBackend(port)
    on_clock(rig, clock)
    return rig, board, clock, port


def on_clock(rig: RtdacRig, clock: Clock) -> None:
    """The rig's waits (the arm's stillness at configure) on the board's simulated clock."""
    rig.monotonic = lambda: clock.now * 1e-9

    def sleep(seconds: float) -> None:
        clock.now += round(seconds * 1e9)

    rig.sleep = sleep


def cycle(rig: RtdacRig, clock: Clock, cmd: RigCommand, n: int = 1):
    sample = None
    for _ in range(n):
        clock.now += PERIOD_NS
        clock.host += PERIOD_NS
        sample = rig.read(clock.host, PERIOD_NS)
        rig.write(cmd, clock.host, PERIOD_NS)
    return sample


def test_configure_reads_the_header_picks_the_map_and_writes_both_outputs_at_rest():
    rig, board, _clock, port = make()
    board.words[board.map.pwm_width_word(0)] = 3000  # a previous host left the coil on
    board.words[board.map.da_word(0)] = 12000
    rig.configure()
    assert rig.map is not None and rig.map.logic == "0103"
    assert rig.header is not None and rig.header.application == "SASHIL"
    # what crossed: one read request, then one write frame that rests both outputs
    assert port.sent[0] == READ_REQUEST
    frame = port.sent[1]
    assert len(frame) == 504 and frame[:2] == WRITE_MARK
    assert frame[2 * 22 : 2 * 22 + 2] == b"\x00\x00"  # PWM 0 width 0 (RTDACUSB2_0103.cs line 168)
    assert frame[2 * 21 : 2 * 21 + 2] == b"\x02\x00"  # mode 12-bit << 1 (line 166)
    assert frame[2 * 220 : 2 * 220 + 2] == DA_ZERO.to_bytes(2, "little")  # D/A 0 at 0 V (line 221)
    assert board.at_rest()
    rig.close()


def test_the_0111_layout_is_read_with_its_own_map():
    rig, board, clock, _ = make(logic="0111")
    rig.configure()
    assert rig.map is not None and rig.map.logic == "0111" and rig.map.da_word(0) == 210
    rig.activate()
    cycle(rig, clock, RigCommand(0.0, 1.0), 50)
    assert board.words[210] != DA_ZERO  # the road motor's D/A is driven where 0111 puts it
    rig.close()
    assert board.at_rest()


def test_a_commanded_current_becomes_a_duty_and_the_sensed_current_follows():
    rig, board, clock, _ = make()
    rig.configure()
    rig.activate()
    sample = cycle(rig, clock, RigCommand(0.5), 200)
    # the map 0..1 A -> duty 0..1 (a 12-bit width), corrected by the loop on the sensed current
    assert board.words[board.map.pwm_width_word(0)] == pytest.approx(0.5 * 4095, abs=40)
    assert sample.current_a == pytest.approx(0.5, abs=0.01)  # A/D 0 at 5 V/A, 12 bits: 1 mA a count
    assert rig.link_stats()["current_source"] == "sensed (A/D 0)"
    rig.close()


def test_the_current_loop_corrects_a_power_stage_the_map_does_not_match():
    raw = default_config()
    clock = Clock()
    board = build_board(freeze_config(raw), stage_gain=0.85)  # 15 % less current than the map says
    host = default_config()
    host["rtdac"].update(BENCH_SECTION)
    rig = RtdacRig.from_parts(rig_parts(freeze_config(host), "rtdac"))
    rig.link.backend = EmulatedUsbBackend(DirectPort(board, clock))
    on_clock(rig, clock)
    rig.configure()
    rig.activate()
    sample = cycle(rig, clock, RigCommand(0.6), 600)
    assert sample.current_a == pytest.approx(0.6, abs=0.01)  # within the loop's authority: +17.6 % of the map
    assert not sample.coil_at_authority
    rig.close()


@pytest.mark.parametrize("sense", ["dead", "doubled"])
def test_a_sense_that_disagrees_moves_the_coil_at_most_the_loops_authority_and_says_so(sense):
    """A sense on a channel that reads nothing (A/D 5: nothing wired there) or at twice its scale: the
    duty stays within (1 ± 0.25) x the map's duty for the command, and the sample says the loop sits at
    its bound (the supervisor trips on it)."""
    sets = {"rtdac.coil_sense_ad": 5} if sense == "dead" else {"rtdac.coil_sense_a_per_v": 0.4}
    rig, board, clock, _ = make(sets, board_sets={"rtdac.coil_sense_ad": 0, "rtdac.coil_sense_a_per_v": 0.2})
    rig.configure()
    rig.activate()
    duties = []
    for _ in range(300):
        sample = cycle(rig, clock, RigCommand(0.4), 1)
        duties.append(board.output("pwm", 0))
    count = 1 / 4095  # one step of the 12-bit width
    assert 0.75 * 0.4 - count <= min(duties) and max(duties) <= 1.25 * 0.4 + count
    assert duties[-1] == pytest.approx(0.4 * (1.25 if sense == "dead" else 0.75), abs=count)
    assert sample.coil_at_authority
    rig.close()


def test_without_a_current_sense_current_a_is_empty_not_a_model():
    rig, _board, clock, _ = make({"rtdac.coil_sense_ad": None})
    rig.configure()
    rig.activate()
    sample = cycle(rig, clock, RigCommand(1.0), 10)
    assert math.isnan(sample.current_a)
    assert not rig.capabilities.current_sensed
    assert rig.link_stats()["current_source"] == "none (no current sense)"
    rig.close()


def test_the_host_closes_the_road_loop_on_the_road_encoder_and_reports_its_tracking():
    rig, board, clock, _ = make()
    rig.configure()
    rig.activate()
    start = cycle(rig, clock, RigCommand(0.0, None), 1).theta_road_rad
    sample = cycle(rig, clock, RigCommand(0.0, 2.0), 2000)
    assert sample.theta_road_rad - start == pytest.approx(4.0, abs=0.05)
    tracking = rig.link_stats()
    assert tracking["road_cycles"] == 2000
    assert 0.0 < tracking["road_error_rms_rad"] < 0.05
    rig.close()
    assert board.at_rest() and board.road_target_rad_s == 0.0


def test_the_encoders_wiring_signs_and_resolutions_come_from_config():
    sets = {
        "rtdac.arm_encoder": 5,
        "rtdac.arm_reversed": True,
        "rtdac.road_encoder": 2,
        "rtdac.road_counts_per_rev": 1024,
    }
    rig, board, clock, _ = make(sets)
    rig.configure()  # the counters zeroed with the arm at rest, then the operator presses it down
    board.rig.plant.hold(math.radians(-5.0))
    sample = cycle(rig, clock, RigCommand(0.0), 1)
    assert math.degrees(sample.theta_rad) == pytest.approx(-5.0, abs=0.1)
    low, _ = board.map.counter_words(5)
    assert board.words[low] == round(5.0 / 360 * 4096)  # the emulated bench counts the arm down
    rig.close()


def test_deactivate_rests_both_outputs_and_the_readback_confirms_it():
    rig, board, clock, _ = make()
    rig.configure()
    rig.activate()
    cycle(rig, clock, RigCommand(1.0, 3.0), 100)
    assert not board.at_rest()
    rig.deactivate()
    assert board.at_rest()
    assert rig.link_stats()["safe_state_confirmed"] is True
    rig.close()


def test_wiring_the_board_does_not_have_is_refused_before_anything_is_written():
    rig, _board, _clock, port = make({"rtdac.arm_encoder": 12})
    with pytest.raises(DriverError, match=r"rtdac.arm_encoder: the board has no encoder counter 12 \(logic 0103"):
        rig.configure()
    assert port.sent == [READ_REQUEST]  # only the header was read: no frame written
    rig.close()


def test_a_bad_wiring_key_is_refused_when_the_config_is_checked():
    from sashil.config.schema import validate
    from sashil.config.sections import SCHEMA

    with pytest.raises(ConfigError, match=r"lab.yaml: rtdac.coil_channel: expected a D/A channel from 0 to 3, got 7"):
        validate({"rtdac": {"coil_output": "da", "coil_channel": 7, "coil_map_output": [0, 5]}}, SCHEMA, "lab.yaml")
    with pytest.raises(ConfigError, match=r"lab.yaml: rtdac.coil_map_output: expected as many points"):
        validate({"rtdac": {"coil_map_output": [0, 0.5, 1]}}, SCHEMA, "lab.yaml")
    with pytest.raises(ConfigError, match=r"lab.yaml: rtdac.road_encoder: the same counter as arm_encoder"):
        validate({"rtdac": {"road_encoder": 0}}, SCHEMA, "lab.yaml")


#: a fault's time from the claim: after configure, which waits 0.5 s for the arm to stand still
AFTER_CONFIGURE_S = 0.8


@pytest.mark.parametrize(
    ("faults", "error", "text"),
    [
        (BoardFaults(vanish_after_s=AFTER_CONFIGURE_S), DriverIOError, "the board is gone (No such device"),
        (
            BoardFaults(short_frame_after_s=AFTER_CONFIGURE_S),
            ProtocolError,
            "a read frame of 502 bytes from endpoint 4, expected 504",
        ),
        (
            BoardFaults(timeout_after_s=AFTER_CONFIGURE_S),
            DriverTimeoutError,
            "no answer within 20 ms (transfer timed out)",
        ),
        (
            BoardFaults(stuck_busy_after_s=AFTER_CONFIGURE_S),
            DriverIOError,
            "A/D 0 (the coil current) has stayed busy for",
        ),
    ],
)
def test_a_fault_mid_run_is_one_line_and_the_board_ends_at_rest_where_it_can(faults, error, text):
    rig, board, clock, _ = make(faults=faults)
    rig.configure()
    rig.activate()
    with pytest.raises(error) as err:
        cycle(rig, clock, RigCommand(0.8, 1.0), 500)
    assert text in str(err.value) and "\n" not in str(err.value)
    rig.close()
    if faults.vanish_after_s is None and faults.timeout_after_s is None:
        assert board.at_rest()  # reachable: both outputs rested on the way out


def test_permission_denied_says_which_udev_rule_fixes_it():
    rig, *_ = make(faults=BoardFaults(permission_denied=True))
    with pytest.raises(DriverError) as err:
        rig.configure()
    text = str(err.value)
    assert "permission denied" in text and 'ATTRS{manufacturer}=="InTeCo"' in text and "/etc/udev/rules.d/" in text
    rig.close()


def test_another_program_holding_the_board_is_named():
    rig, _board, _clock, port = make()
    port.state["holder"] = object()  # another host claimed it
    with pytest.raises(DriverError, match="another program holds the board"):
        rig.configure()
    rig.close()


def test_no_board_says_so_in_one_line():
    class Nowhere(DirectPort):
        def call(self, request: bytes, timeout_s: float) -> bytes | None:
            return b"\x01\x13No such device"

    rig, board, clock, _ = make()
    rig.link.backend = EmulatedUsbBackend(Nowhere(board, clock))
    with pytest.raises(DriverError, match=r"rtdac: no RT-DAC/USB2 found \(manufacturer 'InTeCo'; is it plugged in"):
        rig.configure()


def test_a_register_readback_through_pyusb_gives_what_was_written():
    rig, board, clock, _ = make({"rtdac.coil_loop_ki_per_s": 0.0})
    rig.configure()
    rig.activate()
    cycle(rig, clock, RigCommand(0.25), 1)
    words = decode_frame(rig.link.read_frame())
    assert words[22] == board.words[22] == round(0.25 * 4095)
    rig.close()


def test_the_board_keeps_its_outputs_when_the_host_goes_quiet():
    rig, board, clock, _ = make()
    rig.configure()
    rig.activate()
    cycle(rig, clock, RigCommand(0.7), 20)
    rig.link.close()  # the host vanishes without a word: no watchdog on this board
    clock.now += 5_000_000_000
    board.bulk_write(0x02, READ_REQUEST, clock.now)
    assert not board.at_rest() and board.drive_a > 0.6


def test_a_pyusb_backend_named_in_config_is_called_with_the_port_or_with_nothing(tmp_path, monkeypatch):
    """An emulator that is not ours plugs in as ``rtdac.usb_backend: module:callable``."""
    import sys
    import types

    from sashil.drivers.rtdac_usb import UsbSettings, pyusb_backend

    board = build_board(freeze_config(default_config()))
    module = types.ModuleType("their_emulator")
    module.with_port = lambda port: ("port", port)  # type: ignore[attr-defined]
    module.without = lambda: EmulatedUsbBackend(DirectPort(board))  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "their_emulator", module)
    assert pyusb_backend(UsbSettings(usb_backend="their_emulator:with_port", port="bus 3")) == ("port", "bus 3")
    assert isinstance(pyusb_backend(UsbSettings(usb_backend="their_emulator:without")), EmulatedUsbBackend)
    with pytest.raises(ConfigError, match=r"rtdac\.usb_backend: cannot load 'their_emulator:nothing'"):
        pyusb_backend(UsbSettings(usb_backend="their_emulator:nothing"))
    raw = default_config()
    raw["rtdac"]["usb_backend"] = "their_emulator:without"
    rig = RtdacRig.from_parts(rig_parts(freeze_config(raw), "rtdac"))
    rig.configure()
    assert rig.header is not None and rig.header.logic == "0103"
    rig.close()


def test_a_header_that_reports_no_module_counts_is_read_with_the_maps():
    """A board (or another emulator) that leaves the header's count words at 0: the map's counts stand."""
    rig, board, clock, _ = make(identity=BoardIdentity(logic_version=0x0103, modules={}))
    rig.configure()
    assert rig.header is not None and rig.header.modules["encoder_i"] == 0
    rig.activate()
    cycle(rig, clock, RigCommand(0.5), 5)
    assert board.words[board.map.pwm_width_word(0)] > 0
    rig.close()
    assert board.at_rest()


def test_a_board_that_names_no_manufacturer_is_found_by_its_usb_ids():
    import errno as errnos

    import usb.core

    class Mute(EmulatedUsbBackend):
        def ctrl_transfer(self, *args, **kwargs):
            raise usb.core.USBError("Pipe error (request not supported)", -9, errnos.EPIPE)

    rig, _, _, port = make()
    rig.link.backend = Mute(port)
    with pytest.raises(DriverError, match=r"rtdac\.vendor_id and rtdac\.product_id"):
        rig.configure()
    rig.close()
    rig, _, _, port = make({"rtdac.vendor_id": 0x04B4, "rtdac.product_id": 0x8613})
    rig.link.backend = Mute(port)
    rig.configure()
    assert rig.header is not None and rig.header.logic == "0103"
    rig.close()
