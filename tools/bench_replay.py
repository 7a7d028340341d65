#!/usr/bin/env python3
"""Benchmark of ``sashil replay``'s speed: a recorded 60 s run at 1 kHz through several laws.

One run is recorded on the simulated rig on the virtual clock (the skyhook law under a 1.2 Hz
road sine, through the one runner, as ``sashil run`` streams it), then replayed offline by
:func:`sashil.lab._replay.replay_rows` with each law: its own (skyhook), passive (no inverse),
clipped-optimal (an LQR law), and skyhook again with a live change re-applied halfway (a tuned
run's ``events.csv``). The figure is the replay's speed as a multiple of real time (best of three
passes); the baseline is the closed-loop simulation of the same run in the same process (plant
and controller on the virtual clock). Goal: >= 200x real time.

    python tools/bench_replay.py            # 60 s recording
    python tools/bench_replay.py --quick    # 2 s (seconds; the code path only)
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sashil.config.parts import StageParts
from sashil.control.registry import make_controller
from sashil.drivers import rig_parts
from sashil.drivers.sim import SimulatedRig
from sashil.engine import assemble
from sashil.engine.resolve import apply_values, default_config
from sashil.lab._replay import differences, replay_rows
from sashil.recording.data_file import read_data_csv
from sashil.roads.option import RoadParts, RoadStage, parse_road
from sashil.runtime.clock import VirtualClock
from sashil.runtime.runner import run_plan
from sashil.runtime.warmup import warm_kernels

LAWS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("skyhook", {"c_sky": 2.0}),
    ("passive", {"current_a": 0.5}),
    ("clipped-optimal", {}),
)


def law_config(base: dict[str, Any], law: str, params: dict[str, Any]) -> dict[str, Any]:
    values = [(["controller", "law"], law), *((["controller", key], value) for key, value in params.items())]
    return apply_values(base, values, "bench_replay")


def record(config: dict[str, Any], seconds: float, folder: Path) -> tuple[dict[str, Any], float]:
    """The recorded stream of a skyhook run of ``seconds``, and the wall time the simulation took."""
    road, _ = parse_road("sine:1.2:1.0", RoadParts.read(config))
    stage = RoadStage(make_controller(None, StageParts.read(config)), road)
    rig = SimulatedRig.from_parts(rig_parts(config, "sim"))
    started = time.perf_counter()
    outcome = run_plan(
        assemble(config), rig, stage, VirtualClock(), seconds, data_path=folder / "data.csv", realtime=False
    )
    wall = time.perf_counter() - started
    if outcome.error is not None:
        raise SystemExit(f"bench_replay: the recording failed: {outcome.error}")
    return read_data_csv(folder / "data.csv", required=("time_s",)), wall


def best_replay(config: dict[str, Any], data: dict[str, Any], changes: dict, passes: int) -> tuple[float, dict]:
    """The fastest of ``passes`` replays (a fresh controller each) and the last one's differences."""
    best, diff = float("inf"), {}
    for _ in range(passes):
        controller = make_controller(None, StageParts.read(config))
        started = time.perf_counter()
        out = replay_rows(controller, data, int(config["rig"]["encoder_counts_per_rev"]), changes, rate_hz=1000.0)
        best = min(best, time.perf_counter() - started)
        diff = differences(data, out)
    return best, diff


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="length of the recorded run (default 60)")
    parser.add_argument("--passes", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="a 2 s run, one pass (the code path only)")
    args = parser.parse_args(argv)
    if args.quick:
        args.seconds, args.passes = 2.0, 1
    warm_kernels()
    base = default_config()
    base["loop"]["rate_hz"] = 1000.0
    own = law_config(base, *LAWS[0])
    with tempfile.TemporaryDirectory(prefix="bench_replay-") as tmp:
        data, sim_wall = record(own, args.seconds, Path(tmp))
    span = float(data["time_s"][-1] - data["time_s"][0])
    print(f"recorded {span:.1f} s at 1 kHz (skyhook, road sine 1.2 Hz): {data['time_s'].size} rows")
    print(f"baseline: closed-loop simulation of the same run {span / sim_wall:7.0f}x real time ({sim_wall:.2f} s)")
    halfway = int(data["time_s"].size // 2)
    cases = [(law, params, {}) for law, params in LAWS]
    cases.append(("skyhook", {"c_sky": 2.0}, {halfway: ({"c_sky": 3.0}, 0.5)}))
    worst = float("inf")
    for law, params, changes in cases:
        seconds, diff = best_replay(law_config(base, law, params), data, changes, args.passes)
        speed = span / seconds
        worst = min(worst, speed)
        label = law + (" + a live change" if changes else "")
        same = diff.get("current_cmd_a", {}).get("max_abs")
        note = f"  (own law: i* differs by at most {same:.3g} A)" if law == "skyhook" and not changes else ""
        print(f"replay {label:<26} {speed:7.0f}x real time ({seconds:.3f} s){note}")
    print(f"slowest replay: {worst:.0f}x real time  (goal >= 200x)")
    print("note: measured on this machine as it is loaded; other processes slow both figures alike")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("bench_replay", main))
