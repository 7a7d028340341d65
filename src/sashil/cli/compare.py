"""``sashil compare``: several laws on the same road, one table (compare.md, metrics.csv, compare.png).

Each ``--controller`` (a law name, ``package.module:Class`` or ``path/file.py:Class``; repeatable)
runs on the same road through the one runner (:mod:`sashil.experiments.compare`), beside the
passive damper at 0 A and at i_max, which are always included. ``--set controller.<p>=v`` goes to
every compared law that declares ``p``. Every law is checked before anything runs. On the simulated
rig on the virtual clock the laws may run in parallel processes (``--jobs``); on any other rig they
run one after another, the rig at rest (0 A, the road stopped) for ``compare.rest_s`` in between.
A law that fails or trips gets its row saying why; the others still run.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from typing import Any

from sashil.cli.common import (
    add_config_options,
    add_driver_options,
    add_output_options,
    add_verbosity_options,
    law_help,
    positive_seconds,
    resolve_config,
    say,
    setup_logging,
)
from sashil.config.overrides import apply_overrides, parse_override
from sashil.config.sections import CONTROLLER
from sashil.drivers import on_virtual_clock
from sashil.errors import ConfigError
from sashil.experiments.compare import LawJob, LawResult, run_job
from sashil.experiments.road_option import SYNTAX as ROAD_SYNTAX
from sashil.experiments.road_option import parse_road
from sashil.recording.compare_report import plot_compare, write_compare_md, write_metrics_csv
from sashil.recording.run_folder import RunFolder

EXAMPLE = "sashil compare --road iso8608:C --duration 30 --controller skyhook-add --controller clipped-optimal"
DEFAULT_ROAD = "iso8608:C"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_options(parser)
    add_driver_options(parser)
    parser.add_argument(
        "--controller",
        action="append",
        default=[],
        dest="laws",
        metavar="LAW",
        help=f"a law to compare (repeatable; passive at 0 A and at i_max are always included): {law_help()}",
    )
    parser.add_argument(
        "--road", metavar="SPEC", help=f"the road every law runs on: {ROAD_SYNTAX} (default {DEFAULT_ROAD})"
    )
    parser.add_argument("--duration", type=float, default=30.0, metavar="S", help="seconds per law (default 30)")
    parser.add_argument(
        "--jobs", type=int, metavar="N", help="simulated rig: laws in N processes (default compare.jobs)"
    )
    add_output_options(parser)
    add_verbosity_options(parser)


def split_sets(overrides: list[str]) -> tuple[list[str], list[tuple[str, str]]]:
    """``--set`` items for the base config, and ``(param, item)`` for the laws' own parameters."""
    base, law_sets = [], []
    for item in overrides:
        path, _ = parse_override(item)
        if path == ["controller", "law"]:
            raise ConfigError(f"--set {item}: sashil compare takes its laws from --controller (repeatable)")
        if len(path) == 2 and path[0] == "controller" and path[1] not in CONTROLLER.fields:
            law_sets.append((path[1], item))
        else:
            base.append(item)
    return base, law_sets


def law_config(
    base: dict[str, Any], spec: str, law_sets: list[tuple[str, str]], extra: Sequence[str] = ()
) -> dict[str, Any]:
    """``base`` running law ``spec`` with the ``--set`` parameters it declares (checked: ConfigError
    naming --controller and the key)."""
    from sashil.control.law_registry import find_law

    try:
        declared = find_law(spec).cls.params()
        mine = [item for key, item in law_sets if key in declared]
        return apply_overrides(base, [f"controller.law={spec}", *mine, *extra], "--set")
    except ConfigError as err:
        raise ConfigError(f"--controller {spec}: {err}") from None


def build_jobs(
    base: dict[str, Any], laws: list[str], law_sets: list[tuple[str, str]], road: str, duration: float
) -> list[LawJob]:
    """The references (passive at 0 A and i_max) and each law, every config checked."""
    from sashil.control.law_registry import find_law

    i_max = float(base["rig"]["current_max_a"])
    jobs: dict[str, LawJob] = {}
    for current in (0.0, i_max):
        config = law_config(base, "passive", [], [f"controller.current_a={current}"])
        jobs.setdefault(f"passive {current:g} A", LawJob(f"passive {current:g} A", config, road, duration))
    used: set[str] = set()
    for spec in laws:
        config = law_config(base, spec, law_sets)
        name = find_law(spec).cls.name or spec
        used |= set(find_law(spec).cls.params())
        label = f"passive {config['controller']['current_a']:g} A" if name == "passive" else name
        jobs.setdefault(label, LawJob(label, config, road, duration))
    for key, item in law_sets:
        if key not in used:
            raise ConfigError(
                f"--set {item}: none of the compared laws ({', '.join(laws) or 'none'}) has a parameter {key}"
            )
    return list(jobs.values())


def run_jobs(
    jobs: list[LawJob], processes: int, rest_s: float, virtual: bool, args: argparse.Namespace
) -> list[LawResult]:
    """Run the jobs: in ``processes`` processes on the virtual clock, else one after another with
    the rig at rest for ``rest_s`` between them."""
    if virtual and processes > 1:
        # fork: a worker starts at once with the parent's imports, and no resource-tracker process
        # outlives the pool (spawn's would); the parent runs no thread at this point
        with ProcessPoolExecutor(max_workers=processes, mp_context=get_context("fork")) as pool:
            results = list(pool.map(run_job, jobs))
        for r in results:
            say(args, f"sashil compare: {r.label}: {r.status} ({r.wall_s:.1f} s)")
        return results
    results = []
    for i, job in enumerate(jobs):
        if i and not virtual and rest_s > 0:
            time.sleep(rest_s)  # the runner left the rig at 0 A with the road stopped: let it settle
        result = run_job(job)
        say(args, f"sashil compare: {result.label}: {result.status} ({result.wall_s:.1f} s)")
        results.append(result)
    return results


def accel_note(results: list[LawResult], bandwidth_hz: float) -> str:
    """How θ̈2 was measured (the simulated plant's own, or the encoders'), for compare.md."""
    sources = {r.accel_source for r in results if r.ok}
    how = {
        "plant": "the simulated plant's own, (−k·θ − T)/J of its true state",
        "encoders": "the arm angle θ2 = θ + θ1 from the encoders, differentiated twice",
    }
    text = "; ".join(how[s] for s in sorted(sources)) or "none measured"
    return (
        f"θ̈2: {text}, low-passed at {bandwidth_hz:g} Hz. The road-side torque k·θ + T equals −J·θ̈2 on this "
        "rig (seed 001 eq. 13, the road side driven), so it ranks the laws as comfort does."
    )


def compute_bound(config: dict[str, Any], road: Any, duration: float, args: argparse.Namespace) -> Any:
    """The optimal bound on this road for the config's model (None without a road, or when the run
    is shorter than the settling time)."""
    from sashil.experiments.optimal_bound import optimal_bound
    from sashil.models.hysteresis import BoucWenParams

    settle = float(config["compare"]["settle_s"])
    if road is None or duration <= settle:
        return None
    params = BoucWenParams.from_mapping(config["model"]["params"])
    start = time.perf_counter()
    bound = optimal_bound(params, float(config["rig"]["current_max_a"]), road, duration, settle)
    say(
        args,
        f"sashil compare: optimal bound {bound.gain_pct:.1f} % below passive ({time.perf_counter() - start:.1f} s)",
    )
    return bound


def run(args: argparse.Namespace) -> int:
    setup_logging(args)
    base_sets, law_sets = split_sets(list(args.overrides))
    ns = argparse.Namespace(**{**vars(args), "overrides": base_sets})
    base = resolve_config(ns)
    duration = positive_seconds("--duration", args.duration)
    road = args.road or DEFAULT_ROAD
    parse_road(road, base)  # a bad road is one line before anything runs
    processes = int(base["compare"]["jobs"] if args.jobs is None else args.jobs)
    if processes < 1:
        raise ConfigError(f"--jobs: expected a number of processes >= 1, got {processes}")
    jobs = build_jobs(base, list(args.laws), law_sets, road, duration)
    virtual = on_virtual_clock(base)
    if not virtual:
        processes = 1
    folder = RunFolder.create(args.out, "compare")
    folder.write_config(base)
    say(
        args,
        f"sashil compare: {len(jobs)} laws, road {road}, {duration:g} s each, {processes} process(es) -> {folder.path}",
    )
    start = time.perf_counter()
    results = run_jobs(jobs, processes, float(base["compare"]["rest_s"]), virtual, args)
    wall = time.perf_counter() - start
    road_profile, road_text = parse_road(road, base)
    section = base["compare"]
    bound = compute_bound(base, road_profile, duration, args)
    header = {
        "road": f"`{road}`: {road_text}",
        "duration": f"{duration:g} s per law, the first {section['settle_s']:g} s left out of the metrics",
        "rig": f"{base['driver']['name']} ({'virtual clock' if virtual else 'real clock'}), {base['loop']['rate_hz']:g} Hz",
        "wall time": f"{wall:.1f} s for {len(jobs)} laws in {processes} process(es)",
    }
    if bound is not None:
        header["optimal bound"] = (
            f"RMS θ̈2 {bound.rms_accel_bound:.4g} rad/s² against {bound.rms_accel_passive:.4g} for the best constant "
            f"damping ({bound.c_passive:.3g} N m s/rad), {bound.gain_pct:.1f} % below it, in the model's viscous "
            "envelope (the hysteretic term left out), knowing the road in advance"
        )
    notes = [
        accel_note(results, float(section["accel_bandwidth_hz"])),
        f"Coil energy: R·∫i² dt with R = {section['coil_resistance_ohm']:g} Ω (compare.coil_resistance_ohm).",
        "θ̈2 vs best passive: 1 − RMS θ̈2 / that of the best constant current run (positive: better).",
        "Share of the bound: the law's gain over the best passive run as a share of the optimal bound's gain over "
        "the best constant damping (sashil.experiments.optimal_bound: direct transcription on the viscous "
        "envelope, the damping of every millisecond free in [c1, c1 + c2·i_max], L-BFGS-B on the exact "
        "adjoint gradient; the best of two starts, not a certificate). 100 %: all the bound allows.",
    ]
    gain = bound.gain_pct if bound is not None else float("nan")
    write_metrics_csv(folder.file("metrics.csv"), results, gain)
    write_compare_md(folder.file("compare.md"), results, header, notes, gain)
    plot_compare(folder.file("compare.png"), results)
    failed = [r for r in results if not r.ok]
    say(args, f"sashil compare: {wall:.1f} s of wall time")
    print(f"compare folder: {folder.path}", file=sys.stderr)
    if failed:
        print(
            f"sashil compare: {len(failed)} of {len(results)} laws did not finish: "
            + "; ".join(f"{r.label}: {r.status}" for r in failed),
            file=sys.stderr,
        )
        return 1
    return 0
