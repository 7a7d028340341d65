"""One calibration from start to finish: run the plan, fit, validate, write the folder."""

from __future__ import annotations

import dataclasses
import math
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sashil.config.frozen import freeze_config, thaw
from sashil.config.section_parts import CalibratePart
from sashil.drivers.operator_prompt import hold_prompt
from sashil.engine import assemble
from sashil.errors import ConfigError, DriverIOError, SashilError
from sashil.identify.data import MIN_CURRENT_SPREAD_A, Record
from sashil.identify.fit import FitResult, simulate_fitted
from sashil.identify.intervals import MIN_BLOCK_S, MIN_BLOCKS_PER_PARAMETER
from sashil.identify.report import write_params
from sashil.identify.rig_models import MODELS
from sashil.lab.calibration.analysis import Calibration, analyse, gap_cut
from sashil.lab.calibration.extra import candidates, suggest
from sashil.lab.calibration.plan import READS, Plan, plan_of, road_chirp
from sashil.lab.calibration.report import params_document, write_report
from sashil.lab.calibration.rig import StepResult, run_step
from sashil.plans.calibration_step import Step, StuckEncoderError
from sashil.runtime.runner import CYCLES_FILE
from sashil.writer.documents import Documents, RunRecord
from sashil.writer.folder_writer import FolderWriter, ending
from sashil.writer.run_folder import RunFolder

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec
    from sashil.config.typed import RunConfig

#: times a step is repeated when a link gap (a host pause that lost samples) cuts its record short
GAP_REPEATS = 2


@dataclass
class Outcome:
    folder: Path
    params_path: Path
    report_path: Path
    calibration: Calibration
    rig_s: float


def check_inertia(inertia: float | None) -> float:
    """``--inertia``: a finite J > 0, or None (J = 1, torques relative to it)."""
    if inertia is None:
        return 1.0
    if not (math.isfinite(inertia) and inertia > 0.0):
        raise ConfigError(f"--inertia: expected the arm's inertia J > 0 [kg m^2], got {inertia:g}")
    return float(inertia)


def check_plan(plan: Plan, source: str, block_s: float | None = None) -> None:
    """The fit runs must span two currents: alpha2 and c2 are always identified; and with
    ``block_s`` they must hold enough jackknife blocks for the intervals (:func:`min_blocks`), if
    need be shortened down to MIN_BLOCK_S (:func:`sashil.identify.intervals.interval_blocks`)."""
    currents = {s.current_a for s in plan.fit_steps()}
    if max(currents) - min(currents) < MIN_CURRENT_SPREAD_A:
        raise ConfigError(
            f"{source}: calibrate: every run to fit is at {min(currents):g} A, so the current terms (alpha2, c2) "
            f"cannot be identified; give calibrate.currents_a at least two currents {MIN_CURRENT_SPREAD_A:g} A apart"
        )
    if block_s is not None:
        need = min_blocks(plan.model)
        fit_s = sum(s.duration_s for s in plan.fit_steps())
        have = sum(max(1, int(s.duration_s / MIN_BLOCK_S)) for s in plan.fit_steps())
        if have < need:
            drops = [s for s in plan.fit_steps() if s.road is None]
            short = (
                math.ceil(100 * (need * MIN_BLOCK_S - (fit_s - sum(s.duration_s for s in drops))) / max(len(drops), 1))
                / 100
            )
            raise ConfigError(
                f"{source}: calibrate.drop_duration_s: the runs to fit ({fit_s:g} s in all) are too short to block "
                f"for the intervals: {need} blocks of at least {MIN_BLOCK_S:g} s are needed; give at least {short:g} s"
            )


def check_port(port: str | None) -> None:
    """A link's port given as a device path (``/dev/ttyACM0``) must exist: refused in one line before
    the operator is told to press the arm (the first prompt comes before the rig is opened)."""
    if isinstance(port, str) and port.startswith("/") and not Path(port).exists():
        raise ConfigError(f"--port (driver.port): {port}: no such device (is the board plugged in?)")


def min_blocks(model: str) -> int:
    """Jackknife blocks the plan must hold: MIN_BLOCKS_PER_PARAMETER per free parameter (the most
    of any model when ``model`` is all)."""
    names = list(MODELS) if model == "all" else [model]
    return MIN_BLOCKS_PER_PARAMETER * max(len(MODELS[n].linear) + len(MODELS[n].nonlinear) for n in names)


def _summary_row(res: StepResult) -> dict[str, Any]:
    s = res.step
    return {
        "name": s.name,
        "role": s.role,
        "kind": s.kind,
        "theta0_deg": s.theta0_deg,
        "hold_angle_deg": round(res.hold_angle_deg, 4),
        "current_a": s.current_a,
        "duration_s": s.duration_s,
        "release_estimated": res.release_estimated,
        **{key: value for key, value in ending(res.error).items() if key != "exit_code"},
        "link": res.extra.get("link"),
        "gap_repeats": res.extra.get("gap_repeats", 0),
        "loop_process": res.extra.get("loop_process"),
    }


def _stream(target: RunFolder, attempt: int) -> Path:
    """Where the runner streams a step's cycles: cycles.csv, and cycles-2.csv, ... for its repeats."""
    return target.file(CYCLES_FILE if attempt == 1 else CYCLES_FILE.replace(".csv", f"-{attempt}.csv"))


#: a refit with extra steps whose RMS over the plan's own runs exceeds this multiple of the first
#: fit's is not kept (the extra run led the search astray)
EXTRA_WORSE = 1.5


def plan_rms(result: FitResult, records: Sequence[Record]) -> float:
    """RMS output error [rad] of ``result`` over ``records`` (all samples)."""
    errors = [sim - r.theta for sim, r in zip(simulate_fitted(result, records), records, strict=True)]
    return float(np.sqrt(np.mean(np.concatenate(errors) ** 2)))


def _stopped(
    documents: Documents, runs: FolderWriter, results: list[StepResult], rig_s: float, say: Callable[[str], None]
) -> None:
    """A step failed: the runs so far and summary.json are kept, nothing is fitted; raises its error."""
    assert runs.error is not None
    documents.end(
        rig_time_s=round(rig_s, 2),
        note="the plan was cut short: the runs recorded so far are kept; nothing was fitted",
    )
    say(f"the plan stopped at {results[-1].step.name}; the runs so far are in {runs.folder.path}")
    raise runs.error


def calibrate_rig(
    config: RunConfig,
    out: str | Path | None = None,
    inertia: float | None = None,
    model: str | None = None,
    say: Callable[[str], None] | None = None,
    source: str = "config",
    profile: bool = True,
    prompt: Callable[[str], None] | None = None,
) -> Outcome:
    """Calibrate the rig of ``config`` (its ``driver`` section says which: sim, serial, can).

    Runs the plan of its ``calibrate`` section (:func:`sashil.lab.calibration.plan.plan_of`),
    fits the model (seed 001 eqs. 9-17 for Bouc-Wen) to the ``fit`` runs, validates it on the
    held-out ones and writes ``out`` (default ``runs/<UTC>-calibrate/``): ``params.yaml`` (the
    shape ``sashil identify`` writes, accepted by ``--params`` on every verb), ``report.md`` with
    ``fit.png``, ``validation.png``, ``n_profile.png``, ``summary.json``, ``config.yaml`` and
    every raw run under ``runs/<step>/`` (``data.csv``, ``summary.json``).

    ``inertia``: the arm's J [kg m^2]; None fits with J = 1 and says so in the report's first line.
    ``model``: overrides ``calibrate.model`` (bouc-wen, dahl, lugre, bingham or all).
    ``prompt``: told, before every attempt of a step (a repeat too) and before the rig is opened
    for it, the operator's instruction: :func:`~sashil.drivers.operator_prompt.hold_prompt` of
    the step's angle (default: ``say``). A person at the bench reads it; so does the emulator's
    operator reading the host's console (``sashil emulate --prompts``).
    Bad input (config, inertia, a plan at one current, a port path that does not exist) raises
    ConfigError before anything is energised or written. A step that fails on the link is
    repeated once, and one whose record a link gap cut short (a host pause lost samples the fit
    needs) up to GAP_REPEATS times, keeping the longest record (the fit uses the angle each record
    starts from); a step that fails (a lost link, a stuck encoder, a safety trip) ends the plan:
    the runs so far and ``summary.json`` are written and the step's error is raised.
    Returns an :class:`Outcome` (folder, params and report paths, the calibration, rig seconds).
    """
    say = say or (lambda text: None)
    J = check_inertia(inertia)
    if model is not None:
        derived = thaw(config)
        derived["calibrate"]["model"] = model
        config = freeze_config(derived)
    run = assemble(config, reads=READS)
    section = CalibratePart.read(config)
    plan = plan_of(run, section, source)
    check_plan(plan, source, section.interval_block_s)
    check_port(run.options["port"])
    folder = RunFolder.create(out, "calibrate")
    runs_folder = RunFolder.create(folder.path / "runs", "calibrate")
    runs = FolderWriter(folder, "calibrate", {"driver": run.rig.backend}, sub_root=runs_folder.path)
    documents = Documents([runs])
    documents.start(None, config, run)
    say(
        f"calibration plan: {len(plan.steps)} runs, about {plan.rig_time_s:.0f} s of rig time "
        f"({run.rig.backend} rig; operator hold angles {', '.join(f'{a:g}' for a in plan.operator_angles_deg())} deg)"
    )
    session = _Session(run, section, plan, folder, documents, runs, say, prompt or say, J)
    session.run_steps(plan.steps, 1, len(plan.steps))
    say(f"rig time {session.rig_s:.0f} s; fitting ...")
    extra = section.extra_steps
    cal = session.fit(profile and not extra)
    if extra:
        cal = session.run_extra_steps(cal, extra, profile)
    return session.write(cal, inertia is not None)


@dataclass
class _Session:
    """One calibration under way: its assembled run (``options``: :data:`READS`), its ``calibrate``
    section and plan, its folders, the runs so far, how it talks to the user (``say``) and to the
    operator (``tell``)."""

    run: RunSpec
    calibrate: CalibratePart
    plan: Plan
    folder: RunFolder
    documents: Documents
    runs: FolderWriter
    say: Callable[[str], None]
    tell: Callable[[str], None]
    J: float
    results: list[StepResult] = dataclasses.field(default_factory=list)
    started: float = dataclasses.field(default_factory=time.perf_counter)
    rig_s: float = 0.0

    @property
    def counts_per_rev(self) -> int:
        return self.run.stage.counts_per_rev

    def run_once(self, step: Step, data_path: Path) -> StepResult:
        """One run of ``step``, the operator told first which angle to hold."""
        hold_s = float(self.run.options["hold_time_s"])
        self.tell(f"{step.name}: {hold_prompt(step.theta0_deg)}, hold it still {hold_s:g} s and let go")
        return run_step(self.run, step, data_path)

    def run_steps(self, steps: Sequence[Step], first: int, total: int) -> None:
        """Run ``steps`` (numbered from ``first`` of ``total``) into :attr:`results`; the rig time so
        far in :attr:`rig_s`. A step that fails ends the plan (:func:`_stopped` raises its error)."""
        failure = None
        for number, step in enumerate(steps, start=first):
            self.say(f"[{number}/{total}] {step.describe()} ...")
            target = self.runs.folder_for(step.name)
            result = self.attempts(step, target)
            error = result.error
            if (
                not self.results
                and error is not None
                and error.exit_code == 2
                and not isinstance(error, StuckEncoderError)
                and not result.columns.get("time_s", np.zeros(0)).size
            ):  # the rig could not be opened (a bad port, another device): bad input, nothing written
                shutil.rmtree(self.folder.path, ignore_errors=True)
                raise error
            self.results.append(result)
            recorded = result.columns.get("time_s") is not None and result.columns["time_s"].size
            entry = {**_summary_row(result), "metrics": result.extra.get("metrics")}
            self.documents.stop(
                step.name, RunRecord(error=result.error, entry=entry, data=result.columns if recorded else None)
            )
            if result.error is not None:
                failure = result.error
                break
        self.rig_s = time.perf_counter() - self.started
        if failure is not None:
            _stopped(self.documents, self.runs, self.results, self.rig_s, self.say)

    def attempts(self, step: Step, target: RunFolder) -> StepResult:
        """The record of ``step``: once more after a transient link fault, and up to
        :data:`GAP_REPEATS` more times while a link gap cuts it short (the longest kept)."""
        attempts = iter(range(2, 100))  # a repeat streams beside the first attempt: cycles-2.csv, ...
        try:
            result = self.run_once(step, _stream(target, 1))
        except SashilError:
            if not self.results:  # the rig could not be opened (a bad port): bad input, nothing written
                shutil.rmtree(self.folder.path, ignore_errors=True)
            raise
        if isinstance(result.error, DriverIOError):  # a transient link fault: the run once more
            self.say(f"  {step.name} failed on the link ({result.error}); repeating it once")
            try:
                again = self.run_once(step, _stream(target, next(attempts)))
            except SashilError as err:  # the link is gone (cannot even open it): the first failure stands
                self.say(f"  the repeat failed too ({err})")
            else:
                if again.error is None:
                    result = again
        for attempt in range(1, GAP_REPEATS + 1):  # a host pause lost samples inside the record
            cut_at = gap_cut(result, self.counts_per_rev) if result.error is None else None
            if cut_at is None:
                break
            self.say(
                f"  {step.name}: a link gap {cut_at:.2f} s after the release cut the record short; "
                f"repeating it ({attempt} of {GAP_REPEATS})"
            )
            try:
                again = self.run_once(step, _stream(target, next(attempts)))
            except SashilError as err:  # cannot even open the link again: keep the cut record
                self.say(f"  the repeat failed ({err})")
                break
            if again.error is not None:
                break  # keep the record cut short (the fit leaves it out if too short)
            again_cut = gap_cut(again, self.counts_per_rev)
            if again_cut is None or again_cut > cut_at:
                result = again
            result.extra["gap_repeats"] = attempt
        return result

    def fit(self, profile_n: bool) -> Calibration:
        """The model fitted to the fit runs, validated on the held-out ones, with the extra steps
        that would shrink its widest interval ranked."""
        section = self.calibrate
        current_max_a = self.run.stage.current_max_a
        cal = analyse(
            [r for r in self.results if r.step.role == "fit"],
            [r for r in self.results if r.step.role == "validate"],
            self.plan.model,
            self.J,
            self.counts_per_rev,
            progress=self.say,
            profile=profile_n,
            current_max_a=current_max_a,
            block_s=section.interval_block_s,
        )
        if cal.intervals is not None:
            road = road_chirp(section)
            cal.suggestions = suggest(
                cal.best,
                cal.intervals,
                candidates(section, current_max_a, road),
                current_max_a,
                self.counts_per_rev,
            )
        return cal

    def run_extra_steps(self, cal: Calibration, extra: int, profile: bool) -> Calibration:
        """Run the ``extra`` steps ranked first and refit; the first fit stands when the refit fits
        the plan's runs worse."""
        count = len(self.plan.steps)
        chosen = [
            dataclasses.replace(
                s.step, name=f"{n:02d}-fit-{s.step.kind}-{abs(s.step.theta0_deg):g}deg-{s.step.current_a:.2f}A-extra"
            )
            for n, s in enumerate(cal.suggestions[:extra], start=count + 1)
        ]
        self.say(
            f"{cal.suggestions[0].quantity} has the widest interval (±{100 * cal.suggestions[0].now:.2g} %); "
            f"running {len(chosen)} extra step(s) that shrink it most: {', '.join(c.describe() for c in chosen)}"
        )
        self.run_steps(chosen, count + 1, count + len(chosen))
        self.say("refitting with the extra steps ...")
        first, cal = cal, self.fit(profile)
        before, after = first.best.rms_total, plan_rms(cal.best, first.fit_records)
        if after > EXTRA_WORSE * before:  # the refit lost the plan's runs: keep the fit without the extra steps
            note = (
                f"the refit with the extra steps fit the plan's runs worse (RMS {math.degrees(after):.4f} deg against "
                f"{math.degrees(before):.4f} deg): kept the fit without them"
            )
            self.say(note)
            first.extra_note = note
            cal = first
        return cal

    def write(self, cal: Calibration, inertia_given: bool) -> Outcome:
        """``params.yaml``, ``report.md`` with its plots, and the folder's ``summary.json``."""
        run, rig_s = self.run, self.rig_s
        rows = [_summary_row(r) for r in self.results]
        params_path = write_params(self.folder.file("params.yaml"), params_document(cal, inertia_given, rig_s, rows))
        report_path = write_report(
            self.folder.path,
            cal,
            self.results,
            self.J,
            inertia_given,
            run.stage.counts_per_rev,
            run.stage.current_max_a,
            rig_s,
            virtual=run.virtual,
        )
        self.documents.end(
            model=cal.best.model,
            inertia_given=inertia_given,
            held_out_nrmse={v.name: v.nrmse for v in cal.validations},
            held_out_nrmse_mean=None if math.isnan(cal.validation_nrmse) else cal.validation_nrmse,
            fit_nrmse=dict(zip(cal.best.record_names, cal.best.nrmse, strict=True)),
            rig_time_s=round(rig_s, 2),
            fit_s=round(cal.fit_s, 2),
            identifiability_s=round(cal.analysis_s, 2),
            convergence=cal.best.convergence,
        )
        return Outcome(self.folder.path, params_path, report_path, cal, rig_s)
