#!/usr/bin/env python3
"""Benchmark of the simulated rig: how fast a simulated drop test runs, and which parts cost what.

Prints:
- the simulated 10 s drop test (hold + release + 10 s record, sim backend on the virtual clock,
  through the same runner, loop, plan, safety supervisor and stream as a real run; no run folder)
  as a multiple of real time, wall and CPU time, best and median of several repetitions; beside it,
  from the same run, the baseline: the bare plant integration (``RigPlant.step`` alone, one call
  per 1 kHz cycle over the same simulated time), the floor any loop around the plant stands on;
- the same for a drop under the ``skyhook`` law (estimator, observer, law and inverse each cycle);
- the CPU cost of each part per cycle [us]: the drop run once whole, then each part alone over that
  run's own samples, times and commands (CPU time of the block, so a shared machine's preemptions
  do not count; no timer inside the cycle):
  the sim backend's ``read`` (the plant's sub-steps, the encoder counts and edge times in one
  compiled call, :func:`sashil.drivers.sim_advance.advance`; the sample), the plan (and under a law the controller: estimator + observer
  + law + inverse), safety (``check`` + ``limit``), recording (the loop's row into the stream and the
  stream's columns after the run), the backend's ``write``; then what the whole run costs beyond
  those parts, in three rows: the parts called in turn as a cycle calls them (no loop around them)
  less the sum of each alone (what they cost each other: the caches and branch history they share),
  the per-run cost (set-up, warm-up, the record derived after the run: from the same drop with a
  ``SHORT_S`` record, the cost that does not grow with the run's length) and the loop around the
  parts (the rest: the clock, deadlines, timing rings, the stop and tuning checks); the CPU other
  threads spent during the run is its own row (BLAS's worker threads spin for about 0.1 s once a
  matrix set-up wakes them);
  for reference, the bare plant (``RigPlant.step``) over the same commands;
- the damper model's real-time step (BoucWenZ.advance over one 1 kHz sample's angle increment of a
  recorded drop test, plus the torque), median / p99 / max per sample.

Goals: drop test >= 200x real time; damper step <= 20 us median.

    .venv/bin/python tools/bench_sim.py [--repeats 6] [--quick]

``--quick``: one repetition of a 1 s drop test (seconds; the figures mean little at that size).
The machine may be shared: CPU time is the steadier figure.
"""

from __future__ import annotations

import argparse
import copy
import itertools
import math
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sashil.config.parts import SafetyParts, StageParts
from sashil.control.registry import make_controller
from sashil.drivers import rig_parts
from sashil.drivers.interface import RigCommand
from sashil.drivers.sim import SimulatedRig
from sashil.engine import assemble
from sashil.engine.resolve import default_config
from sashil.lab._drop_test import READS, run_drop_test
from sashil.models.hysteresis import BoucWenParams, BoucWenZ
from sashil.plans.drop import DropTestPlan
from sashil.recording.recorder import Recorder
from sashil.runtime.clock import VirtualClock
from sashil.runtime.loop import ControlLoop, record_columns
from sashil.safety import SafetySupervisor

clock = time.perf_counter_ns
#: the record length [s] of the short drop whose cost is taken as the per-run part of a drop's
SHORT_S = 0.2


def drop_config(law: str) -> dict[str, Any]:
    config = copy.deepcopy(default_config())
    config["controller"]["law"] = law
    if law == "skyhook":
        config["controller"]["c_sky"] = 2.0
    return config


def drop_plan(config: dict[str, Any], current: float, record_s: float, controller: Any) -> DropTestPlan:
    """A drop's plan from -5 deg at ``current`` for ``record_s`` under ``controller``, given no rig."""
    return DropTestPlan(assemble(config, reads=READS), -5.0, current, record_s, controller)


def one_drop(config: dict[str, Any], current: float, record_s: float) -> Any:
    law = config["controller"]["law"]
    controller = None if law == "passive" else make_controller(law, StageParts.read(config))
    return run_drop_test(config, -5.0, current, record_s, controller=controller)


def bare_plant(config: dict[str, Any], cycles: int, current: float) -> tuple[float, float]:
    """(wall, CPU) seconds of ``cycles`` plant steps of one period (the drop's hold, then free)."""
    rate = config["loop"]["rate_hz"]
    plant = SimulatedRig.from_parts(rig_parts(config, "sim")).plant
    plant.hold(math.radians(-5.0))
    dt = 1.0 / rate
    held = round(0.3 * rate)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    step = plant.step
    for k in range(cycles):
        if k == held:
            plant.release()
        step(dt, current)
    return time.perf_counter() - wall0, time.process_time() - cpu0


def bench_speed(law: str, repeats: int, record_s: float) -> None:
    config = drop_config(law)
    rate = config["loop"]["rate_hz"]
    one_drop(config, 0.0, min(record_s, 1.0))  # warm-up (imports, caches)
    wall_ratios, cpu_ratios, plant_wall, plant_cpu = [], [], [], []
    simulated = 0.0
    for repeat in range(repeats):
        current = 1.0 if repeat % 2 else 0.0
        wall0, cpu0 = time.perf_counter(), time.process_time()
        record = one_drop(config, current, record_s)
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        simulated = record.summary["timing"]["cycles"] / rate
        wall_ratios.append(simulated / wall)
        cpu_ratios.append(simulated / cpu)
        bare_wall, bare_cpu = bare_plant(config, record.summary["timing"]["cycles"], current)
        plant_wall.append(simulated / bare_wall)
        plant_cpu.append(simulated / bare_cpu)
    what = "passive, constant current" if law == "passive" else f"under {law!r} after the release"
    print(
        f"simulated drop test ({what}): {simulated:.2f} s of rig time per run ({record_s:g} s record + hold), "
        f"{repeats} run(s) at 0 A / 1 A"
    )
    print(
        f"  speed (wall): best {max(wall_ratios):7.0f}x  median {statistics.median(wall_ratios):7.0f}x real time"
        + ("   [goal >= 200x]" if law == "passive" else "")
    )
    print(f"  speed (CPU):  best {max(cpu_ratios):7.0f}x  median {statistics.median(cpu_ratios):7.0f}x real time")
    print(
        f"  baseline, the bare plant integration (RigPlant.step per cycle, same rig time): "
        f"wall best {max(plant_wall):.0f}x, CPU best {max(plant_cpu):.0f}x real time"
    )


def _cpu(block: Callable[[], Any], repeats: int = 3) -> float:
    """This thread's CPU seconds of ``block()``, the best of ``repeats`` (the machine may be shared:
    preemptions do not count, and the best run is the one least slowed by a neighbour's use of the
    caches; BLAS's worker threads, spinning after a set-up woke them, are the whole run's row of
    their own, not a part's)."""
    best = math.inf
    for _ in range(repeats):
        cpu0 = time.thread_time()
        block()
        best = min(best, time.thread_time() - cpu0)
    return best


def _cpu_and_thread(block: Callable[[], Any], repeats: int = 3) -> tuple[float, float]:
    """(process CPU, this thread's CPU) seconds of ``block()``, of the run with the least process CPU.
    The difference is other threads' work during the run (BLAS's worker threads, when woken)."""
    best = (math.inf, math.inf)
    for _ in range(repeats):
        cpu0, thread0 = time.process_time(), time.thread_time()
        block()
        best = min(best, (time.process_time() - cpu0, time.thread_time() - thread0))
    return best


def bench_breakdown(law: str, record_s: float) -> None:
    """Per-cycle cost of each part of one drop test: the run once whole, then each part alone over the
    run's own samples, times and commands (module docstring); the loop's share is the rest."""
    config = drop_config(law)
    one_drop(config, 0.0, min(record_s, 1.0))  # warm-up
    current = 1.0
    samples: list[Any] = []
    commands: list[float] = []
    rig = SimulatedRig.from_parts(rig_parts(config, "sim"))
    read, write = rig.read, rig.write

    def capture_read(t_ns: int, dt_ns: int) -> Any:
        sample = read(t_ns, dt_ns)
        samples.append((sample, t_ns, dt_ns))
        return sample

    def capture_write(cmd: Any, t_ns: int, dt_ns: int) -> None:
        commands.append(cmd.current_a)
        write(cmd, t_ns, dt_ns)

    rig.read, rig.write = capture_read, capture_write  # type: ignore[method-assign]
    controller = None if law == "passive" else make_controller(law, StageParts.read(config))
    record = run_drop_test(config, -5.0, current, record_s, rig=rig, controller=controller)
    # a fresh controller for each timed block, built beforehand: its construction (the filter's
    # gains, the law's set-up) is not a per-cycle cost
    built = [None if law == "passive" else make_controller(law, StageParts.read(config)) for _ in range(32)]

    def fresh() -> Any:
        return built.pop()

    cycles = record.summary["timing"]["cycles"]
    whole, loop_thread = _cpu_and_thread(lambda: run_drop_test(config, -5.0, current, record_s, controller=fresh()))
    # the cost of a run that does not grow with its length: the same drop with a record SHORT_S long
    short = run_drop_test(config, -5.0, current, SHORT_S, controller=fresh()).summary["timing"]["cycles"]
    short_cpu = _cpu(lambda: run_drop_test(config, -5.0, current, SHORT_S, controller=fresh()))
    per_run = short_cpu - short * (loop_thread - short_cpu) / (cycles - short)  # the loop's thread, both
    commands = commands[:cycles]
    steps = samples[:cycles]
    release_after = max(config["drop_test"]["hold_time_s"] + 0.1, 0.3)
    rate = config["loop"]["rate_hz"]

    def plant_alone() -> None:
        plant = SimulatedRig.from_parts(rig_parts(config, "sim")).plant
        plant.hold(math.radians(-5.0))
        step, dt, held = plant.step, 1.0 / rate, round(release_after * rate)
        for k, command in enumerate(commands):
            if k == held:
                plant.release()
            step(dt, command)

    def backend(with_write: bool) -> Callable[[], None]:
        def run() -> None:
            sim = SimulatedRig.from_parts(rig_parts(config, "sim"))
            sim.operator_hold(math.radians(-5.0), release_after)
            sim.set_initial_current(current)
            sim.configure()
            sim.activate()
            sim_read, sim_write = sim.read, sim.write
            cmd = RigCommand(0.0)
            for (_, t_ns, dt_ns), command in zip(steps, commands, strict=True):
                sim_read(t_ns, dt_ns)
                if with_write:
                    cmd.current_a = command
                    sim_write(cmd, t_ns, dt_ns)
                else:
                    sim._command = command  # the command a write would leave

        return run

    def stage(with_plan: bool) -> Callable[[], None]:
        def run() -> None:
            ctl = fresh()
            if with_plan:
                plan = drop_plan(config, current, record_s, ctl)
                plan.known_release_after_s = release_after
                step = plan.step
            elif ctl is not None:
                ctl.held = False
                step = ctl.step
            else:
                return
            for sample, t_ns, dt_ns in steps:
                step(sample, t_ns, dt_ns)

        return run

    def safety_alone() -> None:
        safety = SafetySupervisor.from_parts(SafetyParts.read(config))
        safety.start(steps[0][1])
        check, limit, cmd = safety.check, safety.limit, RigCommand(0.0)
        for (sample, t_ns, dt_ns), command in zip(steps, commands, strict=True):
            check(sample, t_ns)
            cmd.current_a = command
            limit(cmd, dt_ns)

    def in_turn() -> None:
        """A cycle's calls one after another over the run's times, as the loop makes them, without
        the loop around them (no clock, deadlines, timing rings, stop or tuning checks)."""
        sim = SimulatedRig.from_parts(rig_parts(config, "sim"))
        sim.operator_hold(math.radians(-5.0), release_after)
        sim.set_initial_current(current)
        sim.configure()
        sim.activate()
        plan = drop_plan(config, current, record_s, fresh())
        plan.known_release_after_s = release_after
        safety = SafetySupervisor.from_parts(SafetyParts.read(config))
        safety.start(steps[0][1])
        recorder = Recorder(None, record_columns(plan), keep=True)
        loop = ControlLoop(sim, plan, VirtualClock(), rate, recorder=recorder)
        loop.start_ns = steps[0][1]
        read, check, step, limit, row, write = sim.read, safety.check, plan.step, safety.limit, loop._record, sim.write
        for _, t_ns, dt_ns in steps:
            sample = read(t_ns, dt_ns)
            check(sample, t_ns)
            cmd = step(sample, t_ns, dt_ns)
            if cmd is None:
                break
            cmd = limit(cmd, dt_ns)
            row(t_ns, sample, cmd.current_a, cmd.road_speed_rad_s, 0)
            write(cmd, t_ns, dt_ns)
        recorder.stream()

    def recording_alone() -> None:
        plan = drop_plan(config, current, record_s, fresh())
        recorder = Recorder(None, record_columns(plan), keep=True)
        loop = ControlLoop(rig, plan, VirtualClock(), rate, recorder=recorder)
        loop.start_ns = steps[0][1]
        row = loop._record
        for (sample, t_ns, _), command in zip(steps, commands, strict=True):
            row(t_ns, sample, command, None, 0)
        recorder.stream()

    plant = _cpu(plant_alone)
    sim_read = _cpu(backend(False))
    write_only = _cpu(backend(True)) - sim_read
    controller_s = _cpu(stage(False))
    plan = _cpu(stage(True)) - controller_s
    rows = [("sim read (plant, encoder counts and edge times in one compiled call; the sample)", sim_read)]
    if controller is not None:
        rows.append(("estimator + observer + law + inverse (Controller.step)", controller_s))
    rows += [
        ("plan (DropTestPlan.step" + (", less the controller)" if controller is not None else ")"), plan),
        ("safety (check + limit)", _cpu(safety_alone)),
        ("recording (the row into the stream, the stream's columns)", _cpu(recording_alone)),
        ("backend write", write_only),
    ]
    parts = sum(v for _, v in rows)
    turn = _cpu(in_turn)
    rows += [
        ("the parts in turn, beyond each alone (caches and branches they share)", turn - parts),
        ("other threads than the loop's (BLAS workers, when a set-up wakes them)", whole - loop_thread),
        (f"per run: set-up, warm-up, the record after the run ({per_run * 1e3:.1f} ms a run)", per_run),
    ]
    rows.append(("the loop around the parts (clock, deadlines, timing rings, checks)", whole - sum(v for _, v in rows)))
    what = "passive" if law == "passive" else f"under {law!r}"
    print(f"CPU cost per cycle, drop test {what} ({cycles} cycles; each part alone over the run's samples):")
    for label, value in rows:
        print(f"  {label:<74s} {value / cycles * 1e6:6.2f} us  {100 * value / whole:5.1f} %")
    print(
        f"  {'for reference, the plant alone (RigPlant.step per cycle, not in the sum)':<74s} {plant / cycles * 1e6:6.2f} us"
    )
    per_cycle = whole / cycles * 1e6
    print(f"  {'the whole run':<74s} {per_cycle:6.2f} us  (= {1e6 / per_cycle / rate:.0f}x real time in CPU time)")


def bench_damper_step(record_s: float = 10.0) -> None:
    params = BoucWenParams()
    config = default_config()
    record = run_drop_test(config, -5.0, 0.0, record_s)
    angles = record.data["theta_rad"].tolist()
    currents = record.data["current_a"].tolist()
    increments = [b - a for a, b in itertools.pairwise(angles)]
    law = BoucWenZ.from_params(params)
    torque = params.torque
    # timer overhead, to subtract
    overhead = []
    for _ in range(len(increments)):
        t0 = clock()
        overhead.append(clock() - t0)
    base = statistics.median(overhead)
    samples = []
    for _ in range(3):
        z = 0.0
        for dtheta, current in zip(increments, currents[1:], strict=True):  # the current at the end of each step
            t0 = clock()
            z = law.advance(z, dtheta)
            torque(z, dtheta * 1000.0, current)
            samples.append(clock() - t0 - base)
    samples.sort()
    n = len(samples)
    print(f"damper model step (z over one 1 kHz sample of a drop test + torque), {n} samples:")
    print(
        f"  median {samples[n // 2] / 1000:.2f} us   p99 {samples[int(n * 0.99)] / 1000:.2f} us   "
        f"max {samples[-1] / 1000:.1f} us   [goal median <= 20 us]"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=6)
    parser.add_argument("--quick", action="store_true", help="one repetition of a 1 s drop test (seconds)")
    args = parser.parse_args()
    record_s = 1.0 if args.quick else 10.0
    repeats = 1 if args.quick else args.repeats
    bench_speed("passive", repeats, record_s)
    bench_breakdown("passive", record_s)
    bench_speed("skyhook", max(1, repeats // 2), record_s)
    bench_breakdown("skyhook", record_s)
    bench_damper_step(record_s)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    keep_output("bench_sim", main)
