"""The rtdac backend's coil and road outputs and its bring-up caps: pure math against hand-derived values.

The values are chosen exact in binary (a map from 0..1 A to a duty 0..1, ki·dt = 1/8) so that each
bound is met exactly where a test says: these tests are the mutation tests' judges of
``drivers/rtdac_outputs.py`` and ``drivers/rtdac_bringup.py`` (tools/mutate_safety.py).
"""

from __future__ import annotations

import math

import pytest

from sashil.config.rtdac_section import COIL_KEYS, ROAD_KEYS, WIRING_KEYS
from sashil.drivers.rtdac_bringup import BringUp
from sashil.drivers.rtdac_outputs import CoilDrive, RoadDrive, interp
from sashil.drivers.rtdac_wiring import Wiring

DT = 0.0078125  # 2**-7 s: ki 16/s times it is 1/8


def coil(tau_s: float = 0.0) -> CoilDrive:
    return CoilDrive((0.0, 1.0), (0.0, 1.0), 16.0, 0.25, tau_s)


def test_the_map_alone_without_a_sense_and_rest_at_or_below_0_a():
    drive = coil()
    assert drive.output(0.5, None, DT) == 0.5
    assert drive.output(0.5, math.nan, DT) == 0.5
    for current in (0.0, -0.1, math.nan):
        assert drive.output(current, 0.7, DT) == 0.0 and not drive.at_authority


def test_the_loop_corrects_by_the_sensed_error_and_stops_exactly_at_its_authority():
    drive = coil()
    assert drive.output(0.5, 0.0, DT) == 0.5625  # step 16 * 0.5 / 128 = 1/16
    assert not drive.at_authority
    assert drive.output(0.5, 0.5, DT) == 0.5625  # no error: the correction stays
    assert not drive.at_authority
    assert drive.output(0.5, 0.375, DT) == 0.578125  # step 1/64
    drive.reset()
    assert drive.output(0.5, -0.5, DT) == 0.625  # step 1/8: exactly the authority (0.25 x 0.5 A), not past it
    assert not drive.at_authority
    assert drive.output(0.5, -1.5, DT) == 0.625  # a further push: held at the bound, and it says so
    assert drive.at_authority
    assert drive.output(0.5, 0.5, DT) == 0.625  # no error: the correction held at the bound stays
    assert not drive.at_authority


def test_the_bound_below_holds_a_sense_that_reads_too_much():
    drive = coil()
    assert drive.output(0.5, 1.5, DT) == 0.375  # step -1/8: exactly 0.75 x the map's
    assert not drive.at_authority
    assert drive.output(0.5, 1.5, DT) == 0.375
    assert drive.at_authority
    assert drive.output(0.5, 0.375, DT) == 0.390625  # step +1/64 from the bound
    assert not drive.at_authority


def test_the_maps_end_holds_the_output_and_the_correction_still_meets_its_authority():
    drive = coil()
    for _ in range(2):  # corrections of 1/8 and 1/4: the map holds its last output
        assert drive.output(1.0, 0.0, DT) == 1.0
        assert not drive.at_authority
    assert drive.output(1.0, 0.0, DT) == 1.0  # 3/8 asked, 1/4 allowed
    assert drive.at_authority
    drive.reset()
    assert drive.output(0.5, 0.4375, DT) == 0.5078125  # a correction of 1/128 kept
    assert drive.output(0.02, 0.02, DT) == pytest.approx(0.025)  # 1/128 passes 0.25 x 0.02 A: held at it
    assert drive.at_authority


def test_rest_forgets_the_correction():
    drive = coil()
    drive.output(0.5, 0.0, DT)
    drive.output(0.0, 0.0, DT)
    assert drive.output(0.5, 0.5, DT) == 0.5


def test_the_loop_compares_the_sense_with_the_command_through_the_coils_lag():
    drive = coil(tau_s=0.01)
    expected = 0.5 * (1.0 - math.exp(-DT / 0.01))  # the coil's current a step of 0.5 A gives after DT
    assert drive.output(0.5, expected, DT) == pytest.approx(0.5, abs=1e-12)  # agrees: no correction
    instant = coil(tau_s=0.0)  # no lag: the command itself
    assert instant.output(0.5, 0.5, DT) == 0.5


def test_interp_holds_the_ends_and_is_linear_between():
    assert interp(-1.0, (0.0, 1.0), (0.0, 2.0)) == 0.0
    assert interp(0.25, (0.0, 1.0), (0.0, 2.0)) == 0.5
    assert interp(3.0, (0.0, 1.0), (0.0, 2.0)) == 2.0


def road(reverses: bool = True) -> RoadDrive:
    return RoadDrive(0.5, 8.0, 1.0, 0.0, 0.0, reverses=reverses)


def test_the_road_rests_until_a_speed_is_commanded_and_reports_no_error():
    drive = road()
    assert drive.output(0.3, DT) == 0.0 and math.isnan(drive.error_rad) and not drive.at_limit


def test_the_road_output_is_its_feed_forward_plus_its_gain_on_the_error():
    drive = road()
    drive.command(1.0)
    assert drive.output(0.0, DT) == 0.5  # the reference starts where the road is: no error
    assert drive.error_rad == 0.0
    assert drive.output(0.0, DT) == 0.5 + 8.0 * DT  # the reference moved 1 rad/s for DT
    assert drive.error_rad == DT and not drive.at_limit


def test_the_road_output_held_at_its_limit_says_so():
    drive = road()
    drive.command(1.0)
    drive.output(0.0, DT)
    assert drive.output(-0.0625, DT) == 1.0  # 0.5 + 8 * (1/128 + 1/16) = 1.0625: held at 1
    assert drive.at_limit and drive.limit_cycles == 1
    drive.command(2.0)  # the lead of the lag: none here (lag 0)
    drive.stop()
    assert drive.output(0.0, DT) == 0.0 and not drive.at_limit


def test_a_one_way_output_gives_rest_for_a_brake_never_forward_drive():
    drive = road(reverses=False)
    drive.command(-1.0)
    assert drive.output(0.0, DT) == 0.0 and drive.at_limit  # -0.5 asked: a brake it cannot give
    both = road(reverses=True)
    both.command(-1.0)
    assert both.output(0.0, DT) == -0.5 and not both.at_limit


def test_the_feed_forward_leads_a_speed_change_by_the_motors_lag():
    drive = RoadDrive(0.5, 0.0, 10.0, 0.0, 0.02)
    drive.command(1.0)
    assert drive.output(0.0, DT) == 0.5
    drive.command(2.0)
    assert drive.output(0.0, DT) == pytest.approx((2.0 + 0.02 * 1.0 / DT) * 0.5)
    drive.command(3.0)
    assert drive.output(0.0, 0.0) == 1.5  # no time passed: no rate of change to lead by


def test_bring_up_caps_each_group_until_all_its_keys_are_confirmed():
    guessed = BringUp.of(Wiring(), 1.0)
    assert guessed.guesses == WIRING_KEYS and guessed.coil_capped and guessed.road_capped
    assert guessed.current_max_a == 0.3 and guessed.road_output_limit == 2.5 and guessed.road_unit == "V"
    coil_only = BringUp.of(Wiring(confirmed=COIL_KEYS), 1.0)
    assert not coil_only.coil_capped and coil_only.current_max_a == 1.0 and coil_only.road_capped
    almost = BringUp.of(Wiring(confirmed=COIL_KEYS[:-1] + ROAD_KEYS), 0.2)
    assert almost.coil_capped and almost.current_max_a == 0.2 and not almost.road_capped  # i_max below the cap
    assert almost.road_output_limit == 10.0
    everything = BringUp.of(Wiring(confirmed=WIRING_KEYS), 1.0)
    assert everything.guesses == () and everything.line() is None and everything.caps() == []
    pwm = BringUp.of(Wiring(road_output="pwm", road_output_limit=1.0), 1.0)
    assert pwm.road_unit == "duty" and "duty 0.25" in pwm.caps()[1]
    no_road = BringUp.of(Wiring(road_output="none"), 1.0)
    assert not no_road.road_capped and no_road.caps() == ["the coil at 0.3 A (rtdac.bringup_current_max_a)"]
    assert "coil_output" in guessed.line() and "until then the coil at 0.3 A" in guessed.line()
