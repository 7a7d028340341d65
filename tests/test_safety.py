"""The safety supervisor: clamp, slew limit, angle interlock, sensor timeout by sequence number."""

from __future__ import annotations

import math

import pytest

from sashil.config.parts import SafetyParts
from sashil.drivers.interface import FLAG_FAULT, FLAG_HELD, FLAG_OVERCURRENT, FLAG_STUCK_SENSOR, RigCommand, RigSample
from sashil.errors import SafetyTrip
from sashil.safety import SafetySupervisor

COUNTS = 3600  # 0.1 deg per count


def sample(seq, theta_deg=0.0, flags=0):
    return RigSample(seq, 0, 0, round(theta_deg * 10), 0, 0.0, flags, COUNTS)


def supervisor(**kw):
    """A supervisor whose encoder-step check lets these tests' angles jump (its own tests below set it)."""
    kw.setdefault("max_angle_rate_rad_s", math.inf)
    s = SafetySupervisor(current_max_a=1.0, angle_limit_rad=math.radians(30.0), **kw)
    s.start(1_000_000_000)
    return s


def test_current_is_clamped_to_the_range_and_nan_is_zero():
    s = supervisor()
    assert s.limit(RigCommand(1.7), 1_000_000).current_a == 1.0
    assert s.limit(RigCommand(-0.2), 1_000_000).current_a == 0.0
    assert s.limit(RigCommand(float("nan")), 1_000_000).current_a == 0.0
    assert s.limit(RigCommand(0.4, 2.0), 1_000_000).current_a == 0.4
    assert s.limit(RigCommand(0.4, 2.0), 1_000_000).road_speed_rad_s == 2.0
    assert s.clamped_cycles == 3 and s.trips == []


def test_slew_limit_over_the_measured_period():
    s = supervisor(slew_a_per_s=100.0)  # 0.1 A per 1 ms cycle
    got = [s.limit(RigCommand(1.0), 1_000_000).current_a for _ in range(4)]
    assert got == pytest.approx([0.1, 0.2, 0.3, 0.4])
    assert s.limit(RigCommand(1.0), 3_000_000).current_a == pytest.approx(0.7)  # a 3 ms period
    assert s.limit(RigCommand(0.0), 1_000_000).current_a == pytest.approx(0.6)  # down as well
    s.safe_state()  # the shutdown wrote 0 A: a restart slews up from 0
    assert s.limit(RigCommand(1.0), 1_000_000).current_a == pytest.approx(0.1)
    assert s.slew_limited_cycles == 7


def test_angle_interlock_both_ways_with_time_and_reason():
    s = supervisor()
    s.check(sample(1, 29.9), 1_000_000_000)
    s.check(sample(2, -29.9), 1_001_000_000)
    with pytest.raises(SafetyTrip, match=r"\|theta\| = 30.10 deg beyond the limit 30 deg"):
        s.check(sample(3, -30.1), 1_250_000_000)
    (trip,) = s.trips
    assert trip.kind == "angle_interlock" and trip.code == 1
    assert trip.time_s == pytest.approx(0.25)
    assert s.trip_code == 1


def test_interlock_off():
    s = SafetySupervisor(current_max_a=1.0, angle_limit_rad=None)
    s.check(sample(1, 80.0), 0)
    s.check(sample(2, 80.0), 1_000_000)
    assert s.trips == []


def test_repeated_sequence_numbers_trip_after_n_cycles():
    s = supervisor(sensor_timeout_cycles=3)
    s.check(sample(10), 0)
    s.check(sample(10), 1)
    s.check(sample(10), 2)
    assert s.stale_samples == 2
    s.check(sample(11), 3)  # fresh again: the count restarts
    s.check(sample(11), 4)
    s.check(sample(9), 5)  # backwards: stale as well
    with pytest.raises(SafetyTrip, match="no fresh sample for 3 cycles"):
        s.check(sample(11), 6)
    assert s.trips[0].kind == "sensor_timeout" and s.trips[0].code == 2


def test_missing_samples_count_towards_the_timeout():
    s = supervisor(sensor_timeout_cycles=2)
    s.check(None, 0)
    with pytest.raises(SafetyTrip, match="no sample"):
        s.check(None, 1)


def test_sequence_wrap_at_16_bits_is_fresh():
    s = supervisor(sensor_timeout_cycles=1)
    s.check(sample(65534), 0)
    s.check(sample(65535), 1)
    s.check(sample(0), 2)
    s.check(sample(1), 3)
    assert s.stale_samples == 0


def test_device_fault_flags_trip_but_held_does_not():
    s = supervisor()
    s.check(sample(1, flags=FLAG_HELD), 0)
    with pytest.raises(SafetyTrip, match="overcurrent"):
        s.check(sample(2, flags=FLAG_OVERCURRENT), 1)
    quiet = SafetySupervisor(1.0, trip_on_device_fault=False)
    quiet.check(sample(1, flags=FLAG_FAULT), 0)
    assert quiet.trips == []


def test_a_stuck_sensor_trips_the_supervisor():
    s = supervisor()
    with pytest.raises(SafetyTrip, match="stuck sensor"):
        s.check(sample(1, flags=FLAG_STUCK_SENSOR | FLAG_HELD), 0)
    assert s.trips[0].kind == "device_fault"


def test_the_supervisor_takes_the_configs_limits(config):
    config["safety"]["slew_a_per_s"] = 50.0
    s = SafetySupervisor.from_parts(SafetyParts.read(config))
    assert s.angle_limit_rad == pytest.approx(math.radians(30.0))
    assert s.slew_a_per_s == 50.0 and s.sensor_timeout_cycles == 20
    config["safety"]["angle_interlock"] = False
    assert SafetySupervisor.from_parts(SafetyParts.read(config)).angle_limit_rad is None


# boundaries (each kills a mutant of tools/mutate_safety.py) ---------------------------------------
def test_the_angle_limit_itself_is_inside():
    edge = sample(1, 30.0).theta_rad
    s = SafetySupervisor(current_max_a=1.0, angle_limit_rad=edge, max_angle_rate_rad_s=math.inf)
    s.check(sample(1, 30.0), 0)
    s.check(sample(2, -30.0), 1)
    assert s.trips == []


def test_a_jump_of_half_the_sequence_counter_is_stale_just_under_it_is_fresh():
    s = supervisor(sensor_timeout_cycles=5)
    s.check(sample(100), 0)
    s.check(sample(100 + 32767), 1)  # ahead by 2**15 - 1: fresh
    assert s.stale_samples == 0
    s.check(sample((100 + 32767 + 32768) % 65536), 2)  # ahead by exactly 2**15: ambiguous, stale
    assert s.stale_samples == 1


def test_a_change_of_exactly_one_slew_step_is_not_limited():
    s = supervisor(slew_a_per_s=100.0)
    step = 100.0 * 1_000_000 * 1e-9  # what limit() allows over a 1 ms period
    assert s.limit(RigCommand(step), 1_000_000).current_a == step
    assert s.limit(RigCommand(0.0), 1_000_000).current_a == 0.0
    assert s.slew_limited_cycles == 0


def test_summary_reports_the_limits():
    summary = supervisor(slew_a_per_s=5.0).summary()
    assert summary["angle_limit_deg"] == pytest.approx(30.0) and summary["slew_a_per_s"] == 5.0
    assert SafetySupervisor(current_max_a=1.0).summary()["angle_limit_deg"] is None


# encoder steps, the arm's travel, and the host-closed loops ------------------------------------
MS = 1_000_000
T0 = 1_000_000_000


def counted(seq, arm=0, road=0, **facts):
    return RigSample(seq, 0, 0, arm, road, 0.0, 0, COUNTS, **facts)


def stepper():
    """10 rev/s at 3600 counts a revolution: 36 counts a millisecond, 37 with the one count's grace."""
    s = SafetySupervisor(current_max_a=1.0, max_angle_rate_rad_s=10 * 2 * math.pi)
    s.start(T0)
    return s


@pytest.mark.parametrize("which", ["arm", "road"])
def test_an_encoder_step_faster_than_the_rig_can_turn_trips_naming_the_encoder(which):
    s = stepper()
    s.check(counted(1), T0)
    s.check(counted(2, **{which: 37}), T0 + MS)  # exactly the allowed step
    s.check(counted(3, **{which: 0}), T0 + 2 * MS)  # back, as fast
    s.check(counted(4, **{which: -73}), T0 + 4 * MS)  # two periods: twice the step, one grace
    with pytest.raises(SafetyTrip, match=rf"the {which} angle jumped 38 counts in 1.0 ms, more than 37"):
        s.check(counted(5, **{which: -35}), T0 + 5 * MS)
    assert s.trips[-1].kind == "encoder_step" and s.trip_code == 4


def test_the_first_sample_after_a_start_is_no_step():
    s = stepper()
    s.check(counted(1, arm=5000, road=-5000), T0)  # an index reset's value before the run: no step yet
    s.start(T0 + MS)
    s.check(counted(2, arm=0, road=0), T0 + 2 * MS)
    assert s.trips == []


def test_the_arm_beyond_its_travel_trips_both_ways_and_its_edge_is_inside():
    edge = counted(1, arm=100).arm_counts * 2 * math.pi / COUNTS  # 10 deg as the supervisor computes it
    s = SafetySupervisor(current_max_a=1.0, arm_travel_rad=edge, max_angle_rate_rad_s=math.inf)
    s.start(T0)
    s.check(counted(1, arm=100), T0)
    s.check(counted(2, arm=-100), T0 + MS)
    with pytest.raises(SafetyTrip, match=r"\|theta2\| = 10.10 deg beyond 10 deg \(safety.arm_travel_deg\)"):
        s.check(counted(3, arm=-101), T0 + 2 * MS)
    s = SafetySupervisor(current_max_a=1.0, arm_travel_rad=edge, max_angle_rate_rad_s=math.inf)
    with pytest.raises(SafetyTrip, match="arm travel"):
        s.check(counted(1, arm=101), T0)
    assert s.trips[-1].kind == "arm_travel" and s.trip_code == 5
    s = SafetySupervisor(current_max_a=1.0, max_angle_rate_rad_s=math.inf)  # no travel: off
    s.check(counted(1, arm=3000), T0)
    assert s.trips == []


@pytest.mark.parametrize(
    ("kind", "code", "beyond", "within", "text"),
    [
        ("road_tracking", 6, {"road_error_rad": -0.0201}, {"road_error_rad": 0.02}, "the road is 0.020 rad off"),
        ("road_limit", 7, {"road_at_limit": True}, {"road_at_limit": False}, "output held at its limit for 50 ms"),
        ("coil_sense", 8, {"coil_at_authority": True}, {"coil_at_authority": False}, "sensed current disagrees"),
    ],
)
def test_a_loop_held_beyond_its_bound_trips_only_after_its_time(kind, code, beyond, within, text):
    bound = {"road_tracking": 5, "road_limit": 50, "coil_sense": 50}[kind]
    s = SafetySupervisor(current_max_a=1.0)
    s.start(T0)
    # a sample a millisecond: within for 100 ms, beyond from 100 ms, a break at 100 + bound, beyond again
    facts = {ms: within for ms in range(100)}
    facts.update({ms: beyond for ms in range(100, 100 + bound)})
    facts[100 + bound] = within
    facts.update({ms: beyond for ms in range(101 + bound, 101 + 2 * bound)})
    for ms, fact in facts.items():
        s.check(counted(ms + 1, **fact), T0 + ms * MS)
    assert s.trips == []
    with pytest.raises(SafetyTrip, match=text):
        s.check(counted(999, **beyond), T0 + (101 + 2 * bound) * MS)  # exactly its time since 101 + bound
    assert s.trips[-1].kind == kind and s.trip_code == code
    assert s.trips[-1].time_s == pytest.approx((101 + 2 * bound) * 1e-3)


@pytest.mark.parametrize("kind", ["road_tracking", "road_limit"])
def test_after_a_host_pause_the_road_is_given_its_grace_to_catch_up(kind):
    beyond = {"road_tracking": {"road_error_rad": 0.5}, "road_limit": {"road_at_limit": True}}[kind]
    bound = {"road_tracking": 5, "road_limit": 50}[kind]
    s = SafetySupervisor(current_max_a=1.0, road_grace_ms=150.0)
    s.start(T0)
    for ms in range(10):
        s.check(counted(ms + 1), T0 + ms * MS)
    s.check(counted(11, **beyond), T0 + 13 * MS)  # four periods after the last: a pause
    t = 13
    while t < 13 + 150 + bound - 1:  # the grace, then the bound from its end
        t += 1
        s.check(counted(t, **beyond), T0 + t * MS)
    assert s.trips == []
    with pytest.raises(SafetyTrip):
        s.check(counted(t + 1, **beyond), T0 + (t + 1) * MS)
    assert s.trips[-1].time_s == pytest.approx((13 + 150 + bound) * 1e-3)


def test_a_gap_of_three_periods_is_no_pause_and_the_coil_is_never_excused():
    s = SafetySupervisor(current_max_a=1.0)
    s.start(T0)
    s.check(counted(1), T0)
    s.check(counted(2), T0 + MS)
    for ms in range(4, 9):  # three periods after the last, then on time: judged all along
        s.check(counted(ms, road_error_rad=0.5), T0 + ms * MS)
    with pytest.raises(SafetyTrip, match=r"the road is 0\.500 rad off"):
        s.check(counted(99, road_error_rad=0.5), T0 + 9 * MS)
    s = SafetySupervisor(current_max_a=1.0)
    s.start(T0)
    s.check(counted(1), T0)
    s.check(counted(2), T0 + MS)
    for ms in range(10, 60):  # a pause excuses the road only
        s.check(counted(ms, coil_at_authority=True), T0 + ms * MS)
    with pytest.raises(SafetyTrip, match="sensed current disagrees"):
        s.check(counted(99, coil_at_authority=True), T0 + 60 * MS)


def test_no_host_road_loop_is_never_off_its_reference():
    s = SafetySupervisor(current_max_a=1.0)
    s.start(T0)
    for seq in range(1, 200):
        s.check(counted(seq), T0 + seq * MS)  # road_error_rad NaN by default
    assert s.trips == []


def test_the_bounds_come_from_the_config_parts():
    parts = SafetyParts(1.0, None, 0.0, 20, True, 30.0, 12.0, 0.02, 5.0, 7.0, 9.0, 11.0)
    s = SafetySupervisor.from_parts(parts)
    assert s.road_grace_ns == 11 * MS
    assert s.max_angle_rate_rad_s == 30.0 and s.arm_travel_rad == pytest.approx(math.radians(12.0))
    assert (s.road_error_max_rad, s.road_error_ns, s.road_limit_ns, s.coil_authority_ns) == (
        0.02,
        5 * MS,
        7 * MS,
        9 * MS,
    )
    assert SafetySupervisor.from_parts(SafetyParts(1.0, None, 0.0, 20, True)).arm_travel_rad is None


def test_samples_a_link_hands_over_in_a_burst_are_judged_on_the_devices_clock():
    """Two samples the device took 1 ms apart, read 0.2 ms apart on the host: the step a millisecond
    allows (36 counts and the one count's grace), not a fifth of it."""
    s = stepper()
    s.check(RigSample(1, 0, 1_000, 0, 0, 0.0, 0, COUNTS), T0)
    s.check(RigSample(2, 0, 2_000, 37, 0, 0.0, 0, COUNTS), T0 + MS // 5)
    with pytest.raises(SafetyTrip, match=r"the arm angle jumped 38 counts in 1\.0 ms, more than 37"):
        s.check(RigSample(3, 0, 3_000, 75, 0, 0.0, 0, COUNTS), T0 + 2 * MS // 5)
    s = stepper()  # a device clock that steps back: the host's gap
    s.check(RigSample(1, 0, 5_000, 0, 0, 0.0, 0, COUNTS), T0)
    with pytest.raises(SafetyTrip, match=r"jumped 38 counts in 1\.0 ms"):
        s.check(RigSample(2, 0, 1_000, 38, 0, 0.0, 0, COUNTS), T0 + MS)
