"""``sashil doctor --walk`` against the emulated RT-DAC/USB2 in this process, on the board's clock.

The emulated bench is wired unlike the host's config (the config's guesses: the arm on counter 0,
the coil on PWM 0 with no sense, the road on D/A 0 with counter 1 at 4096 counts a revolution), and
an emulated operator (:class:`BenchOperator`) answers the walk's prompts and does what they ask on
the simulated rig. The host runs the real pyusb core and the rtdac backend; the walk's reads are
paced on the board's clock, so every figure is deterministic.
"""

from __future__ import annotations

import math

import pytest
import yaml

from sashil.cli import main
from sashil.config.frozen import freeze_config
from sashil.config.rtdac_section import COIL_KEYS, ROAD_KEYS, WIRING_KEYS
from sashil.diagnostics import OK, WARN
from sashil.diagnostics.rtdac import walk_checks
from sashil.diagnostics.rtdac_findings import (
    NotFound,
    PulseTrace,
    coil_map,
    find_arm,
    find_coil,
    find_road,
    output_caps,
    pulse_effect,
)
from sashil.diagnostics.rtdac_walk import PULSE_S, REST_S, SETTLE_S, Walk, WalkOptions
from sashil.drivers import rig_parts
from sashil.drivers.emulator.board_clock import BoardClock
from sashil.drivers.emulator.rtdac_board import REWIRED_BENCH, RtdacBoard, build_board
from sashil.drivers.emulator.rtdac_operator import BenchOperator
from sashil.drivers.emulator.rtdac_usb import DirectPort, EmulatedUsbBackend
from sashil.drivers.interface import RigCommand
from sashil.drivers.rtdac_rig import RtdacRig
from sashil.drivers.rtdac_wiring import Wiring
from sashil.engine.resolve import default_config, load_config

#: the bench's truth, unlike the config's guesses
BENCH = REWIRED_BENCH
#: the bench's power stage gives 0.8 of the current the config's map says (0.8 A at duty 1)
STAGE_GAIN = 0.8
#: one A/D count of the sense at the bench's 0.2 A/V (12 bits over +-10 V) [A]
AD_COUNT_A = 10.0 / 2048 * 0.2


def bench(bench_wiring: dict | None = None, board_sets: dict | None = None) -> tuple[RtdacRig, RtdacBoard, BoardClock]:
    """The host's rig on the default config, the emulated board wired as ``bench_wiring``."""
    clock = BoardClock()
    raw = default_config()
    for key, value in (board_sets or {}).items():
        section, name = key.split(".")
        raw[section][name] = value
    board = build_board(freeze_config(raw), stage_gain=STAGE_GAIN, wiring_changes=bench_wiring or BENCH)
    rig = RtdacRig.from_parts(rig_parts(freeze_config(default_config()), "rtdac"))
    rig.link.backend = EmulatedUsbBackend(DirectPort(board, clock))
    rig.configure()
    return rig, board, clock


def walk(tmp_path, choices: dict, bench_wiring: dict | None = None, **options):
    """The walk with the operator's ``choices``: its rows by name, the fragment (None: none
    written), the operator (its transcript) and the board."""
    rig, board, clock = bench(bench_wiring)
    operator = BenchOperator(board, clock.seconds, choices)
    path = tmp_path / "wiring.yaml"
    try:
        checks = walk_checks(
            rig, str(path), operator.ask, operator.say, WalkOptions(**options), clock.seconds, clock.sleep
        )
    finally:
        rig.close()
    fragment = yaml.safe_load(path.read_text()) if path.exists() else None
    return {c.name: c for c in checks}, fragment, operator, board


def test_the_walk_finds_a_bench_wired_unlike_the_config(tmp_path):
    """Every key of the bench's truth found and confirmed: the coil on PWM 3 (the config guesses PWM 0:
    a walk that pulsed the guessed channel would find no sense there), the road on D/A 1 with its
    encoder (counter 5) reversed at 2000 counts a revolution, the arm on counter 4 counting down."""
    rows, fragment, operator, board = walk(tmp_path, {"scale": "0.2", "revolution": "m"})
    found = fragment["rtdac"]
    assert fragment["driver"] == {"name": "rtdac"}
    assert (found["arm_encoder"], found["arm_reversed"]) == (4, True)
    # 5 deg of travel is 57 counts at 4096 a revolution: one count in 57
    assert abs(found["arm_counts_per_rev"] - 4096) <= 4096 / 56
    assert (found["coil_output"], found["coil_channel"], found["coil_sense_ad"]) == ("pwm", 3, 6)
    assert (found["road_output"], found["road_channel"], found["road_encoder"]) == ("da", 1, 5)
    assert found["road_reversed"] is True and found["road_counts_per_rev"] == 2000
    # the power stage's true map: 0.8 A per unit duty, measured in duty steps of 0.1 to the 0.3 A cap
    assert found["coil_map_output"] == [0.0, 0.1, 0.2, 0.3]
    for current, duty in zip(found["coil_map_current_a"], found["coil_map_output"], strict=True):
        assert current == pytest.approx(STAGE_GAIN * duty, abs=AD_COUNT_A)
    assert found["coil_sense_a_per_v"] == 0.2 and found["coil_sense_offset_v"] == 0.0
    # the emulated motor: 2 rad/s per V (the config's 0.5 V per rad/s), a 20 ms lag
    assert found["road_output_per_rad_s"] == pytest.approx(0.5, rel=0.02)
    assert found["road_lag_s"] == pytest.approx(0.02, abs=0.003)  # the emulated motor steps its speed each read
    assert found["confirmed"] == list(WIRING_KEYS)
    assert rows["fragment"].status == OK and "14 of 14 wiring keys confirmed" in rows["fragment"].found
    assert rows["outputs at rest"].status == OK and board.at_rest()
    text = "\n".join(operator.transcript)
    assert "PWM 0: nothing moved" in text and "PWM 3: A/D 6 +0.4" in text and "D/A 1: counter 5 -" in text


def test_the_fragment_is_a_config_that_drives_the_bench_it_was_found_on(tmp_path):
    """The fragment loads as a config (the section's check: the coil's map rising from 0 A, distinct
    channels) and a host on it drives the true coil and road: 0.2 A commanded is 0.2 A in the coil
    (the map has the stage's 0.8), and the road's loop on its reversed encoder tracks."""
    walk(tmp_path, {"scale": "0.2", "revolution": "m"})
    config = load_config(tmp_path / "wiring.yaml")
    clock = BoardClock()
    board = build_board(freeze_config(default_config()), stage_gain=STAGE_GAIN, wiring_changes=BENCH)
    rig = RtdacRig.from_parts(rig_parts(config, "rtdac"))
    rig.link.backend = EmulatedUsbBackend(DirectPort(board, clock))
    rig.configure()
    rig.activate()
    host = 0
    sample = None
    for _ in range(1500):
        clock.now += 1_000_000
        host += 1_000_000
        sample = rig.read(host, 1_000_000)
        rig.write(RigCommand(0.2, 1.0), host, 1_000_000)
    true_a, road_rad = board.rig.plant.state.current_a, board.rig.plant.state.theta_road_rad
    rig.close()
    assert sample is not None and sample.current_a == pytest.approx(0.2, abs=2 * AD_COUNT_A)
    assert true_a == pytest.approx(0.2, abs=2 * AD_COUNT_A)
    assert road_rad == pytest.approx(1.5, abs=0.02)  # 1 rad/s for 1.5 s
    assert board.at_rest()


def test_the_coil_map_declined_and_the_revolution_skipped_leave_their_keys_unconfirmed(tmp_path):
    rows, fragment, operator, board = walk(tmp_path, {"scale": "0.2", "revolution": "s", "coil": "n"})
    found = fragment["rtdac"]
    left = {"coil_map_current_a", "coil_map_output", "coil_sense_a_per_v", "road_counts_per_rev"}
    assert found["confirmed"] == [key for key in WIRING_KEYS if key not in left]
    assert not left & found.keys() and "road_output_per_rad_s" not in found
    assert (found["coil_channel"], found["road_channel"], found["road_encoder"]) == (3, 1, 5)
    assert rows["fragment"].status == WARN and "coil_map_current_a" in rows["fragment"].found
    assert rows["coil map"].status == WARN and rows["revolution"].status == WARN
    assert "drive PWM 3 at 0, 0.1, 0.2, 0.3 duty" in "\n".join(operator.transcript)
    assert board.at_rest()


def test_declining_the_pulses_confirms_only_the_arm_and_drives_nothing(tmp_path):
    """The hand's revolution still counts the road wheel's revolution (the counter, not the arm's, that
    moved most); nothing else but the arm is confirmed, and no output was driven."""
    rows, fragment, operator, board = walk(tmp_path, {"outputs": "n", "revolution": "h"})
    found = fragment["rtdac"]
    assert found["confirmed"] == ["road_counts_per_rev", "arm_encoder", "arm_counts_per_rev", "arm_reversed"]
    assert found["road_counts_per_rev"] == 2000 and "road_encoder" not in found
    assert "PWM 0:" not in "\n".join(operator.transcript) and board.exchanges > 0
    assert "needs the coil and its sense (step 2): skipped" in rows["coil map"].found


def test_a_skipped_arm_step_leaves_the_road_unconfirmed_the_arm_following_it(tmp_path):
    """With no arm step the arm's counter, which follows the road wheel, cannot be told from the road's."""
    rows, fragment, _, _ = walk(tmp_path, {"arm": "s", "scale": "0.2", "revolution": "s"})
    confirmed = fragment["rtdac"]["confirmed"]
    assert not set(ROAD_KEYS) & set(confirmed) and "arm_encoder" not in confirmed
    assert {"coil_output", "coil_channel", "coil_sense_ad", "coil_map_output"} <= set(confirmed)
    assert "arm step was skipped" in rows["road"].found


def test_a_meter_reading_and_a_hand_revolution(tmp_path):
    """The scale from a clamp meter at the first step (the coil's true current), the revolution turned
    by hand: the same wiring, the road motor's gain from the scan's pulse."""
    _, fragment, operator, _ = walk(tmp_path, {"scale": "m", "revolution": "h"})
    found = fragment["rtdac"]
    assert found["confirmed"] == list(WIRING_KEYS)
    assert found["coil_sense_a_per_v"] == pytest.approx(0.2, rel=0.02)  # a meter's 4 digits at 0.08 A
    assert found["road_counts_per_rev"] == 2000
    assert found["road_output_per_rad_s"] == pytest.approx(0.5, rel=0.05)  # a 0.3 s pulse's tail
    assert "type the current your meter reads in A (s: skip): 0.08" in "\n".join(operator.transcript)


def test_a_coil_with_no_sense_is_not_found_and_the_road_is(tmp_path):
    rows, fragment, _, board = walk(tmp_path, {"revolution": "s"}, {**BENCH, "coil_sense_ad": None})
    confirmed = fragment["rtdac"]["confirmed"]
    assert not set(COIL_KEYS) & set(confirmed) and "coil_sense_ad" not in confirmed
    assert {"road_output", "road_channel", "road_encoder", "road_reversed"} <= set(confirmed)
    assert rows["coil"].status == WARN and "no coil with a current sense found" in rows["coil"].found
    assert board.at_rest()


def test_a_pulse_that_turns_the_road_too_far_ends_at_once_at_rest(tmp_path):
    """A road motor 100 times the config's speed per volt: its pulse passes the guard (the arm or the
    road 45 deg) long before 0.3 s and ends at rest; the motor and its encoder are still named."""
    rig, board, clock = bench()
    board.motor = type(board.motor)(rad_s_per_output=200.0, tau_s=0.02)
    operator = BenchOperator(board, clock.seconds, {"revolution": "s", "coil": "n", "scale": "0.2"})
    record = Walk(rig, operator.ask, operator.say, WalkOptions(), clock.seconds, clock.sleep)
    try:
        record.run()
    finally:
        rig.close()
    road = next(e for e in record.effects if e.name == "D/A 1")
    assert road.stopped and road.counter == 5 and road.counts < 0
    assert record.found["road_channel"] == 1 and board.at_rest()
    assert "(ended early: " in "\n".join(operator.transcript)


def test_the_walk_stays_under_the_bring_up_caps():
    caps = output_caps(Wiring())
    assert caps == {"pwm": pytest.approx(0.3), "da": pytest.approx(2.5)}  # 0.3 A on the map; 0.25 of 10 V
    lower = output_caps(Wiring(bringup_current_max_a=0.05, bringup_road_output=0.01))
    assert lower == {"pwm": pytest.approx(0.05), "da": pytest.approx(0.1)}


def test_a_low_cap_shrinks_the_pulses(tmp_path):
    rig, board, clock = bench()
    rig.wiring = Wiring.from_part(
        rig_parts(freeze_config(default_config()), "rtdac").rtdac,
        bringup_current_max_a=0.05,
        bringup_road_output=0.01,
    )
    operator = BenchOperator(board, clock.seconds, {"revolution": "s", "coil": "n", "scale": "0.2"})
    record = Walk(rig, operator.ask, operator.say, WalkOptions(), clock.seconds, clock.sleep)
    try:
        record.run()
    finally:
        rig.close()
    assert {e.level for e in record.effects} == {0.05, 0.1}
    assert record.found["coil_channel"] == 3 and record.found["road_channel"] == 1


# the findings, from readings ------------------------------------------------------------------
def test_find_arm_from_the_marker_and_the_rest():
    arm = find_arm([0, 100, 0], [0, 100 - 57, 1], -5.0)
    assert (arm.encoder, arm.counts_per_rev, arm.reversed, arm.counts) == (1, round(57 / 5 * 360), True, -57)
    with pytest.raises(NotFound, match="more than one counter moved"):
        find_arm([0, 0], [57, 30], -5.0)
    with pytest.raises(NotFound, match="no counter moved"):
        find_arm([0, 0], [2, 1], -5.0)


def trace(ads_rest: float, ads_pulse: float, counts: list[int]) -> PulseTrace:
    n = len(counts)
    return PulseTrace(
        "pwm", 2, 0.1, [[ads_rest, 0.0]] * 10, [0, 0], [0.002 * (k + 1) for k in range(n)],
        [[0, c] for c in counts], [[ads_pulse, 0.0]] * n,
    )  # fmt: skip


def test_pulse_effects_and_what_they_name():
    coil = pulse_effect(trace(0.0, 0.4, [0] * 20), arm_encoder=0)
    assert (coil.ad, coil.counter) == (0, None) and coil.ad_rise_v == pytest.approx(0.4)
    quiet = pulse_effect(trace(0.0, 0.04, [0] * 10 + [3] * 10), arm_encoder=0)
    assert (quiet.ad, quiet.counter) == (None, None)  # under 50 mV and 8 counts
    road = pulse_effect(trace(0.0, 0.0, list(range(0, -40, -2))), arm_encoder=0)
    assert (road.counter, road.counts) == (1, -38)
    shaking = pulse_effect(trace(0.0, 0.0, [0, 20, -20, 20, -20, 20, -20, 20, -20, 20]), arm_encoder=0)
    assert shaking.counter is None  # moved, but not steadily
    assert find_coil([coil, quiet, road]).channel == 2
    assert find_road([coil, quiet, road], arm_known=True).reversed is True
    with pytest.raises(NotFound, match="more than one output raised an A/D"):
        find_coil([coil, coil])


def test_coil_map_drops_a_step_whose_current_does_not_rise():
    found = coil_map([0.0, 0.1, 0.2, 0.3], [0.01, 0.012, 0.51, 1.01], 0.2)
    assert found.currents_a == (0.0, 0.1, 0.2) and found.outputs == (0.0, 0.2, 0.3)
    assert found.dropped == (0.1,) and found.offset_v == 0.01
    with pytest.raises(NotFound, match="did not rise"):
        coil_map([0.0, 0.1], [0.0, -0.5], 0.2)


# the command line -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--walk", "--driver", "rtdac", "--arm-deg", "0"], "--arm-deg"),
        (["--walk", "--driver", "rtdac", "--sense-a-per-v", "-1"], "--sense-a-per-v"),
        (["--sense-a-per-v", "0.2"], "--sense-a-per-v"),
        (["--arm-deg", "-10"], "--arm-deg"),
    ],
)
def test_doctor_walk_bad_options(args, named, capsys):
    assert main(["doctor", "--jitter-s", "0", *args]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and named in err


def test_the_walk_is_paced_on_the_clock_it_is_given():
    """A pulse lasts PULSE_S of the board's clock (the walk's reads paced by it), not of the wall's."""
    rig, board, clock = bench()
    operator = BenchOperator(board, clock.seconds, {"outputs": "n", "arm": "s", "revolution": "s"})
    record = Walk(rig, operator.ask, operator.say, WalkOptions(), clock.seconds, clock.sleep)
    try:
        record.rest()
        start = clock.seconds()
        pulse = record._pulse("pwm", 3, 0.1)
    finally:
        rig.close()
    assert pulse.times[-1] == pytest.approx(PULSE_S, abs=0.003) and not pulse.stopped
    # the counters' stillness (SETTLE_S), the A/Ds at rest (REST_S), the pulse, the rest after it (REST_S)
    assert clock.seconds() - start == pytest.approx(SETTLE_S + REST_S + PULSE_S + REST_S, abs=0.01)
    assert math.isclose(max(row[6] for row in pulse.ads), 0.08 / 0.2, abs_tol=0.01)
