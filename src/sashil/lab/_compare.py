"""``sashil compare`` as a library function: several laws on the same road, one table
(``compare.md``, ``metrics.csv``, ``compare.png``).

Each law runs on the road ``compare.road`` for ``compare.duration_s`` through the one runner, beside
the passive damper at constant currents: on a simulated rig 0 A, i_max and the best constant current
a bounded search finds; on any other rig the currents ``compare.passive_currents_a`` lists. The best
constant current is the passive baseline of every gain and share (:mod:`sashil.lab.passive_baseline`),
and the optimal bound on the rig's model (:mod:`sashil.lab.hysteretic_bound`) their 100 %. Every law is checked before anything runs. On the simulated rig on the virtual clock the
laws may run in ``compare.jobs`` parallel processes; on any other rig they run one after another,
the rig at rest (0 A, the road stopped) for ``compare.rest_s`` in between, and a law whose host paused
longer than ``compare.max_pause_ms`` runs again (:mod:`sashil.lab.compare_pauses`). A law that fails
or trips gets its row saying why; the others still run.

A :class:`LawJob` is one law's run: its label, its checked config (``controller.law`` and its
parameters), the road spec, the duration and its run folder. :func:`run_job` builds the law's stage
(:func:`sashil.control.registry.make_stage`: the controller, or a constant-current stage for a law
that reads no state, such as ``passive``), wraps it in the road
(:class:`~sashil.roads.option.RoadStage`: the road motor's speed each cycle), runs it with
:func:`sashil.runtime.runner.run_plan`, streaming every cycle into the folder's ``data.csv`` (and
its loop timing into ``timing.npz``), and derives the metrics from the stream. A job is picklable,
so on the simulated rig jobs may run in parallel processes; the caller writes each folder's
``config.yaml`` before and its ``summary.json`` after (:attr:`LawResult.summary`).

Metrics, after ``compare.settle_s``:

* comfort: RMS of the arm's angular acceleration θ̈2 low-passed at ``compare.accel_bandwidth_hz``
  (4th-order Butterworth, forward and back). On a simulated rig θ̈2 is the plant's own,
  (−k·θ − T)/J of its true state (seed 001 eq. 13), recorded every cycle as
  ``arm_accel_true_rad_s2``; on any other rig it is the arm encoder's angle θ2 = θ + θ1, a cubic
  spline through its edges (each count change an exact angle at its own device time), differentiated
  twice, then low-passed, on a uniform grid of the samples' own device time (a link loses samples and
  repeats one when a cycle reads nothing new; a grid of the rows would read those as jumps)
  (:func:`sashil.lab.compare_metrics.arm_acceleration`). Over the emulated serial link it reads the
  emulator's true θ̈2 0–2 % low in RMS (30 s runs), where the arm moves slowly and its edges lie
  further apart than the band's shortest period; through the samples' counts alone (a stream
  without the edge columns) a 4096-count encoder adds a floor of about 0.8–1.1 rad/s² RMS in
  quadrature at 20 Hz, the same for every law;
* travel: RMS of the relative angle θ;
* peak measured current, and the energy to the coil R·∫i² dt (R = ``compare.coil_resistance_ohm``).
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil import engine
from sashil.api import Run, load_run
from sashil.config.frozen import freeze, thaw
from sashil.config.overrides import parse_override
from sashil.config.parts import RigParts, RunSpec, StageParts
from sashil.config.sections import CONTROLLER
from sashil.control.law_config import reads_road_ahead
from sashil.control.law_registry import find_law
from sashil.control.registry import law_run_label, make_stage
from sashil.drivers import open_rig
from sashil.drivers.interface import capabilities_of
from sashil.engine import assemble
from sashil.engine.checks import check_road_ahead
from sashil.engine.events import Event, Listener, ignore
from sashil.engine.resolve import apply_overrides
from sashil.errors import ConfigError, SashilError
from sashil.lab.compare_metrics import METRICS, LawResult, metrics_of
from sashil.lab.compare_pauses import PausePolicy, paused_note, run_unpaused
from sashil.lab.compare_report import (
    BOUND_TOLERANCE_PTS,
    Scale,
    above_bound,
    plot_compare,
    shares_of_bound,
    write_compare_md,
    write_metrics_csv,
)
from sashil.lab.hysteretic_bound import HystereticBound, bound_on_chain, find_bound, model_passive
from sashil.lab.passive_baseline import Baseline, best_constant_current, passive_label
from sashil.models.hysteresis import BoucWenParams
from sashil.recording.outputs import Outputs
from sashil.roads.option import RoadParts, RoadStage, parse_road
from sashil.runtime.loop import stage_signals
from sashil.writer.documents import Documents
from sashil.writer.folder_writer import FolderWriter, ending
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = [
    "CompareLaw",
    "LawJob",
    "LawResult",
    "MeasuredStage",
    "compare",
    "compare_bound",
    "folder_name",
    "law_parameters",
    "law_summary",
    "laws_of",
    "metrics_of",
    "own_law",
    "passive_baseline",
    "plant_bound",
    "run_job",
    "scale_bound",
    "split_sets",
]

#: the comparison's own values (``{name: config key}``), read once by the engine into each run's
#: ``options``: the ``compare`` section and what its road is made with
READS = {
    **{
        key: f"compare.{key}"
        for key in (
            "road",
            "duration_s",
            "jobs",
            "rest_s",
            "max_pause_ms",
            "repeats",
            "settle_s",
            "accel_bandwidth_hz",
            "coil_resistance_ohm",
            "passive_currents_a",
        )
    },
    **RoadParts.READS,
}


@dataclass(frozen=True)
class CompareLaw:
    """One law to compare, as ``--controller`` and ``--set`` give it: ``law`` (a registered name,
    ``package.module:Class`` or ``path/file.py:Class``) and ``sets``, its parameters as
    ``controller.<param>=value`` texts (YAML values, checked by the law's ``Param``s)."""

    law: str
    sets: Sequence[str] = ()


def split_sets(overrides: Sequence[str]) -> tuple[list[str], list[tuple[str, str]]]:
    """``--set`` items for the base config, and ``(param, item)`` for the laws' own parameters
    (``controller.<p>`` that is not a key of the controller section)."""

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


def laws_of(specs: Sequence[str], law_sets: Sequence[tuple[str, str]]) -> list[CompareLaw]:
    """The laws of repeated ``--controller``, each with the ``--set`` items (from :func:`split_sets`)
    of the parameters it declares; ConfigError for an unknown law, or an item no law declares."""

    laws, used = [], set()
    for spec in specs:
        try:
            declared = find_law(spec).cls.params()
        except ConfigError as err:
            raise ConfigError(f"--controller {spec}: {err}") from None
        used |= set(declared)
        laws.append(CompareLaw(spec, tuple(item for key, item in law_sets if key in declared)))
    for key, item in law_sets:
        if key not in used:
            raise ConfigError(
                f"--set {item}: none of the compared laws ({', '.join(specs) or 'none'}) has a parameter {key}"
            )
    return laws


def _law_config(base: Mapping[str, Any], law: CompareLaw, extra: Sequence[str] = ()) -> Any:
    """``base`` running ``law`` with its parameters, checked (ConfigError naming --controller and
    the key) and read-only. Parameters of another law that ``base`` holds (a law's own config.yaml
    given back with --config) are left out."""

    try:
        declared = find_law(law.law).cls.params()  # an unknown law named as such, before its parameters
        doc = thaw(base)  # the law's own config document, written to its folder's config.yaml
        section = doc.get("controller") or {}
        for key in [k for k in section if k not in CONTROLLER.fields and k not in declared]:
            del section[key]
        return freeze(apply_overrides(doc, [f"controller.law={law.law}", *law.sets, *extra], "--set"))
    except ConfigError as err:
        raise ConfigError(f"--controller {law.law}: {err}") from None


def folder_name(label: str) -> str:
    """A law's sub-folder in the compare folder: its label with what a file name should not hold
    replaced (``passive 0 A`` -> ``passive-0A``)."""
    text = re.sub(r"(\d) A$", r"\1A", label)
    return re.sub(r"[^A-Za-z0-9._+-]+", "-", text).strip("-.") or "law"


def own_law(config: RunConfig) -> list[CompareLaw]:
    """The config's own law when it is not passive (a compared law's config.yaml given back with
    --config), as the law to compare when none is named."""
    law = StageParts.read(config).law
    return [] if law == "passive" else [CompareLaw(law)]


def reference_currents(run: RunSpec) -> list[float]:
    """The constant currents compare runs as rows of its table: 0 A and i_max on a simulated rig (the
    ends of the baseline's search), else those ``compare.passive_currents_a`` lists (ConfigError for
    a current outside [0, rig.current_max_a], or none)."""
    i_max = run.stage.current_max_a
    if run.virtual:
        return [0.0, i_max]
    listed = [float(c) for c in run.options["passive_currents_a"]]
    if not listed:
        raise ConfigError("compare.passive_currents_a: give at least one constant current for the passive baseline")
    for current in listed:
        if not 0.0 <= current <= i_max:
            raise ConfigError(
                f"compare.passive_currents_a: {current:g} A is outside [0, rig.current_max_a = {i_max:g} A]"
            )
    return listed


def passive_job(base: Mapping[str, Any], current: float, road: str, duration: float) -> LawJob:
    """The passive damper at ``current`` on the road, its config checked."""
    config = _law_config(base, CompareLaw("passive"), [f"controller.current_a={current!r}"])
    return LawJob(passive_label(current), config, road, duration)


def _jobs(
    base: Mapping[str, Any], currents: Sequence[float], laws: Sequence[CompareLaw], road: str, duration: float
) -> list[Any]:
    """The references (the passive damper at each of ``currents``) and each law, every config checked."""

    jobs: dict[str, LawJob] = {}
    for current in currents:
        job = passive_job(base, current, road, duration)
        jobs.setdefault(job.label, job)
    for law in laws:
        config = _law_config(base, law)
        label = law_run_label(StageParts.read(config))
        jobs.setdefault(label, LawJob(label, config, road, duration))
    return list(jobs.values())


def law_parameters(result: Any, config: RunConfig) -> dict[str, Any]:
    """The parameters a law ran with: the law's own values as its run reported them
    (``controller_stats.law.parameters``), else those its config gives (each declared parameter,
    its default when unset); the passive stage's current."""

    stats = (result.summary or {}).get("controller_stats") or {}
    reported = (stats.get("law") or {}).get("parameters") if isinstance(stats, Mapping) else None
    if isinstance(reported, Mapping):
        return dict(reported)
    stage = StageParts.read(config)
    declared = find_law(stage.law).cls.params()
    return {key: stage.controller.params.get(key, param.default) for key, param in declared.items()}


def law_summary(result: Any, config: RunConfig, road_text: str, duration: float) -> dict[str, Any]:
    """A compared law's own summary.json: the runner's keys of its run, the law (name, origin,
    parameters) and its metrics (also as its one entry of ``runs``)."""

    entry = find_law(StageParts.read(config).law)
    common = dict(result.summary)
    if not common:  # the law never started: its status says why
        common = {"exit_status": "error", "exit_code": 1}
    if not result.ok:
        common["error"] = common.get("error") or result.status
        if common.get("exit_status") == "ok":
            common["exit_status"], common["exit_code"] = "error", 1
    return {
        **common,
        "verb": "compare",
        "driver": RigParts.backend_of(config),
        "controller": result.label,
        "controller_origin": entry.origin,
        "parameters": law_parameters(result, config),
        "road": road_text,
        "duration_s": duration,
        "status": result.status,
        "accel_source": result.accel_source,
        "pauses_ms": result.pauses_ms,
        "metrics": result.metrics,
        "runs": [{"folder": ".", "controller": result.label, **result.metrics}],
    }


def _run_jobs(
    jobs: list[Any], processes: int, rest_s: float, virtual: bool, on_event: Listener, policy: PausePolicy
) -> list[Any]:
    """Run the jobs: in ``processes`` processes on the virtual clock, else one after another with
    the rig at rest for ``rest_s`` between them, each run again while its host paused longer than
    ``policy`` allows (:func:`~sashil.lab.compare_pauses.run_unpaused`)."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    def done(result: Any) -> None:
        on_event(
            Event(
                "progress",
                f"sashil compare: {result.label}: {result.status} ({result.wall_s:.1f} s)",
                {"law": result.label, "status": result.status},
            )
        )

    if virtual and processes > 1:
        # fork: a worker starts at once with the parent's imports, and no resource-tracker process
        # outlives the pool (spawn's would); the parent runs no thread at this point
        with ProcessPoolExecutor(max_workers=processes, mp_context=get_context("fork")) as pool:
            results = list(pool.map(run_job, jobs))
        for result in results:
            done(result)
        return results

    def rest() -> None:
        if not virtual and rest_s > 0:
            time.sleep(rest_s)  # the runner left the rig at 0 A with the road stopped: let it settle

    results = []
    for i, job in enumerate(jobs):
        if i:
            rest()
        result = run_job(job) if virtual else run_unpaused(partial(run_job, job), rest, policy, on_event)
        done(result)
        results.append(result)
    return results


def _accel_note(results: list[Any], bandwidth_hz: float) -> str:
    """How θ̈2 was measured (the simulated plant's own, or the encoders'), for compare.md."""
    sources = {r.accel_source for r in results if r.ok}
    how = {
        "plant": "the simulated plant's own, (−k·θ − T)/J of its true state",
        "encoders": "the arm angle θ2 = θ + θ1 from the encoders, differentiated twice",
    }
    text = "; ".join(how[s] for s in sorted(sources)) or "none measured"
    return (
        f"θ̈2: {text}, low-passed at {bandwidth_hz:g} Hz. The road-side torque k·θ + T equals −J·θ̈2 on this "
        "rig (Iskandarani & Karimi 2011, eq. 13, the road side driven), so it is not a second measure: J times RMS θ̈2."
    )


def passive_baseline(
    config: RunConfig, run: RunSpec, road: str, duration: float, known: Mapping[float, LawResult] | None = None
) -> Baseline:
    """The passive baseline of the comparison (:func:`sashil.lab.passive_baseline.best_constant_current`):
    on the virtual clock a bounded search over [0, i_max], each current a run of the same road and seed;
    else the best of ``compare.passive_currents_a``. ``known``: the reference rows already run, by
    current."""

    def run_current(current: float) -> LawResult:
        return run_job(passive_job(config, current, road, duration))

    listed = None if run.virtual else reference_currents(run)
    return best_constant_current(run_current, run.stage.current_max_a, listed, dict(known or {}))


def _bound_of(run: RunSpec, params: BoucWenParams, coil_tau_s: float, road: Any, duration: float) -> HystereticBound:
    """The optimal bound (:func:`sashil.lab.hysteretic_bound.find_bound`) of the damper ``params`` on
    the road, its cost over the metric's window, θ̈2 low-passed as the metric is."""
    return find_bound(
        params,
        run.stage.current_max_a,
        coil_tau_s,
        road,
        duration,
        float(run.options["settle_s"]),
        bandwidth_hz=float(run.options["accel_bandwidth_hz"]),
    )


def compare_bound(run: RunSpec, road: Any, duration: float, on_event: Listener = ignore) -> HystereticBound | None:
    """The optimal bound on this road for the run's model, the controller's (None without a road,
    or when the run is no longer than the settling time)."""
    if road is None or duration <= float(run.options["settle_s"]):
        return None
    start = time.perf_counter()
    bound = _bound_of(run, BoucWenParams.from_mapping(run.stage.model.params), run.stage.coil_tau_s, road, duration)
    on_event(
        Event(
            "progress",
            f"sashil compare: optimal bound RMS θ̈2 {bound.rms_accel_bound:.4g} rad/s², its {len(bound.starts)} starts "
            f"{bound.spread:.2g} apart ({time.perf_counter() - start:.1f} s)",
            {"rms_accel_bound": bound.rms_accel_bound, "spread": bound.spread},
        )
    )
    return bound


def plant_bound(config: RunConfig, run: RunSpec, road: Any, duration: float) -> HystereticBound | None:
    """The optimal bound of the true plant where it is known and is not the controller's model: a
    simulated rig whose ``mismatch`` section moves the plant's parameters or its coil's lag (None
    elsewhere, or without a road)."""
    from sashil.drivers.mismatch import plant_parts

    if run.rig.backend != "sim" or road is None or duration <= float(run.options["settle_s"]):
        return None
    parts = run.rig
    if parts.model is None or parts.rig is None:
        return None
    model, rig = plant_parts(parts.model, parts.rig, parts.mismatch)
    params = BoucWenParams.from_mapping(model.params)
    if params == BoucWenParams.from_mapping(run.stage.model.params) and rig.coil_tau_s == run.stage.coil_tau_s:
        return None
    return _bound_of(run, params, rig.coil_tau_s, road, duration)


def scale_bound(run: RunSpec, road: Any, duration: float, bound_rms: float, baseline: Baseline) -> float:
    """The 100 % of the shares' scale: the bound's RMS θ̈2 ``bound_rms`` where the runs' θ̈2 is the
    plant's own, and the bound put on the encoders' chain where it is theirs (:func:`bound_on_chain`,
    with the model's passive run at the baseline's current), so both ends and the laws are read on
    one chain. NaN without a bound."""
    if not math.isfinite(bound_rms) or baseline.result.accel_source != "encoders":
        return bound_rms
    model = model_passive(
        BoucWenParams.from_mapping(run.stage.model.params),
        baseline.current_a,
        run.stage.coil_tau_s,
        road,
        duration,
        float(run.options["settle_s"]),
        bandwidth_hz=float(run.options["accel_bandwidth_hz"]),
    )
    return bound_on_chain(bound_rms, baseline.rms_accel, model)


def compare(
    config: RunConfig, laws: Sequence[CompareLaw | str], outputs: Outputs | None = None, on_event: Listener = ignore
) -> Run:
    """Compare ``laws`` (each a :class:`CompareLaw`, or a law spec without parameters) on the road
    of a resolved ``config`` (:func:`sashil.engine.resolve.resolve` with verb ``compare``: the
    ``compare`` section) into a new folder, beside the passive references, and return it as a
    :class:`~sashil.api.Run`: ``metrics.csv`` (:attr:`~sashil.api.Run.tables` ``["metrics"]``),
    ``compare.md``, ``compare.png``, and ``summary.json`` with each law's status and metrics under
    ``laws``. Each law's run is a run folder of its own inside it (:attr:`~sashil.api.Run.runs`;
    ``summary.json`` ``runs``): ``config.yaml`` with the law and its parameters, ``data.csv``,
    ``timing.npz`` and ``summary.json``. With no ``laws``, the config's own law is compared (unless it
    is passive): a compared law's ``config.yaml`` compares that law again.

    Bad input (an unknown law, a parameter its ``Param`` refuses) raises ConfigError before any
    folder exists. A law that fails or trips does not raise: its row says why, the summary ends
    ``error`` (exit code 1) naming it, and a ``warning`` event says so."""

    outputs = outputs if outputs is not None else Outputs()
    run = assemble(config, reads=READS)
    outputs.check(run.rig.backend)
    section = run.options
    road, duration = str(section["road"]), float(section["duration_s"])
    chosen = [law if isinstance(law, CompareLaw) else CompareLaw(law) for law in laws] or own_law(config)
    for law in chosen:  # a law that reads the road ahead needs the road: refused before anything is written
        check_road_ahead(config, "compare", str, law.law, reads_road_ahead(law.law))
    currents = reference_currents(run)
    jobs = _jobs(config, currents, chosen, road, duration)
    virtual = run.virtual
    processes = int(section["jobs"]) if virtual else 1
    road_profile, road_text = parse_road(road, RoadParts.of(section))
    folder, subs, documents = _folders(outputs, config, jobs)
    on_event(
        Event(
            "progress",
            f"sashil compare: {len(jobs)} laws, road {road}, {duration:g} s each, {processes} process(es) -> {folder.path}",
            {"folder": str(folder.path)},
        )
    )
    start = time.perf_counter()
    policy = PausePolicy.of(section)
    results = _run_jobs(jobs, processes, float(section["rest_s"]), virtual, on_event, policy)
    configs = {job.label: job.config for job in jobs}
    baseline = _baseline_row(config, run, jobs, results, folder, subs, documents, on_event)
    if baseline is not None and baseline.label not in configs:  # the searched current: a row of its own
        jobs.append(passive_job(config, baseline.current_a, road, duration))
        configs[baseline.label] = jobs[-1].config
    wall = time.perf_counter() - start
    summaries = {r.label: law_summary(r, configs[r.label], f"{road}: {road_text}", duration) for r in results}
    for label, summary in summaries.items():
        documents.summary(folder_name(label), summary)
    bound = compare_bound(run, road_profile, duration, on_event)
    plant = plant_bound(config, run, road_profile, duration)
    scale = Scale()
    if baseline is not None:
        rms = bound.rms_accel_bound if bound is not None else math.nan
        plant_rms = plant.rms_accel_bound if plant is not None else math.nan
        scale = Scale(
            baseline.label,
            baseline.rms_accel,
            scale_bound(run, road_profile, duration, rms, baseline),
            scale_bound(run, road_profile, duration, plant_rms, baseline),
        )
    header = _header(run, road, road_text, duration, virtual, processes, len(results), wall, bound, baseline, scale)
    notes = _notes(results, section, policy)
    params = {label: summary["parameters"] for label, summary in summaries.items()}
    folders = {label: sub.path.name for label, sub in subs.items()}
    write_metrics_csv(folder.file("metrics.csv"), results, scale)
    write_compare_md(folder.file("compare.md"), results, header, notes, scale, params, folders)
    plot_compare(folder.file("compare.png"), results, f"{road}: {road_text}", scale)
    error = _failures(results)
    figures = Figures(bound, plant, baseline, scale)
    documents.summary(
        None,
        _summary(run, error, f"{road}: {road_text}", duration, processes, wall, results, summaries, folders, figures),
    )
    on_event(Event("progress", f"sashil compare: {wall:.1f} s of wall time", {"wall_s": wall}))
    on_event(Event("folder", f"compare folder: {folder.path}", {"folder": str(folder.path)}))
    if error is not None:
        on_event(Event("warning", f"sashil compare: {error}", {"failed": [r.label for r in results if not r.ok]}))
    return load_run(folder.path)


def _baseline_row(
    config: RunConfig,
    run: RunSpec,
    jobs: list[Any],
    results: list[LawResult],
    folder: RunFolder,
    subs: dict[str, RunFolder],
    documents: Documents,
    on_event: Listener,
) -> Baseline | None:
    """The passive baseline (:func:`passive_baseline`) from the reference rows already run; a searched
    current that is not one of them is run once more into a run folder of its own, its row appended
    to ``results`` (the same road and seed: the same metrics as the search's run). None when no
    constant current finished (the rows say why)."""
    road, duration = str(run.options["road"]), float(run.options["duration_s"])
    known = {}
    for job, result in zip(jobs, results, strict=True):
        stage = StageParts.read(job.config)
        if stage.law == "passive":
            known[float(stage.controller.params["current_a"])] = result
    try:
        baseline = passive_baseline(config, run, road, duration, known)
    except RuntimeError:
        return None
    on_event(
        Event(
            "progress",
            f"sashil compare: passive baseline {baseline.current_a:g} A, RMS θ̈2 {baseline.rms_accel:.4g} "
            f"({baseline.method}: {len(baseline.evaluated)} runs)",
            {"current_a": baseline.current_a},
        )
    )
    if baseline.label in {r.label for r in results}:
        return baseline
    job = passive_job(config, baseline.current_a, road, duration)
    documents.start(folder_name(job.label), job.config)  # its folder's writer creates it, config.yaml in it
    sub = RunFolder(folder.path / folder_name(job.label), "compare")
    job.folder, subs[job.label] = str(sub.path), sub
    row = run_job(job)
    results.append(row)
    return replace(baseline, result=row) if row.ok else baseline


def _failures(results: Sequence[LawResult]) -> SashilError | None:
    """The error of a comparison some of whose laws did not finish (None: every one did)."""
    failed = [r for r in results if not r.ok]
    if not failed:
        return None
    return SashilError(
        f"{len(failed)} of {len(results)} laws did not finish: " + "; ".join(f"{r.label}: {r.status}" for r in failed)
    )


def _folders(
    outputs: Outputs, config: RunConfig, jobs: Sequence[Any]
) -> tuple[RunFolder, dict[str, RunFolder], Documents]:
    """The comparison's folder (its config.yaml says which laws' folders ran what) and each law's
    run folder inside it, its config.yaml written now (``data.csv`` comes as it runs); the
    comparison's documents, which its folder's writer takes."""
    folder = RunFolder.create(outputs.out, "compare")
    writer = FolderWriter(folder, "compare", {})
    documents = Documents([writer])
    note = (
        "The config every law of this comparison started from: its controller section is not one of them.\n"
        "Each law ran with the config.yaml of its own folder: "
        + ", ".join(f"{folder_name(job.label)}/" for job in jobs)
    )
    documents.start(None, config, note=note)
    subs = {}
    for job in jobs:  # each law a run of its own: its folder, config.yaml now, data.csv as it runs
        sub = writer.folder_for(folder_name(job.label))
        documents.start(folder_name(job.label), job.config)
        job.folder, subs[job.label] = str(sub.path), sub
    return folder, subs, documents


@dataclass(frozen=True)
class Figures:
    """What a comparison measures beside its rows: the bound on the controller's model, the true
    plant's (None where it is not known, or is the model), the passive baseline and the scale of the
    shares (:class:`~sashil.lab.compare_report.Scale`)."""

    bound: HystereticBound | None
    plant: HystereticBound | None
    baseline: Baseline | None
    scale: Scale

    @property
    def gain_pct(self) -> float:
        """How far the bound lies below the passive baseline, on the runs' chain [%]."""
        return 100.0 * (1.0 - self.scale.bound / self.scale.passive) if self.scale.passive > 0.0 else math.nan


def _starts_text(bound: HystereticBound) -> str:
    """Each start's optimum and their spread, for compare.md."""
    each = ", ".join(f"{name} {value:.4g}" for name, value in bound.starts.items())
    return f"its starts' optima {each} rad/s², {bound.spread:.2g} apart ({bound.spread_pct:.2g} % of its gap)"


def _header(
    run: RunSpec,
    road: str,
    road_text: str,
    duration: float,
    virtual: bool,
    processes: int,
    laws: int,
    wall: float,
    bound: HystereticBound | None,
    baseline: Baseline | None,
    scale: Scale,
) -> dict[str, str]:
    """The lines at the head of ``compare.md``: the road, the duration, the rig, the wall time, the
    passive baseline and how it was found, the bound and its starts, the shares' tolerance, the
    shares' scale where it is not the bound's own, and the true plant's bound where it is known."""
    section = run.options
    header = {
        "road": f"`{road}`: {road_text}",
        "duration": f"{duration:g} s per law, the first {section['settle_s']:g} s left out of the metrics",
        "rig": f"{run.rig.backend} ({'virtual clock' if virtual else 'real clock'}), {run.loop.rate_hz:g} Hz",
        "wall time": f"{wall:.1f} s for {laws} laws in {processes} process(es)",
    }
    if baseline is not None:
        header["passive baseline"] = (
            f"{baseline.describe(run.stage.current_max_a)}; RMS θ̈2 {baseline.rms_accel:.4g} rad/s², the 0 % of "
            "every gain and share"
        )
    if bound is not None:
        header["optimal bound"] = (
            f"RMS θ̈2 {bound.rms_accel_bound:.4g} rad/s², knowing the road in advance, on the controller's model "
            f"(its Bouc-Wen state and the coil's lag, θ̈2 low-passed and windowed as measured here); "
            f"{_starts_text(bound)}; the model's best constant current {bound.passive_current_a:.3g} A gives "
            f"{bound.rms_accel_passive:.4g}"
        )
        header["tolerance"] = (
            f"a share above 100 % by more than {BOUND_TOLERANCE_PTS:g} points is flagged (⚠): the bound's model "
            "is not the rig's there, or its search missed"
        )
        if math.isfinite(scale.bound) and scale.bound != bound.rms_accel_bound:
            header["share's scale"] = (
                f"the bound on the encoders' chain, RMS θ̈2 {scale.bound:.4g} rad/s²: their floor (the baseline "
                "run's excess over the model's own at its current) added to the bound's in quadrature"
            )
    if math.isfinite(scale.plant_bound):
        header["true plant's bound"] = (
            f"RMS θ̈2 {scale.plant_bound:.4g} rad/s², the same search on the simulated plant's own parameters "
            "(the mismatch section applied): the share of it is the share a law reached of what this plant allows"
        )
    return header


def _notes(results: list[LawResult], section: Mapping[str, Any], policy: PausePolicy) -> list[str]:
    """The notes under ``compare.md``'s table: the laws the host's pauses ran again, what its columns
    mean and where each law's run is."""
    paused = paused_note(results, policy)
    return [
        *([paused] if paused else []),
        _accel_note(results, float(section["accel_bandwidth_hz"])),
        f"Coil energy: R·∫i² dt with R = {section['coil_resistance_ohm']:g} Ω (compare.coil_resistance_ohm).",
        "θ̈2 vs best passive: 1 − RMS θ̈2 / that of the passive baseline, the best constant current "
        "(sashil.lab.passive_baseline; positive: better).",
        "Share of the bound: where the law's RMS θ̈2 lies on one scale from the passive baseline's (0 %) to the "
        "optimal bound's (100 %), 100·(passive − law)/(passive − bound) (sashil.lab.hysteretic_bound: direct "
        "transcription, the current of every millisecond free in its range, L-BFGS-B on the exact adjoint "
        "gradient, on the controller's Bouc-Wen model, its cost over the metric's window, from starts no law "
        f"made; the best found, not a certificate). Above 100 % + {BOUND_TOLERANCE_PTS:g} points (⚠): the rig "
        "beat the bound by more than its tolerance.",
        "Each law's run is a run folder of its own (the folder column): its config.yaml (the law and its "
        "parameters), data.csv (every cycle) and summary.json, for `sashil report`, `sashil replay` and "
        "`sashil compare --config FOLDER/config.yaml` (that law against the references again).",
    ]


def _bound_summary(bound: HystereticBound | None) -> dict[str, Any]:
    """A bound's RMS θ̈2, its starts' optima and their spread, for summary.json."""
    if bound is None:
        return {"rms_accel_rad_s2": float("nan"), "starts": {}, "spread_rad_s2": float("nan")}
    return {
        "rms_accel_rad_s2": bound.rms_accel_bound,
        "starts": dict(bound.starts),
        "spread_rad_s2": bound.spread,
        "spread_pct": bound.spread_pct,
        "model_passive_current_a": bound.passive_current_a,
        "model_passive_rms_accel_rad_s2": bound.rms_accel_passive,
    }


def _summary(
    run: RunSpec,
    error: SashilError | None,
    road: str,
    duration: float,
    processes: int,
    wall: float,
    results: Sequence[LawResult],
    summaries: Mapping[str, Mapping[str, Any]],
    folders: Mapping[str, str],
    figures: Figures,
) -> dict[str, Any]:
    """The comparison's ``summary.json``: how it ended, the road, the passive baseline and how it was
    found, the bound and its starts, each law's status, metrics and share of the bound (flagged above
    it), each law's run."""
    scale, baseline = figures.scale, figures.baseline
    shares = shares_of_bound(results, scale)
    plant_shares = shares_of_bound(results, scale, scale.plant_bound)
    return {
        "verb": "compare",
        "driver": run.rig.backend,
        **ending(error),
        "road": road,
        "duration_s": duration,
        "processes": processes,
        "wall_s": wall,
        "passive_baseline": None
        if baseline is None
        else {
            "law": baseline.label,
            "current_a": baseline.current_a,
            "method": baseline.method,
            "rms_accel_rad_s2": baseline.rms_accel,
            "xatol_a": baseline.xatol_a,
            "evaluated": {f"{c:g}": r.metrics.get("rms_accel_rad_s2") for c, r in sorted(baseline.evaluated.items())},
        },
        "optimal_bound_gain_pct": figures.gain_pct,
        "optimal_bound_rms_accel_rad_s2": figures.bound.rms_accel_bound if figures.bound is not None else float("nan"),
        "optimal_bound_model": "hysteretic" if figures.bound is not None else None,
        "optimal_bound": _bound_summary(figures.bound),
        "plant_bound": _bound_summary(figures.plant) if figures.plant is not None else None,
        "share_scale_bound_rms_accel_rad_s2": scale.bound,
        "bound_tolerance_pts": BOUND_TOLERANCE_PTS,
        "laws": [
            {
                "law": r.label,
                "status": r.status,
                "accel_source": r.accel_source,
                "wall_s": r.wall_s,
                "pauses_ms": r.pauses_ms,
                **r.metrics,
                "share_of_bound_pct": shares.get(r.label, float("nan")),
                "above_bound": above_bound(shares.get(r.label, float("nan"))),
                **(
                    {"share_of_plant_bound_pct": plant_shares.get(r.label, float("nan"))}
                    if math.isfinite(scale.plant_bound)
                    else {}
                ),
            }
            for r in results
        ],
        "runs": [
            {
                "folder": folders[r.label],
                "controller": r.label,
                "controller_origin": summaries[r.label]["controller_origin"],
                "parameters": summaries[r.label]["parameters"],
                "exit_status": summaries[r.label]["exit_status"],
                "error": summaries[r.label].get("error"),
                **r.metrics,
            }
            for r in results
        ],
    }


#: seconds of arm acceleration kept for the time-trace plot, and its decimation
TRACE_S = 5.0
TRACE_DECIMATE = 5


@dataclass
class LawJob:
    """One law's run (picklable: a process runs it on the simulated rig)."""

    label: str
    config: RunConfig
    road: str
    duration_s: float
    #: the law's run folder (created, its config.yaml written): data.csv and timing.npz go there
    folder: str | None = None


class MeasuredStage:
    """A loop stage that runs ``stage`` and records the true arm acceleration θ̈2 = (−k·θ − T)/J
    (seed 001 eq. 13) of a rig that reports it (its capability ``true_torque``: a simulated plant) as
    ``arm_accel_true_rad_s2`` (NaN on any other rig)."""

    def __init__(self, stage: Any, rig: Any):

        self.stage = stage
        self._truth = rig if rig is not None and capabilities_of(rig).true_torque else None
        self.signal_names = (*stage_signals(stage), "arm_accel_true_rad_s2")
        self.arm_accel_true_rad_s2 = math.nan

    def __getattr__(self, name: str) -> Any:  # the inner stage's signals
        if name == "stage":
            raise AttributeError(name)
        return getattr(self.stage, name)

    def step(self, sample: Any, t_ns: int, dt_ns: int) -> Any:
        if self._truth is not None:
            self.arm_accel_true_rad_s2 = self._truth.plant_truth().arm_accel_rad_s2
        return self.stage.step(sample, t_ns, dt_ns)


def run_job(job: LawJob) -> LawResult:
    """Run one law on the road (on the clock the config's backend runs on) and measure it; a law
    that fails, trips or stops gets a result saying why instead of metrics."""
    from scipy.signal import welch

    run = assemble(job.config, reads=READS)
    result = LawResult(job.label, metrics=dict.fromkeys(METRICS, math.nan))
    folder = RunFolder(Path(job.folder), "compare") if job.folder is not None else None
    start = time.perf_counter()
    try:
        road, _ = parse_road(job.road, RoadParts.of(run.options))
        stage = make_stage(run.stage)[1]
        if road is not None:
            stage = RoadStage(stage, road, job.duration_s)
        rig = open_rig(run.rig)
        outcome = engine.run(
            run,
            MeasuredStage(stage, rig),
            job.duration_s,
            rig=lambda: rig,
            data_path=folder.file("data.csv") if folder is not None else None,
            realtime=False,
            say=lambda _: None,
        )
    except Exception as err:  # a law that cannot even start: its row says why
        result.status = f"failed: {type(err).__name__}: {(str(err).splitlines() or [''])[0]}"
        result.wall_s = time.perf_counter() - start
        return result
    result.wall_s = time.perf_counter() - start
    result.summary = dict(outcome.summary)
    if folder is not None:
        folder.write_timing(outcome.timing)
    if outcome.error is not None or outcome.exit_status != "ok":
        trips = "; ".join(str(trip.get("reason", trip)) for trip in outcome.trips)
        why = trips or outcome.summary["error"] or outcome.stop_reason or outcome.exit_status
        result.status = f"{outcome.exit_status}: {why}"
        return result
    try:
        metrics, t, accel, result.accel_source = metrics_of(outcome.stream, run)
    except (KeyError, ValueError) as err:
        result.status = f"no metrics: {err}"
        return result
    result.metrics = metrics
    rate = run.loop.rate_hz
    f, pxx = welch(accel, fs=rate, nperseg=min(accel.size, int(8 * rate)))
    band = f <= 4.0 * float(run.options["accel_bandwidth_hz"])
    result.psd_f, result.psd = f[band].tolist(), pxx[band].tolist()
    window = t <= t[0] + TRACE_S
    result.trace_t = t[window][::TRACE_DECIMATE].tolist()
    result.trace = accel[window][::TRACE_DECIMATE].tolist()
    return result
