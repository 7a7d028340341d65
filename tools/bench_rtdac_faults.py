"""An RT-DAC bench wired otherwise than its config guesses, over a spread of benches: how far each
fault gets before the safety supervisor ends it, against the same bench wired as configured.

Each case runs the real rtdac backend through pyusb's core against the emulated board in this process,
on the board's simulated clock, with the supervisor's default bounds on every cycle (as the loop runs
it). The spread: the road motor's gain (0.5x, 1x, 2x the config's feed-forward) and lag (10, 20, 50 ms),
road speeds of 0.3, 1 and 3 rad/s, and a host whose wiring is guessed (bring-up caps on) or wrongly
confirmed (no caps). Printed for each fault, worst case beside the median:

* **a road encoder reversed against the config**: how far the road's true angle got from its
  reference (target <= 0.1 rad), how long its output sat at its limit (target <= 0.1 s), whether the
  run tripped naming the road, and whether both outputs ended at rest;
* **a coil sense on an A/D that reads nothing**: the coil's largest duty over the map's duty for the
  command (target <= 1.25), whether the run tripped saying so;
* **the baseline**: the same road on the bench wired as configured, which must run through untripped.

    python tools/bench_rtdac_faults.py            # the whole spread
    python tools/bench_rtdac_faults.py --quick    # one bench per fault (seconds)
    python tools/bench_rtdac_faults.py --json out.json
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from sashil.config.frozen import freeze_config  # noqa: E402
from sashil.config.rtdac_section import WIRING_KEYS  # noqa: E402
from sashil.drivers import rig_parts  # noqa: E402
from sashil.drivers.emulator.board_clock import BoardClock  # noqa: E402
from sashil.drivers.emulator.rtdac_board import RoadMotor, RtdacBoard, build_board  # noqa: E402
from sashil.drivers.emulator.rtdac_usb import DirectPort, EmulatedUsbBackend  # noqa: E402
from sashil.drivers.interface import RigCommand  # noqa: E402
from sashil.drivers.rtdac_codec import READ_REQUEST  # noqa: E402
from sashil.drivers.rtdac_outputs import interp  # noqa: E402
from sashil.drivers.rtdac_rig import RtdacRig  # noqa: E402
from sashil.engine.resolve import default_config  # noqa: E402
from sashil.errors import SafetyTrip  # noqa: E402
from sashil.safety import SafetySupervisor  # noqa: E402

PERIOD_NS = 1_000_000


def bench(host: dict, truth: dict, motor: RoadMotor) -> tuple[RtdacRig, RtdacBoard, BoardClock]:
    """The host's rig on ``host``'s rtdac keys, the board wired as ``truth``, its road motor ``motor``."""
    raw = default_config()
    raw["rtdac"].update(host)
    clock = BoardClock()
    board = build_board(freeze_config(default_config()), wiring_changes=truth)
    board.motor = motor
    rig = RtdacRig.from_parts(rig_parts(freeze_config(raw), "rtdac"))
    rig.link.backend = EmulatedUsbBackend(DirectPort(board, clock))
    rig.monotonic, rig.sleep = clock.seconds, clock.sleep
    return rig, board, clock


def run(rig: RtdacRig, board: RtdacBoard, clock: BoardClock, cmd: RigCommand, seconds: float) -> dict:
    """``cmd`` each cycle under the supervisor until a trip or ``seconds``; then the bench watched 0.3 s
    more while it coasts at rest."""
    safety = SafetySupervisor(current_max_a=1.0)
    rig.configure()
    rig.activate()
    host = 0
    safety.start(host)
    reference = 0.0
    off = at_limit = 0.0
    duty_ratio = 0.0
    trip = ""
    for _ in range(round(seconds * 1e9 / PERIOD_NS)):
        clock.now += PERIOD_NS
        host += PERIOD_NS
        sample = rig.read(host, PERIOD_NS)
        try:
            safety.check(sample, host)
        except SafetyTrip as err:
            trip = str(err)
            break
        rig.write(safety.limit(cmd, PERIOD_NS), host, PERIOD_NS)
        reference = rig.road.reference_rad if rig.road.reference_rad is not None else reference
        off = max(off, abs(board.rig.plant.state.theta_road_rad - reference))
        at_limit += PERIOD_NS * 1e-9 if rig.road.at_limit else 0.0
        command = min(cmd.current_a, rig.current_max_a)  # the backend's command after its cap
        if command > 0.0:
            mapped = interp(command, rig.coil.map_current_a, rig.coil.map_output)  # the map's duty for it
            duty_ratio = max(duty_ratio, board.output("pwm", rig.wiring.coil_channel) / mapped)
    rig.deactivate()
    for _ in range(300):
        clock.now += PERIOD_NS
        board.bulk_write(0x02, READ_REQUEST, clock.now)
        board.bulk_read(0x84, 504, clock.now)
        off = max(off, abs(board.rig.plant.state.theta_road_rad - reference))
    at_rest = board.at_rest()
    rig.close()
    return {
        "road_off_rad": off,
        "road_at_limit_s": at_limit,
        "duty_ratio": duty_ratio,
        "trip": trip,
        "at_rest": at_rest,
    }


def cases(quick: bool) -> list[tuple[str, dict, dict, RoadMotor, RigCommand]]:
    """(fault, host keys, bench truth, motor, command) over the spread."""
    confirmed = {"confirmed": list(WIRING_KEYS), "coil_sense_ad": 0}
    gains = (2.0,) if quick else (1.0, 2.0, 4.0)  # rad/s per V: the config's feed-forward says 2
    lags = (0.02,) if quick else (0.01, 0.02, 0.05)
    speeds = (1.0,) if quick else (0.3, 1.0, 3.0)
    hosts = (("guessed", {}), ("wrongly confirmed", confirmed)) if not quick else (("guessed", {}),)
    out = []
    for gain, lag, speed, (name, host) in itertools.product(gains, lags, speeds, hosts):
        motor = RoadMotor(gain, lag)
        out.append(("reversed road", {**host, "_name": name}, {"road_reversed": True}, motor, RigCommand(0.0, speed)))
        out.append(("baseline road", {**host, "_name": name}, {}, motor, RigCommand(0.0, min(speed, 0.3))))
    currents = (0.4,) if quick else (0.1, 0.2, 0.3, 0.4, 0.8)
    for current in currents:
        host = {"confirmed": list(WIRING_KEYS), "coil_sense_ad": 3, "_name": "sense on A/D 3"}
        out.append(("dead sense", host, {"coil_sense_ad": 0}, RoadMotor(), RigCommand(current, None)))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="one bench per fault (seconds)")
    parser.add_argument("--json", metavar="FILE", help="write the figures, the commit and the load as JSON")
    args = parser.parse_args()
    results: dict[str, list[dict]] = {}
    for fault, host, truth, motor, cmd in cases(args.quick):
        name = host.pop("_name")
        rig, board, clock = bench(host, truth, motor)
        got = run(rig, board, clock, cmd, 2.0 if fault != "baseline road" else 1.0)
        got.update(host=name, motor_rad_s_per_v=motor.rad_s_per_output, lag_s=motor.tau_s)
        got.update(road_speed=cmd.road_speed_rad_s, current_a=cmd.current_a)
        results.setdefault(fault, []).append(got)
    load = os.getloadavg()[0]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT).stdout
    print(f"bench_rtdac_faults: commit {commit.strip() or '?'}, load average {load:.2f}; simulated time")
    for fault, runs in results.items():
        offs = [r["road_off_rad"] for r in runs]
        limits = [r["road_at_limit_s"] for r in runs]
        trips = sum(1 for r in runs if r["trip"])
        rest = sum(1 for r in runs if r["at_rest"])
        line = f"{fault}: {len(runs)} benches, tripped {trips}, at rest after {rest}"
        if fault != "dead sense":
            line += (
                f"; road off its reference median {statistics.median(offs):.3f} rad, worst {max(offs):.3f} rad"
                f"; output at its limit median {statistics.median(limits):.3f} s, worst {max(limits):.3f} s"
            )
        else:
            ratios = [r["duty_ratio"] for r in runs]
            line += f"; duty over the map's median {statistics.median(ratios):.3f}, worst {max(ratios):.3f}"
        print(line)
    reversed_ok = all(
        r["trip"] and "road" in r["trip"] and r["road_off_rad"] <= 0.1 and r["road_at_limit_s"] <= 0.1 and r["at_rest"]
        for r in results["reversed road"]
    )
    sense_ok = all(r["trip"] and r["duty_ratio"] <= 1.25 + 0.01 for r in results["dead sense"])  # a width step
    baseline_ok = not any(r["trip"] for r in results["baseline road"])
    print(
        f"targets: reversed road (trip naming the road, <= 0.1 rad, <= 0.1 s at the limit, at rest) "
        f"{'met' if reversed_ok else 'NOT met'}; dead sense (<= 1.25 x the map, tripped) "
        f"{'met' if sense_ok else 'NOT met'}; rightly wired benches untripped {'yes' if baseline_ok else 'NO'}"
    )
    if args.json:
        Path(args.json).write_text(
            json.dumps({"commit": commit.strip(), "load": load, "results": results}, indent=1), encoding="utf-8"
        )
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("bench_rtdac_faults", main))
