"""Encoder edge times: the simulated rig times each count change on the plant's trajectory, and both
emulated boards (Python and C, serial and CAN, device and host pacing) send them, identical and
equal to the hand-derived times of a motion whose edges are analytic.

The motion: the operator holds the arm (theta fixed at the hold angle) while the road wheel turns at
a constant speed w from t = 0. Then theta1(t) = w t and theta2(t) = theta_hold + w t, and with q
radians per count the count n is reached (direction d = sign(w)) when the angle crosses the
boundary (n - d/2) q: the road at t = (n - d/2) q / w, the arm at t = ((n - d/2) q - theta_hold) / w.
"""

from __future__ import annotations

import math

import pytest

from sashil.drivers import can_codec, firmware
from sashil.drivers.emulator import Operator, build_device
from sashil.drivers.emulator.wire import WireBytes, WireCan
from sashil.drivers.encoder_edges import hermite_bulge, quick_test, stays_in_cell
from sashil.drivers.interface import NO_EDGE, RigCommand
from sashil.drivers.messages import (
    CMD_ENABLE,
    EDGE_AGE_NONE,
    PACING_DEVICE,
    PACING_HOST,
    Command,
    Configure,
    Hello,
    RoadSpeed,
    Sample,
)
from sashil.drivers.serial_codec import StreamDecoder, encode_frame
from sashil.drivers.sim import SimulatedRig
from sashil.drivers.sim_advance import _angle, _last_crossing
from sashil.engine.resolve import default_config
from sashil.models.hysteresis import rig_params
from sashil.models.plant import RigPlant

MS = 1_000_000
COUNTS = 4096
Q = 2 * math.pi / COUNTS
HOLD_DEG = 0.3


def edge_us(boundary_rad: float, offset_rad: float, speed: float) -> int:
    """The device microsecond of the instant ``offset + speed * t`` reaches ``boundary`` (t from 0)."""
    return math.floor((boundary_rad - offset_rad) / speed * 1e6)


def expected_edge(count: int, offset_rad: float, speed: float) -> tuple[int, int]:
    """(time [us], direction) of the edge into ``count`` of the motion ``offset + speed * t``."""
    direction = 1 if speed > 0 else -1
    return edge_us((count - 0.5 * direction) * Q, offset_rad, speed), direction


# --- the compiled edge finder -------------------------------------------------------------------
# The simulated rig's search (sashil.drivers.sim_advance) takes a sub-step's curve as two tuples: the
# relative angle's Hermite curve (y0, m0, y1, m1, t0) and the road wheel (h, road0, speed, road_t0),
# whose angle at s of the sub-step is road0 + speed * (t0 + s * h - road_t0). With t0 = 0, h = 1 and
# road_t0 = 0, s is the time: the road is the line road0 + speed * s.
#: the road at rest at 0
STILL = (1.0, 0.0, 0.0, 0.0)


def hermite(y0: float, m0: float, y1: float, m1: float, s: float) -> float:
    """The arm's angle the compiled search sees at ``s`` for the Hermite curve alone (the road still)."""
    return _angle(True, s, (y0, m0, y1, m1, 0.0), STILL)


def last_crossing(
    arm: bool, y0: float, y1: float, bulge: float, curve: tuple[float, ...], road: tuple[float, ...]
) -> tuple[float, int] | None:
    """The compiled search's last count change of the arm (``arm``) or the road, as (s, direction),
    or None."""
    s, direction = _last_crossing(arm, y0, y1, bulge, Q, (*curve, 0.0), road)
    return (s, direction) if direction else None


def test_the_hermite_curve_has_its_ends_and_slopes_and_the_bulge_bounds_it():
    y0, m0, y1, m1 = 0.2, 1.5, -0.1, -0.7
    assert hermite(y0, m0, y1, m1, 0.0) == y0 and hermite(y0, m0, y1, m1, 1.0) == pytest.approx(y1)
    eps = 1e-7
    assert (hermite(y0, m0, y1, m1, eps) - y0) / eps == pytest.approx(m0, rel=1e-5)
    bulge = hermite_bulge(y0, m0, y1, m1)
    worst = max(abs(hermite(y0, m0, y1, m1, k / 1000) - (y0 + (y1 - y0) * k / 1000)) for k in range(1001))
    assert worst <= bulge


def test_the_road_adds_its_line_to_the_arms_curve():
    curve, road = (0.2, 1.5, -0.1, -0.7, 0.0), (1.0, 0.05, -0.3, 0.0)
    for s in (0.0, 0.25, 0.6, 1.0):
        assert _angle(False, s, curve, road) == pytest.approx(0.05 - 0.3 * s)
        assert _angle(True, s, curve, road) == pytest.approx(hermite(*curve[:4], s) + 0.05 - 0.3 * s)


def test_the_quick_test_rules_out_an_edge_only_where_the_search_finds_none():
    """quick_test (compiled, every simulated cycle) says -1 exactly when both curves keep their count's
    cell, else gives the arm curve's bound; the search over a sub-step it lets through finds the
    same edges as over one it does not (seeded sub-steps of a swinging arm over a turning road)."""
    import random

    rng = random.Random(7)
    ruled_out = searched = 0
    for _ in range(3000):
        y0 = rng.uniform(-0.1, 0.1)
        speed = rng.choice([0.3, 3.0])  # counts per sub-step: a slow arm (mostly no edge) or a fast one
        m0, m1 = rng.uniform(-speed, speed) * Q, rng.uniform(-speed, speed) * Q
        y1 = y0 + 0.5 * (m0 + m1) + rng.uniform(-0.1, 0.1) * Q
        r0 = rng.choice([0.0, rng.uniform(-0.05, 0.05)])
        r1 = r0 + rng.choice([0.0, rng.uniform(-2, 2) * Q])
        road_bulge = rng.choice([0.0, abs(rng.gauss(0.0, 0.1)) * Q])
        result = quick_test(y0, m0, y1, m1, r0, r1, road_bulge, Q)
        arm_bulge = hermite_bulge(y0, m0, y1, m1) + road_bulge
        keeps = stays_in_cell(y0 + r0, y1 + r1, arm_bulge, Q) and stays_in_cell(r0, r1, road_bulge, Q)
        if keeps:
            ruled_out += 1
            assert result == -1.0
            road = (1.0, r0, r1 - r0, 0.0)
            assert last_crossing(True, y0 + r0, y1 + r1, arm_bulge, (y0, m0, y1, m1), road) is None
        else:
            searched += 1
            assert result == arm_bulge
    assert ruled_out > 500 and searched > 500  # both branches exercised
    # an angle exactly on a count's boundary is not inside the cell (round half to even, as Python)
    assert not stays_in_cell(0.5 * Q, 0.5 * Q, 0.0, Q) and stays_in_cell(0.4 * Q, 0.4 * Q, 0.0, Q)


@pytest.mark.parametrize("arm", [True, False], ids=["arm", "road"])
def test_last_crossing_of_a_straight_line_is_its_last_boundary(arm):
    """The line as the arm's curve (a Hermite curve whose slopes are its chord's) over a still road,
    or as the road under a still arm."""

    def line(start: float, slope: float) -> dict:
        if arm:
            return {"curve": (start, slope, start + slope, slope), "road": STILL}
        return {"curve": (0.0, 0.0, 0.0, 0.0), "road": (1.0, start, slope, 0.0)}

    # 0.3 q to 3.2 q: counts 0 -> 3, the last boundary 2.5 q at s = (2.5 - 0.3) / 2.9
    s, direction = last_crossing(arm, 0.3 * Q, 3.2 * Q, 0.0, **line(0.3 * Q, 2.9 * Q))
    assert direction == 1 and s == pytest.approx(2.2 / 2.9, abs=1e-7)
    s, direction = last_crossing(arm, 0.3 * Q, -0.7 * Q, 0.0, **line(0.3 * Q, -1.0 * Q))
    assert direction == -1 and s == pytest.approx(0.8, abs=1e-7)
    assert last_crossing(arm, 0.1 * Q, 0.3 * Q, 0.0, **line(0.1 * Q, 0.2 * Q)) is None


def test_a_motion_that_leaves_its_count_and_comes_back_has_its_return_edge():
    # up through 0.5 q (at s = 0.22) and back below it within the step (at s = 0.68): the last edge is
    # the way down, where 0.2 + 1.8 s - 2 s^2 = 0.5, s = (1.8 + sqrt(0.84)) / 4; at s = 0.5, one of the
    # search's points, the angle is 0.6 q, inside the next count
    def angle(s: float) -> float:
        return (0.2 + 2.0 * s * (1 - s)) * Q - 0.2 * Q * s

    # the quadratic is its own Hermite curve through its ends and slopes (1.8 q and -2.2 q)
    curve = (angle(0.0), 1.8 * Q, angle(1.0), -2.2 * Q)
    found = last_crossing(True, angle(0.0), angle(1.0), 1.0 * Q, curve, STILL)
    assert found is not None and found[1] == -1
    assert angle(found[0]) == pytest.approx(0.5 * Q, abs=1e-9) and found[0] > 0.5
    assert found[0] == pytest.approx((1.8 + math.sqrt(0.84)) / 4, abs=1e-7)


# --- the simulated rig ----------------------------------------------------------------------------
def _held_rig(speed: float, max_step_s: float = 0.001) -> SimulatedRig:
    config = default_config()
    plant = RigPlant(rig_params(config["model"]), max_step_s=max_step_s)
    rig = SimulatedRig(plant, COUNTS)
    rig.configure()
    rig.activate()
    rig.read(0, 0)
    rig.operator_hold(math.radians(HOLD_DEG), 100.0)
    rig.write(RigCommand(0.0, speed), 0, 0)
    return rig


@pytest.mark.parametrize("speed, max_step_s", [(2.0, 0.001), (-0.37, 0.001), (5.3, 0.0004)])
def test_the_simulated_rig_times_each_edge_on_the_trajectory(speed, max_step_s):
    rig = _held_rig(speed, max_step_s)
    hold = math.radians(HOLD_DEG)
    for k in range(1, 40):
        sample = rig.read(k * MS, MS)
        road = expected_edge(sample.road_counts, 0.0, speed) if sample.road_counts else (NO_EDGE, 0)
        assert (sample.road_edge_us, sample.road_edge_dir) == road
        arm_count_at_hold = round(hold / Q)
        if sample.arm_counts == arm_count_at_hold:  # the hold's jump at t = 0 is the arm's last edge
            assert (sample.arm_edge_us, sample.arm_edge_dir) == (0, 1)
        else:
            assert (sample.arm_edge_us, sample.arm_edge_dir) == expected_edge(sample.arm_counts, hold, speed)


def test_a_rig_at_rest_has_no_edge():
    config = default_config()
    rig = SimulatedRig(RigPlant(rig_params(config["model"])), COUNTS)
    rig.configure()
    rig.activate()
    for k in range(5):
        sample = rig.read(k * MS, MS)
        assert (sample.arm_edge_us, sample.arm_edge_dir, sample.road_edge_us, sample.road_edge_dir) == (
            NO_EDGE,
            0,
            NO_EDGE,
            0,
        )


# --- both boards, both links, both pacings ------------------------------------------------------
def _decode(out: list, decoder: object) -> list[Sample]:
    got = []
    for _, item in out:
        if isinstance(item, Sample):
            got.append(item)
        elif isinstance(item, WireBytes):
            got += [m for _, m in decoder.feed(item.data) if isinstance(m, Sample)]  # type: ignore[attr-defined]
        elif isinstance(item, WireCan):
            done = decoder.feed(item.can_id, item.data)  # type: ignore[attr-defined]
            if done is not None and isinstance(done[1], Sample):
                got.append(done[1])
    return got


def _board_samples(board: str, link: str, pacing: int, speed: float) -> list[Sample]:
    """The samples of one board over 60 ms of the held-arm, turning-road motion."""
    device = build_device(default_config(), operator=Operator(HOLD_DEG, 100.0), board=board, link=link)
    decoder = can_codec.CanDecoder() if link == "can" else StreamDecoder()

    def deliver(msg: object, at_ns: int) -> list:
        if board == "python":
            return device.handle(msg, at_ns)  # type: ignore[arg-type]
        if link == "can":
            out = []
            for can_id, data in can_codec.encode(msg):  # type: ignore[arg-type]
                out += device.handle(WireCan(can_id, data), at_ns)
            return out
        return device.handle(WireBytes(encode_frame(msg, 1)), at_ns)  # type: ignore[arg-type]

    out = deliver(Hello(), 0) + deliver(Configure(1000, 1000, pacing), 0) + deliver(RoadSpeed(speed), 0)
    for k in range(1, 61):
        t = k * MS + (137_000 if pacing == PACING_HOST else 0)  # host pacing: off the device's grid
        out += deliver(Command(0.0, CMD_ENABLE), t)
        out += device.tick(t)
    return _decode(out, decoder)


BOARDS = [("python", "serial")] + ([("c", "serial"), ("c", "can")] if firmware.compiler() is not None else [])


@pytest.mark.parametrize("pacing", [PACING_DEVICE, PACING_HOST])
def test_both_boards_send_the_hand_derived_edge_ages(pacing):
    speed = 1.7  # rad/s: each count changes every q / w = 0.90 ms
    hold = math.radians(HOLD_DEG)
    runs = {f"{board}/{link}": _board_samples(board, link, pacing, speed) for board, link in BOARDS}
    reference = runs["python/serial"]
    assert len(reference) >= 59
    for name, got in runs.items():
        assert got == reference, name  # identical to the microsecond on every board and link
    for sample in reference[1:]:
        t_us = sample.device_time_us
        road_us, road_dir = expected_edge(sample.road_counts, 0.0, speed)
        assert (sample.road_edge_age_us, sample.road_edge_dir) == (t_us - road_us, road_dir)
        arm_us, arm_dir = expected_edge(sample.arm_counts, hold, speed)
        assert (sample.arm_edge_age_us, sample.arm_edge_dir) == (t_us - arm_us, arm_dir)
        assert 0 <= sample.road_edge_age_us <= 903  # at most one count period old


def test_an_encoder_that_does_not_move_reports_no_recent_edge():
    got = _board_samples("python", "serial", PACING_DEVICE, 0.0)
    late = [s for s in got if s.device_time_us > 0]
    assert late and all(s.road_edge_age_us == EDGE_AGE_NONE and s.road_edge_dir == 0 for s in late)
    # the arm's hold jump at boot is an edge, reported until it is 65.535 ms old
    assert all(s.arm_edge_age_us == s.device_time_us and s.arm_edge_dir == 1 for s in late)
