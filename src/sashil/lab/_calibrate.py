"""``sashil calibrate`` as a library function: run the plan of drops and road runs on the rig, fit
the damper model, validate it on the held-out runs, and write the calibration folder
(:func:`sashil.lab.calibration.session.calibrate_rig` does the work)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from sashil.api import Run, load_run
from sashil.config.section_parts import CalibratePart
from sashil.engine.events import Event, Listener, ignore
from sashil.lab.calibration.session import calibrate_rig
from sashil.recording.outputs import Outputs

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["calibrate"]


def calibrate(
    config: RunConfig, outputs: Outputs | None = None, on_event: Listener = ignore, *, source: str = "config"
) -> Run:
    """Calibrate the rig of a resolved ``config`` (:func:`sashil.engine.resolve.resolve` with verb
    ``calibrate``): the plan, model, arm inertia J, exponent profile and extra steps are its
    ``calibrate`` section (``inertia_kg_m2`` None: every torque relative to J = 1).

    Returns the calibration folder as a :class:`~sashil.api.Run`: ``params.yaml`` (accepted by
    ``--params`` on every verb), ``report.md`` and its plots, ``summary.json`` (model, held-out and
    fit NRMSE, rig and fit time) and each raw run under ``runs/``. ``source`` names the config in
    messages about the plan (its file, or ``config``). Bad input (a plan at one current, runs too
    short for the intervals, a port that cannot be opened) raises ConfigError before any folder
    exists; a step that fails ends the plan with the runs so far kept and raises its error.
    Events: ``progress`` lines as the plan runs and the fit proceeds; a ``prompt`` before every
    attempt of a step (the angle to press the arm to; shown even when quiet); ``output`` lines with the
    fit, the held-out NRMSE and the files written; the ``folder``."""

    outputs = outputs if outputs is not None else Outputs()
    outputs.check_folder_only("calibrate")
    section = CalibratePart.read(config)
    inertia = section.inertia_kg_m2
    outcome = calibrate_rig(
        config,
        outputs.out,
        inertia=inertia,
        say=lambda text: on_event(Event("progress", text)),
        prompt=lambda text: on_event(Event("prompt", text)),
        source=source,
        profile=section.profile_n,
    )
    cal, best = outcome.calibration, outcome.calibration.best
    if inertia is None:
        on_event(Event("output", "all torques are relative to J = 1 (no --inertia): multiply them by the rig's J"))
    held = ", ".join(f"{v.name} {100 * v.nrmse:.2f} %" for v in cal.validations) or "none (no held-out runs)"
    on_event(
        Event(
            "output",
            f"model {best.model}: fit RMS {math.degrees(best.rms_total):.4f} deg; held-out NRMSE: {held}",
            {"model": best.model, "held_out_nrmse": {v.name: v.nrmse for v in cal.validations}},
        )
    )
    on_event(
        Event(
            "output",
            f"rig time {outcome.rig_s:.0f} s, fit {cal.fit_s:.1f} s; {best.convergence.get('message', '')}",
            {"rig_time_s": outcome.rig_s, "fit_s": cal.fit_s},
        )
    )
    on_event(
        Event(
            "output",
            f"wrote {outcome.params_path} and {outcome.report_path}",
            {"params": str(outcome.params_path), "report": str(outcome.report_path)},
        )
    )
    on_event(Event("folder", f"calibration folder: {outcome.folder}", {"folder": str(outcome.folder)}))
    return load_run(outcome.folder)
