"""The calibration plan: which runs to make on the rig, in what order, and what each is for.

Every step is a drop test (seed 001 section 8): the arm is pressed to ``theta0_deg`` and released
with the coil already at ``current_a``; a *road* step also drives the road wheel from the release
on with a chirp through the resonance (:class:`~sashil.plans.calibration_step.Step` and its
:class:`~sashil.plans.calibration_step.RoadChirp`, which the loop runs). Each step has a role: ``fit`` (the identification sees it) or ``validate`` (held out: the
fitted model predicts it from its inputs alone). The plan comes from the config's ``calibrate``
section (:func:`plan_from_config`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sashil.config.section_parts import CalibratePart
from sashil.engine import assemble
from sashil.errors import ConfigError
from sashil.lab._drop_test import READS as DROP_READS
from sashil.plans.calibration_step import RoadChirp, Step
from sashil.plans.drop import check_theta0

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec
    from sashil.config.typed import RunConfig

#: rig time a step costs beyond its record (connect, the operator's hold and release), an estimate
STEP_OVERHEAD_S = 2.0
#: a road run's record goes on this long after its chirp has ended (the wheel at rest)
ROAD_REST_S = 0.5


@dataclass(frozen=True)
class Plan:
    steps: tuple[Step, ...]
    model: str

    @property
    def rig_time_s(self) -> float:
        """Estimated rig time: every record plus :data:`STEP_OVERHEAD_S` per step."""
        return sum(step.duration_s + STEP_OVERHEAD_S for step in self.steps)

    def operator_angles_deg(self) -> list[float]:
        """The hold angle of every step in order (``sashil emulate --hold-deg`` plays them until the
        host's first prompt, with ``--prompts``)."""
        return [step.theta0_deg for step in self.steps]

    def fit_steps(self) -> list[Step]:
        return [s for s in self.steps if s.role == "fit"]

    def validate_steps(self) -> list[Step]:
        return [s for s in self.steps if s.role == "validate"]


def road_chirp(section: CalibratePart) -> RoadChirp:
    """The road chirp of a ``calibrate`` section. It ends ROAD_REST_S before the record does: its
    last speed command is exactly 0 (a wheel left turning would move the road under the next run)."""
    return RoadChirp(
        math.radians(section.road_amplitude_deg),
        section.road_f_start_hz,
        section.road_f_stop_hz,
        section.road_duration_s - ROAD_REST_S,
        section.road_ramp_s,
    )


#: the calibration's own values (``{name: config key}``), read once by the engine into its run's
#: ``options``: the rig's angle limit and the drop test's (each step is a drop); its own section
#: is read typed (:class:`~sashil.config.section_parts.CalibratePart`)
READS = {**DROP_READS, "angle_limit_deg": "rig.angle_limit_deg"}


def plan_from_config(config: RunConfig, source: str = "config") -> Plan:
    """The plan of a resolved config's ``calibrate`` section (:func:`plan_of` its assembled run)."""
    return plan_of(assemble(config, reads=READS), CalibratePart.read(config), source)


def plan_of(run: RunSpec, section: CalibratePart, source: str = "config") -> Plan:
    """The plan of the ``calibrate`` section ``section`` for the run (its ``options``: :data:`READS`),
    checked against the rig (one-line ConfigError).

    Currents must lie in [0, rig.current_max_a]; the fit needs at least two currents when the model
    has current terms (checked by the caller, which knows whether they are asked for); the estimated
    rig time must stay within ``max_rig_time_s``; the road chirp must stay below a tenth of the
    loop rate."""
    i_max = run.stage.current_max_a
    limit = float(run.options["angle_limit_deg"])

    def currents(key: str) -> list[float]:
        values: tuple[float, ...] = getattr(section, key)
        for value in values:
            if not 0.0 <= value <= i_max:
                raise ConfigError(
                    f"{source}: calibrate.{key}: expected currents in [0, {i_max:g}] A (rig.current_max_a), got {value:g}"
                )
        if len(set(values)) != len(values):
            raise ConfigError(f"{source}: calibrate.{key}: each current once, got {values}")
        return [float(v) for v in values]

    for key in ("theta0_deg", "small_theta0_deg", "validate_theta0_deg"):
        angle: float = getattr(section, key)
        if not 0.0 < abs(angle) < limit:
            raise ConfigError(
                f"{source}: calibrate.{key}: expected an angle away from 0 and within ±{limit:g} deg "
                f"(rig.angle_limit_deg), got {angle:g}"
            )
        check_theta0(run.options["release_threshold_deg"], angle, f"{source}: calibrate.{key}")
    f0, f1 = section.road_f_start_hz, section.road_f_stop_hz
    if f1 < f0:
        raise ConfigError(f"{source}: calibrate.road_f_stop_hz: expected >= road_f_start_hz ({f0:g}), got {f1:g}")
    if f1 > run.loop.rate_hz / 10:
        raise ConfigError(
            f"{source}: calibrate.road_f_stop_hz: expected at most a tenth of loop.rate_hz, got {f1:g} Hz"
        )
    if 2 * section.road_ramp_s >= section.road_duration_s - ROAD_REST_S:
        raise ConfigError(
            f"{source}: calibrate.road_ramp_s: the two ramps must fit in road_duration_s "
            f"({section.road_duration_s:g} s), got {section.road_ramp_s:g} s"
        )
    road = road_chirp(section)
    drop_s = section.drop_duration_s
    big, small, held_out = section.theta0_deg, section.small_theta0_deg, section.validate_theta0_deg
    # (role, theta0, current, road) in rig order: fit drops, fit road runs, held-out runs
    specs: list[tuple[str, float, float, RoadChirp | None]] = []
    specs += [("fit", big, i, None) for i in currents("currents_a")]
    specs += [("fit", small, i, None) for i in currents("small_currents_a")]
    specs += [("fit", big, i, road) for i in currents("road_currents_a")]
    specs += [("validate", held_out, i, None) for i in currents("validate_currents_a")]
    specs += [("validate", big, i, road) for i in currents("validate_road_currents_a")]
    steps = [
        Step(
            f"{n:02d}-{role}-{'road' if chirp else 'drop'}-{abs(theta0):g}deg-{current:.2f}A",
            role,
            theta0,
            current,
            section.road_duration_s if chirp else drop_s,
            chirp,
        )
        for n, (role, theta0, current, chirp) in enumerate(specs, start=1)
    ]
    if not any(s.role == "fit" for s in steps):
        raise ConfigError(f"{source}: calibrate: the plan has no run to fit (all current lists are empty)")
    plan = Plan(tuple(steps), section.model)
    if plan.rig_time_s > section.max_rig_time_s:
        raise ConfigError(
            f"{source}: calibrate: the plan would take about {plan.rig_time_s:.0f} s of rig time, more than "
            f"calibrate.max_rig_time_s = {section.max_rig_time_s:g} s (fewer currents or shorter runs)"
        )
    return plan
