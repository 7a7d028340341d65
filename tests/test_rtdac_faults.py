"""The emulated RT-DAC bench wired otherwise than the host's config guesses, and the board's own
faults: each ends at rest, tripped or refused in one line, on simulated time.

The host is the real backend through pyusb's core, with the safety supervisor of a run on each
cycle (:func:`run`), against the emulated board in this process (tests/test_rtdac_rig.py's ``make``).
"""

from __future__ import annotations

import math

import pytest
from test_rtdac_rig import BENCH, PERIOD_NS, Clock, cycle, make

from sashil.config.rtdac_section import COIL_KEYS, WIRING_KEYS
from sashil.drivers.emulator.rtdac_board import BoardFaults, Relay, RtdacBoard
from sashil.drivers.interface import RigCommand
from sashil.drivers.rtdac_codec import decode_frame, pwm_duty
from sashil.drivers.rtdac_rig import RtdacRig
from sashil.errors import DriverIOError, SafetyTrip
from sashil.safety import SafetySupervisor

GUESSED = {"rtdac.confirmed": [], "rtdac.coil_sense_ad": None}


class Watch:
    """What the bench did on each cycle: the road's true angle off the host's reference, the road
    output at its limit, the coil's duty."""

    def __init__(self) -> None:
        self.road_off_rad = 0.0
        self.road_at_limit_s = 0.0
        self.duties: list[float] = []
        self.trip: SafetyTrip | None = None


def run(rig: RtdacRig, board: RtdacBoard, clock: Clock, cmd: RigCommand, seconds: float, coast_s: float = 0.3) -> Watch:
    """``cmd`` each cycle for ``seconds`` under the supervisor with the config's bounds, as the loop
    runs it; on a trip the outputs rested, then the bench watched ``coast_s`` more."""
    watch = Watch()
    safety = SafetySupervisor(current_max_a=1.0, arm_travel_rad=math.radians(30.0))
    rig.configure()
    rig.activate()
    safety.start(clock.host)
    reference = 0.0
    for _ in range(round(seconds * 1e9 / PERIOD_NS)):
        clock.now += PERIOD_NS
        clock.host += PERIOD_NS
        sample = rig.read(clock.host, PERIOD_NS)
        try:
            safety.check(sample, clock.host)
        except SafetyTrip as trip:
            watch.trip = trip
            break
        rig.write(safety.limit(cmd, PERIOD_NS), clock.host, PERIOD_NS)
        if rig.road.reference_rad is not None:
            reference = rig.road.reference_rad
        watch.road_off_rad = max(watch.road_off_rad, abs(board.rig.plant.state.theta_road_rad - reference))
        watch.road_at_limit_s += PERIOD_NS * 1e-9 if rig.road.at_limit else 0.0
        watch.duties.append(board.output("pwm", 0))
    rig.deactivate()
    for _ in range(round(coast_s * 1e9 / PERIOD_NS)):  # the road coasts down with the motor's lag
        clock.now += PERIOD_NS
        board.bulk_write(0x02, bytes((0xFF, 0x8F, 0, 0)), clock.now)
        board.bulk_read(0x84, 504, clock.now)
        watch.road_off_rad = max(watch.road_off_rad, abs(board.rig.plant.state.theta_road_rad - reference))
    return watch


@pytest.mark.parametrize("host", ["guessed", "wrongly confirmed"])
def test_a_road_encoder_reversed_against_the_config_trips_naming_the_road_before_it_runs_away(host):
    sets = GUESSED if host == "guessed" else BENCH
    rig, board, clock, _ = make(sets, board_sets={"rtdac.road_reversed": True})
    watch = run(rig, board, clock, RigCommand(0.0, 1.0), 2.0)
    assert watch.trip is not None and "the road" in str(watch.trip) and "\n" not in str(watch.trip)
    assert watch.road_off_rad <= 0.1, watch.road_off_rad
    assert watch.road_at_limit_s <= 0.1
    assert board.at_rest() and rig.safe_state["safe_state_confirmed"] is True


def test_the_same_road_on_a_bench_wired_as_configured_runs_through():
    rig, board, clock, _ = make()
    watch = run(rig, board, clock, RigCommand(0.3, 0.3), 1.0)
    assert watch.trip is None
    assert watch.road_off_rad < 0.01 and watch.road_at_limit_s == 0.0
    assert board.at_rest()


def test_a_coil_sense_on_a_channel_that_reads_nothing_trips_and_the_duty_stays_within_the_authority():
    rig, board, clock, _ = make({"rtdac.coil_sense_ad": 3}, board_sets={"rtdac.coil_sense_ad": 0})
    watch = run(rig, board, clock, RigCommand(0.4, None), 1.0)
    assert watch.trip is not None and "sensed current disagrees" in str(watch.trip)
    assert max(watch.duties) <= 1.25 * 0.4 + 1 / 4095  # the map's duty for 0.4 A is 0.4
    assert board.at_rest()


def test_counters_left_at_arbitrary_values_read_zero_at_the_rest_configure_finds():
    rig, board, clock, _ = make(faults=BoardFaults(counter_preset=1_234_567))
    rig.configure()
    sample = cycle(rig, clock, RigCommand(0.0), 1)
    assert (sample.arm_counts, sample.road_counts) == (0, 0)
    low, high = board.map.counter_words(0)
    assert (board.words[high] << 16 | board.words[low]) == 0  # the board took the reset
    rig.close()


def test_a_board_that_ignores_the_reset_word_has_its_counters_offset_subtracted():
    rig, board, clock, _ = make(faults=BoardFaults(counter_preset=-70_000, ignored_words=(50,)))
    rig.configure()
    board.rig.plant.hold(math.radians(-5.0))  # the operator presses once asked
    sample = cycle(rig, clock, RigCommand(0.0), 1)
    assert math.degrees(sample.theta_rad) == pytest.approx(-5.0, abs=0.1)
    low, high = board.map.counter_words(0)
    assert (board.words[high] << 16 | board.words[low]) != 0  # the preset is still on the board
    rig.close()


def test_an_index_reset_mid_run_is_an_encoder_step_that_trips():
    rig, board, clock, _ = make(faults=BoardFaults(index_reset_after_s=1.0))
    rig.configure()
    board.rig.plant.hold(math.radians(-5.0))
    watch = run(rig, board, clock, RigCommand(0.2), 1.5)
    assert watch.trip is not None and "the arm angle jumped 57 counts" in str(watch.trip)
    assert board.at_rest()


def test_a_coil_word_the_board_ignores_is_one_line_naming_the_word():
    rig, _board, clock, _ = make(faults=BoardFaults(ignored_words=(22,)))  # PWM 0 width
    rig.configure()
    rig.activate()
    with pytest.raises(DriverIOError, match=r"the board ignores word 22 \(the coil's output\): it reads back 0"):
        cycle(rig, clock, RigCommand(0.5), 10)
    rig.close()


def test_each_write_is_the_latest_read_with_only_sashils_words_changed():
    rig, board, clock, port = make({"rtdac.coil_output": "pwm", "rtdac.coil_channel": 1})
    board.words[board.map.pwm_prescaler_word(1)] = 0x1234  # INTECO's prescaler, as the board holds it
    rig.configure()
    rig.activate()
    cycle(rig, clock, RigCommand(0.5), 3)
    board.words[board.map.pwm_width_word(5)] = 777  # the board's own word changes between two reads
    board.words[board.map.encoder_index_active] = 0x0003
    cycle(rig, clock, RigCommand(0.5), 1)
    sent = decode_frame(port.sent[-1])
    assert sent[board.map.pwm_width_word(5)] == 777 and sent[board.map.encoder_index_active] == 0x0003
    assert sent[board.map.pwm_prescaler_word(1)] == 0x1234  # the prescaler stays unless the config sets one
    assert pwm_duty(sent[board.map.pwm_width_word(1)]) == pytest.approx(0.5, abs=0.02)
    rig.close()


def test_a_one_way_pwm_road_output_never_turns_a_brake_into_forward_drive():
    sets = {"rtdac.road_output": "pwm", "rtdac.road_channel": 2, "rtdac.road_output_limit": 1.0}
    rig, board, clock, _ = make(sets)
    rig.configure()
    rig.activate()
    cycle(rig, clock, RigCommand(0.0, 1.0), 200)
    assert board.output("pwm", 2) > 0.0
    widths = []
    for _ in range(200):  # a road speed far below the motor's: the loop asks to brake
        cycle(rig, clock, RigCommand(0.0, -3.0), 1)
        widths.append(board.words[board.map.pwm_width_word(2)])
    assert max(widths[5:]) == 0  # rest, not |brake| as forward drive
    assert not rig.capabilities.road_reverses
    rig.close()


def test_a_guessed_wiring_runs_under_its_caps_and_says_which_keys_are_guesses():
    rig, board, clock, _ = make({"rtdac.confirmed": list(COIL_KEYS)})
    rig.configure()
    rig.activate()
    cycle(rig, clock, RigCommand(1.0), 50)
    assert board.output("pwm", 0) == pytest.approx(1.0, abs=5e-3)  # the coil's keys confirmed: no cap
    facts = rig.link_stats()
    assert facts["guesses"] == [k for k in WIRING_KEYS if k not in COIL_KEYS]
    assert facts["caps"] == ["the road output at 2.5 V (rtdac.bringup_road_output)"]
    rig.close()
    rig, board, clock, _ = make(GUESSED)
    rig.configure()
    rig.activate()
    cycle(rig, clock, RigCommand(1.0), 50)
    assert board.output("pwm", 0) == pytest.approx(0.3, abs=1e-3)  # capped at 0.3 A: the map's duty for it
    assert rig.bringup.line() is not None and "coil_output" in rig.bringup.line()
    rig.close()


def test_the_heartbeat_keeps_the_relay_closed_through_a_run_and_it_opens_after_the_last_cycle():
    relay = Relay(bit=3, hold_ms=20.0)
    rig, board, clock, _ = make({"rtdac.heartbeat_bit": 3})
    board.relay = relay
    rig.configure()
    rig.activate()
    cycle(rig, clock, RigCommand(0.5), 1000)
    assert relay.closed(clock.now) and relay.drops == 0
    assert board.drive_a == pytest.approx(0.5, abs=0.02)  # powered
    last = relay.last_toggle_ns
    assert last is not None and clock.now - last < 2 * PERIOD_NS
    for _ in range(30):  # the host stops: no more frames; the board's time goes on
        clock.now += PERIOD_NS
        board.bulk_write(0x02, bytes((0xFF, 0x8F, 0, 0)), clock.now)
        board.bulk_read(0x84, 504, clock.now)
    assert not relay.closed(clock.now) and relay.opened_at_ns() == last + 20_000_000
    assert board.drive_a == 0.0 and board.road_target_rad_s == 0.0  # both stages unpowered
    rig.close()


def test_without_the_heartbeat_the_relay_never_closes_and_nothing_is_powered():
    rig, board, clock, _ = make()
    board.relay = Relay(bit=3)
    rig.configure()
    rig.activate()
    cycle(rig, clock, RigCommand(0.5, 1.0), 100)
    assert board.drive_a == 0.0 and board.rig.plant.state.current_a == pytest.approx(0.0, abs=1e-6)
    rig.close()


def test_bad_rtdac_keys_are_one_line_naming_the_key_and_exit_2(tmp_path, capsys):
    from sashil.cli import main

    cases = {
        "rtdac.confirmed=[coil_output, bogus]": "rtdac.confirmed: expected a list of names from 'coil_output'",
        "rtdac.heartbeat_bit=40": "rtdac.heartbeat_bit: expected a number >= 0 and <= 25 or null, got 40",
        "rtdac.bringup_road_output=1.5": "rtdac.bringup_road_output: expected a number >= 0 and <= 1, got 1.5",
    }
    for setting, text in cases.items():
        code = main(["run", "--driver", "rtdac", "--port", f"emulated:{tmp_path}/none.sock", "--set", setting,
                     "--duration", "1", "--out", str(tmp_path / "run")])  # fmt: skip
        err = capsys.readouterr().err.strip()
        assert code == 2 and text in err and "\n" not in err, err
        assert not (tmp_path / "run").exists()
    both = ["--set", "rtdac.road_output=pwm", "--set", "rtdac.road_channel=2", "--set", "rtdac.road_output_limit=1"]
    both += ["--set", "rtdac.road_direction_bit=4", "--set", "rtdac.heartbeat_bit=4"]
    code = main(["run", "--driver", "rtdac", "--port", f"emulated:{tmp_path}/none.sock", *both, "--duration", "1"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "rtdac.heartbeat_bit: the same digital output as road_direction_bit (4)" in err, err


def test_a_rightly_wired_coil_driven_hard_never_meets_its_authority():
    """Commands a law gives (steps between 0 A and the map's top, held for a while and for a cycle)
    on a bench whose sense and stage are as configured: the loop never passes its authority."""
    rig, _board, clock, _ = make()
    safety = SafetySupervisor(current_max_a=1.0)
    rig.configure()
    rig.activate()
    safety.start(clock.host)
    at_authority = 0
    for cycle_no in range(3000):
        current = 1.0 if (cycle_no // 37) % 2 else (0.0 if cycle_no % 5 else 0.6)
        clock.now += PERIOD_NS
        clock.host += PERIOD_NS
        sample = rig.read(clock.host, PERIOD_NS)
        safety.check(sample, clock.host)  # raises on a trip
        rig.write(safety.limit(RigCommand(current), PERIOD_NS), clock.host, PERIOD_NS)
        at_authority += rig.coil.at_authority
    assert at_authority == 0
    rig.close()
