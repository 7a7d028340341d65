"""The road the board applied, from the road encoder's edges (sashil.identify.road)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sashil.engine.resolve import default_config
from sashil.identify.data import Record, load_records
from sashil.identify.rig_models import MODELS
from sashil.identify.road import angle_acceleration, applied_road_angle, count_quantum, edge_boundaries
from sashil.lab.calibration.analysis import APPLIED_ROAD, records_of, road_acceleration, with_applied_road
from sashil.lab.calibration.rig import StepResult
from sashil.plans.calibration_step import RoadChirp, Step

COUNTS = 4096
Q = 2.0 * math.pi / COUNTS
PERIOD_S = 1e-3
#: the sample carries no edge older than this (the wire's u16 age saturates)
MAX_AGE_S = 0.065535


def road_path(knots_s: np.ndarray, speeds: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Angle of a wheel at rest at 0 rad that steps to ``speeds[k]`` at ``knots_s[k]``."""
    angle_at_knots = np.concatenate(([0.0], np.cumsum(speeds[:-1] * np.diff(knots_s))))
    k = np.clip(np.searchsorted(knots_s, t, side="right") - 1, 0, None)
    return np.where(t < knots_s[0], 0.0, angle_at_knots[k] + speeds[k] * (t - knots_s[k]))


def encoder_samples(knots_s: np.ndarray, speeds: np.ndarray, t: np.ndarray, offset_rad: float = 0.0):
    """What a board reports of that wheel at each sample time: the count (rounding) and its last
    edge (time, direction), found on a fine grid (1 us: the board's clock)."""
    fine = np.arange(0.0, t[-1] + 1e-6, 1e-6)
    count = np.rint((road_path(knots_s, speeds, fine) + offset_rad) / Q)
    change = np.nonzero(np.diff(count))[0] + 1
    edge_t, edge_dir = fine[change], np.sign(np.diff(count)[change - 1])
    k = np.searchsorted(edge_t, t, side="right") - 1
    has = (k >= 0) & (t - edge_t[np.maximum(k, 0)] < MAX_AGE_S)
    edge_s = np.where(has, edge_t[np.maximum(k, 0)], np.nan)
    return count[np.rint(t / 1e-6).astype(int)], edge_s, np.where(has, edge_dir[np.maximum(k, 0)], 0)


def chirp_commands(duration_s: float, update_s: float = 4e-3) -> tuple[np.ndarray, np.ndarray]:
    """Speed commands of a 1 deg road chirp 0.8-3 Hz (the calibration's), one per ``update_s``."""
    chirp = RoadChirp(math.radians(1.0), 0.8, 3.0, duration_s - 0.5, 1.0)
    times = np.arange(0.0, duration_s, update_s)
    return times, np.array([chirp.speed(s) for s in times])


def test_edges_name_the_boundaries_they_crossed() -> None:
    # a road going up over counts 1, 2, 3 and back down to 2: boundaries 0.5, 1.5, 2.5, then 2.5 down
    edge_s = np.array([np.nan, 0.010, 0.010, 0.020, 0.030, 0.030, 0.040])
    edge_dir = np.array([0, 1, 1, 1, 1, 1, -1])
    counts = np.array([0, 1, 1, 2, 3, 3, 2])
    t, boundary = edge_boundaries(edge_s, edge_dir, counts)
    assert t.tolist() == [0.010, 0.020, 0.030, 0.040]
    assert boundary.tolist() == [0.5, 1.5, 2.5, 2.5]


def test_a_flipped_count_does_not_move_an_edge() -> None:
    # angle noise flipped the count of one sample (3 instead of 2): its edge still crossed 1.5
    times = 0.01 * np.arange(1, 12)
    counts = np.arange(1, 12, dtype=float)
    counts[4] += 1.0
    _, boundary = edge_boundaries(times, np.ones(11), counts)
    assert boundary.tolist() == (np.arange(1, 12) - 0.5).tolist()


def test_too_few_edges_give_no_road() -> None:
    assert edge_boundaries(np.array([0.01, 0.02, np.nan]), np.array([1, 1, 0]), np.array([1, 2, 2])) is None
    t = np.arange(3) * PERIOD_S
    assert applied_road_angle(t, np.full(3, np.nan), np.zeros(3), np.zeros(3), Q) is None


def test_late_commands_are_placed_where_the_edges_saw_the_road() -> None:
    """Commands that reach the wheel 1-9 ms late (a loaded link): the commanded integral is off by
    up to 1.8 counts (0.5 RMS); with the edges the road is within a tenth of a count (the delays of
    the commands between two edges near a reversal, 30-90 ms apart, are not seen), 0.02 RMS."""
    rng = np.random.default_rng(7)
    commanded_at, speeds = chirp_commands(8.0)
    applied_at = commanded_at + rng.uniform(1e-3, 9e-3, commanded_at.size)
    t = np.arange(0.0, 8.0, PERIOD_S)
    counts, edge_s, edge_dir = encoder_samples(applied_at, speeds, t, offset_rad=0.3 * Q)
    held = speeds[np.clip(np.searchsorted(commanded_at, t, side="right") - 1, 0, None)]
    truth = road_path(applied_at, speeds, t) + 0.3 * Q
    applied = applied_road_angle(t, edge_s, edge_dir, counts, Q, held)
    commanded = np.concatenate(([0.0], np.cumsum(held[:-1] * PERIOD_S)))
    assert np.max(np.abs(commanded - truth)) > 1.0 * Q
    assert np.max(np.abs(applied - truth)) < 0.12 * Q
    assert np.sqrt(np.mean((applied - truth) ** 2)) < 0.025 * Q


def test_without_commands_a_spline_through_the_edges() -> None:
    t = np.arange(0.0, 6.0, PERIOD_S)
    knots = np.arange(0.0, 6.0, 1e-4)  # a smooth 1 deg, 2 Hz sine (speed steps every 0.1 ms)
    speeds = math.radians(1.0) * 2 * math.pi * 2.0 * np.cos(2 * math.pi * 2.0 * knots)
    counts, edge_s, edge_dir = encoder_samples(knots, speeds, t)
    truth = road_path(knots, speeds, t)
    applied = applied_road_angle(t, edge_s, edge_dir, counts, Q)
    inside = (t > np.nanmin(edge_s)) & (t < np.nanmax(edge_s))
    assert np.max(np.abs(applied - truth)[inside]) < 0.05 * Q


def test_acceleration_of_a_road_angle_steps_the_speed_at_the_sample() -> None:
    # at rest, then 0.2 rad/s from sample 3 on, then 0.1 rad/s from sample 6 on: steps of +0.2, -0.1 rad/s
    t = np.arange(10) * 0.002
    speed = np.array([0, 0, 0, 0.2, 0.2, 0.2, 0.1, 0.1, 0.1])
    angle = np.concatenate(([0.0], np.cumsum(speed * 0.002)))
    acc = angle_acceleration(t, angle)
    expected = np.zeros(10)
    expected[3], expected[6] = 0.2 / 0.002, -0.1 / 0.002
    assert acc == pytest.approx(expected, abs=1e-9)
    # the same steps as the commanded speeds give them, when the wheel applied each one at once
    assert road_acceleration(t, np.concatenate((speed, [0.1]))) == pytest.approx(expected, abs=1e-9)


def road_result(delay_s: np.ndarray, with_edges: bool = True) -> tuple[StepResult, np.ndarray]:
    commanded_at, speeds = chirp_commands(6.0)
    t = np.arange(0.0, 6.0, PERIOD_S)
    counts, edge_s, edge_dir = encoder_samples(commanded_at + delay_s, speeds, t)
    held = speeds[np.clip(np.searchsorted(commanded_at, t, side="right") - 1, 0, None)]
    columns = {
        "time_s": t,
        "theta_rad": 0.05 * np.exp(-t) * np.cos(10.0 * t),
        "current_a": np.full(t.size, 0.5),
        "theta_road_rad": counts * Q,
        "road_speed_cmd_rad_s": held,
    }
    if with_edges:
        columns.update(road_edge_s=edge_s, road_edge_dir=edge_dir)
    chirp = RoadChirp(math.radians(1.0), 0.8, 3.0, 5.5, 1.0)
    step = Step("06-fit-road-5deg-0.50A", "fit", 5.0, 0.5, 6.0, chirp)
    truth = road_path(commanded_at + delay_s, speeds, t)
    return StepResult(step, columns, 5.0, False), truth


def test_calibration_takes_the_road_from_the_edges_when_the_record_has_them() -> None:
    rng = np.random.default_rng(3)
    result, truth = road_result(rng.uniform(1e-3, 9e-3, 1500))
    columns = with_applied_road(result.columns, COUNTS)
    edges = result.columns["road_edge_s"]
    between = (result.columns["time_s"] >= np.nanmin(edges)) & (result.columns["time_s"] <= np.nanmax(edges))
    assert np.max(np.abs(columns[APPLIED_ROAD] - truth)[between]) < 0.12 * Q
    assert np.max(np.abs(columns[APPLIED_ROAD] - truth)) < 0.5 * Q  # before the first edge, after the last
    (record,) = records_of([result], COUNTS)
    assert record.acc_road == pytest.approx(angle_acceleration(result.columns["time_s"], columns[APPLIED_ROAD]))
    # a record without the edges (an older run folder) falls back on the commanded speeds
    older, _ = road_result(np.zeros(1500), with_edges=False)
    (record,) = records_of([older], COUNTS)
    t = older.columns["time_s"]
    assert record.acc_road == pytest.approx(road_acceleration(t, older.columns["road_speed_cmd_rad_s"]))


def test_identify_reads_the_applied_road_from_a_data_file(tmp_path) -> None:
    """A road run's data.csv (calibrate writes the edges beside the counts) fitted by ``identify``:
    the same road as calibrate's, the count read from the road angle's steps."""
    rng = np.random.default_rng(5)
    result, _ = road_result(rng.uniform(1e-3, 9e-3, 1500))
    path = tmp_path / "data.csv"
    names = list(result.columns)
    rows = np.column_stack([result.columns[n] for n in names])
    np.savetxt(path, rows, delimiter=",", header=",".join(names), comments="", fmt="%.9g")
    (record,) = load_records([path])
    (calibrated,) = records_of([result], COUNTS)
    assert count_quantum(result.columns["theta_road_rad"]) == pytest.approx(Q)
    assert record.acc_road == pytest.approx(calibrated.acc_road, rel=1e-4, abs=1e-3)


def test_the_chain_starts_again_after_lost_samples() -> None:
    """Samples lost while the road crossed two boundaries: the next edge is anchored on its own
    count, not chained from the edge before the gap."""
    time_s = np.array([0.000, 0.001, 0.002, 0.003, 0.004, 0.008, 0.009, 0.010, 0.011, 0.012])
    counts = np.array([0, 1, 2, 3, 4, 7, 8, 9, 10, 11], dtype=float)
    _, boundary = edge_boundaries(time_s - 1e-4, np.ones(10), counts, time_s)
    assert boundary.tolist() == (counts - 0.5).tolist()


def test_counts_flipped_by_angle_noise_do_not_move_the_edges() -> None:
    """Angle noise of 0.3 counts before quantisation (the simulated rig's): right after an edge the
    angle is near the boundary and about half the counts there are off by one; the edges are not."""
    rng = np.random.default_rng(11)
    commanded_at, speeds = chirp_commands(6.0)
    t = np.arange(0.0, 6.0, PERIOD_S)
    counts, edge_s, edge_dir = encoder_samples(commanded_at, speeds, t)
    truth = road_path(commanded_at, speeds, t)
    noisy = np.rint(truth / Q + rng.normal(0.0, 0.3, t.size))
    assert np.mean(noisy != counts) > 0.2
    _, clean = edge_boundaries(edge_s, edge_dir, counts, t)
    _, boundary = edge_boundaries(edge_s, edge_dir, noisy, t)
    assert boundary.tolist() == clean.tolist()


def lossy_road_records(lost_fraction: float) -> tuple[Record, Record, np.ndarray]:
    """One road run at 0.5 A sampled every 1 ms, and the same run as a link recorded it with
    ``lost_fraction`` of its samples lost: the wheel's speed changes only at a received sample (a
    command follows a sample), so both describe the same road. Returns the full record, the lossy
    one and the rows it kept."""
    rng = np.random.default_rng(17)
    t = np.arange(0.0, 6.0, PERIOD_S)
    kept = np.flatnonzero(rng.random(t.size) >= lost_fraction)
    kept = np.union1d(kept, [0, t.size - 1])
    commanded_at, speeds = chirp_commands(6.0)
    wanted = speeds[np.clip(np.searchsorted(commanded_at, t, side="right") - 1, 0, None)]
    held = np.zeros(t.size)  # the speed of each 1 ms sample: the last one commanded at a kept sample
    held[kept] = wanted[kept]
    held = held[np.maximum.accumulate(np.where(np.isin(np.arange(t.size), kept), np.arange(t.size), 0))]

    def record(rows: np.ndarray) -> Record:
        time_s = t[rows]
        zeros = np.zeros(rows.size)
        return Record(
            "road", time_s, zeros, np.full(rows.size, 0.5), road_acceleration(time_s, held[rows]),
            zeros, zeros, zeros, zeros,
        )  # fmt: skip

    return record(np.arange(t.size)), record(kept), kept


def test_lost_samples_leave_the_road_forcing_of_the_fit_unchanged() -> None:
    """The fit's simulation reads the road acceleration linearly between samples: each speed step
    must change the speed by itself whatever the intervals either side, or a record with lost
    samples (2-6 % over a loaded link) drives the simulated arm with a road speed that is off for
    the rest of the record (4 counts RMS near resonance on a 12 s chirp)."""
    params = default_config()["model"]["params"]
    model = MODELS["bouc-wen"]
    full, lossy, kept = lossy_road_records(0.05)
    assert np.diff(lossy.time_s).max() >= 3 * PERIOD_S  # runs of lost samples
    swing = model.simulate(params, full)
    assert np.ptp(swing) > 20 * Q  # the road swings the arm through many counts
    # the speed the simulation integrates from the lossy record's accelerations (trapezoids)
    speed = np.concatenate(([0.0], np.cumsum(0.5 * (lossy.acc_road[1:] + lossy.acc_road[:-1]) * np.diff(lossy.time_s))))
    steps = np.diff(np.concatenate(([0.0], speed)))
    assert speed[-1] == pytest.approx(0.0, abs=1e-9)  # the chirp ends at rest
    assert np.max(np.abs(steps)) < 0.05  # no step larger than a command's (each under 0.02 rad/s)
    assert np.max(np.abs(model.simulate(params, lossy) - swing[kept])) < 0.05 * Q
