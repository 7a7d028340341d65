"""The controller stage of a run: ``make_controller(law, parts)`` builds the cycle stage from the
stage's parts (:class:`~sashil.config.parts.StageParts`: the ``controller`` section, the model and
the rig's facts): law, estimator, observer, inverse, coil lead.

The law comes from :mod:`sashil.control.law_registry` (a registered name, ``package.module:Class``
or ``file.py:Class``) with its parameters checked by :mod:`sashil.control.law_config`. Bad input is
one line naming the key (an unknown law, a missing or out-of-range parameter, a target-damping
c_target outside [c1, c1 + c2*i_max] of the model). During a run an unreachable *torque* is
clipped to the feasible band and counted, never an error.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sashil.config.parts import StageParts
from sashil.control.controller import Controller, signal_names
from sashil.control.estimator import RigEstimator
from sashil.control.inverse import CoilLagCompensator, HysteresisInverse
from sashil.control.kalman import KalmanRigEstimator
from sashil.control.law_api import Law
from sashil.control.law_config import build_law
from sashil.control.law_registry import LawEntry, find_law
from sashil.control.observer import BoucWenObserver
from sashil.control.stages import ConstantCurrent
from sashil.errors import ConfigError

__all__ = ["law_reads_state", "law_run_label", "make_controller", "make_estimator", "make_stage"]


def law_reads_state(parts: StageParts) -> bool:
    """Whether the stage's law reads the rig's state (:attr:`sashil.control.law_api.Law.reads_state`)."""
    return bool(find_law(parts.law).cls.reads_state)


def stage_signals(parts: StageParts) -> tuple[str, ...]:
    """What a controller of the stage's law records each cycle (:func:`~sashil.control.controller.signal_names`);
    none for a law that reads no state (it runs as a constant-current stage), from the law's class alone."""
    cls = find_law(parts.law).cls
    return signal_names(cls) if cls.reads_state else ()


def _stage_law(parts: StageParts, name: str | None = None) -> tuple[LawEntry, Law]:
    """Law ``name`` (None: the stage's law) and an instance of it with the parameters of the
    ``controller`` section that it declares (the section's others belong to another law; a resolved
    config has been checked against its own law by :func:`~sashil.control.law_config.check_controller`)."""
    entry = find_law(parts.law if name is None else name)
    declared = entry.cls.params()
    return entry, build_law(
        entry, parts, {key: value for key, value in parts.controller.params.items() if key in declared}
    )


def law_run_label(parts: StageParts) -> str:
    """What a run calls the stage's law in its summary, sub-folders and plots: the law's own
    :meth:`~sashil.control.law_api.Law.label` (``passive 1 A``; its ``name`` by default, however
    ``controller.law`` names it: a file law is not labelled by its path)."""
    return _stage_law(parts)[1].label()


def make_stage(parts: StageParts) -> tuple[str, Any]:
    """The loop stage of the law and its label (:func:`law_run_label`): a :class:`Controller`, or for
    a law that reads no state a constant-current stage that runs the law alone (no estimator or
    observer)."""
    if law_reads_state(parts):
        controller = make_controller(None, parts)
        return controller.law.label(), controller
    law = _stage_law(parts)[1]
    return law.label(), ConstantCurrent(law=law)


def make_estimator(parts: StageParts) -> RigEstimator | KalmanRigEstimator:
    """The ``controller.estimator``: the rig-model Kalman filter or the fixed-bandwidth tracking filters."""
    section = parts.controller
    if section.estimator == "kalman":
        estimator = KalmanRigEstimator(
            1.0 / parts.rate_hz,
            accel_psd=section.kalman_accel_psd,
            road_jerk_psd=section.kalman_road_jerk_psd,
            bias_psd=section.kalman_bias_psd,
            angle_noise_rad=parts.angle_noise_rad,
            innovation_limit=section.innovation_limit_counts,
            commanded_road_jerk_psd=section.kalman_road_jerk_psd_commanded,
            quantisation=section.kalman_quantisation,
            edge_timing=section.edge_timing,
        )
        # the gains now, not in the first real-time cycle (the device confirms the resolution)
        estimator.prepare(parts.counts_per_rev)
        return estimator
    return RigEstimator(
        section.estimator_bandwidth_hz,
        section.road_bandwidth_hz,
        order=3 if section.estimator_order == 3 else 2,
    )


def make_controller(
    name: str | None,
    parts: StageParts,
    torque: Callable[[float], float] | None = None,
) -> Controller:
    """A :class:`Controller` running law ``name`` (None: the stage's law) on the stage's model.

    The observer and inverse use the model the controller believes (``parts.model``); a simulated
    plant may differ from it (``mismatch`` section, :mod:`sashil.drivers.mismatch`). The law takes
    the section's parameters it declares (:func:`_stage_law`). ``torque``: a T*(t) signal [N m] for
    a law with a ``signal`` attribute (``torque-tracking``) instead of its random band fraction.
    """
    section = parts.controller
    entry, law = _stage_law(parts, name)
    if law.context is None:  # the law's context holds the model only when it is the rig's Bouc-Wen
        raise ConfigError(f"model.name: the controller runs the bouc-wen model, got {parts.model.name!r}")
    params = law.context.model
    i_max = parts.current_max_a
    if torque is not None:
        if not hasattr(law, "signal"):
            raise TypeError(f"law {entry.cls.name!r} takes no torque signal")
        setattr(law, "signal", torque)  # noqa: B010 - a law's optional attribute
    return Controller(
        law=law,
        origin=entry.origin,
        estimator=make_estimator(parts),
        observer=BoucWenObserver(params),
        inverse=HysteresisInverse(params, i_max, section.min_authority_nm_per_a, section.inverse),
        lead=CoilLagCompensator(parts.coil_tau_s, section.lead_horizon_s, i_max),
        lead_current_laws=section.lead_current_laws,
        current_max_a=i_max,
        model_aided=section.model_aided,
        nominal_dt_s=1.0 / parts.rate_hz,
    )
