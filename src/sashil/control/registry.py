"""The controller of a config: ``make_controller(law, config)`` builds the cycle stage from the
``controller:`` section (law, estimator, observer, inverse, coil lead).

The law comes from :mod:`sashil.control.law_registry` (a registered name, ``package.module:Class``
or ``file.py:Class``) with its parameters checked by :mod:`sashil.control.law_config`. Bad input is
one line naming the key (an unknown law, a missing or out-of-range parameter, a target-damping
c_target outside [c1, c1 + c2*i_max] of the model). During a run an unreachable *torque* is
clipped to the feasible band and counted, never an error.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from sashil.config.schema import defaults
from sashil.config.sections import CONTROLLER
from sashil.control.controller import Controller
from sashil.control.estimator import RigEstimator
from sashil.control.inverse import CoilLagCompensator, HysteresisInverse
from sashil.control.kalman import KalmanRigEstimator
from sashil.control.law_api import Law
from sashil.control.law_config import build_law
from sashil.control.law_registry import LawEntry, find_law
from sashil.control.observer import BoucWenObserver
from sashil.control.stages import ConstantCurrent
from sashil.errors import ConfigError

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["controller_section", "law_reads_state", "law_run_label", "make_controller", "make_estimator", "make_stage"]


def law_reads_state(config: RunConfig) -> bool:
    """Whether the config's law reads the rig's state (:attr:`sashil.control.law_api.Law.reads_state`)."""
    return bool(find_law(controller_section(config)["law"]).cls.reads_state)


def _config_law(config: RunConfig, name: str | None = None) -> tuple[LawEntry, Law]:
    """Law ``name`` (None: ``controller.law``) and an instance of it with the parameters of the
    config's ``controller`` section that it declares (the section's others belong to another law; a
    loaded config has been checked against its own law by
    :func:`~sashil.control.law_config.check_controller`)."""
    section = controller_section(config)
    entry = find_law(section["law"] if name is None else name)
    declared = entry.cls.params()
    return entry, build_law(entry, config, {key: value for key, value in section.items() if key in declared})


def law_run_label(config: RunConfig) -> str:
    """What a run calls the config's law in its summary, sub-folders and plots: the law's own
    :meth:`~sashil.control.law_api.Law.label` (``passive 1 A``; its ``name`` by default, however
    ``controller.law`` names it: a file law is not labelled by its path)."""
    return _config_law(config)[1].label()


def make_stage(config: RunConfig) -> tuple[str, Any]:
    """The loop stage of the config's law and its label (:func:`law_run_label`): a
    :class:`Controller`, or for a law that reads no state a constant-current stage that runs the law
    alone (no estimator or observer)."""
    if law_reads_state(config):
        controller = make_controller(None, config)
        return controller.law.label(), controller
    law = _config_law(config)[1]
    return law.label(), ConstantCurrent(law=law)


def controller_section(config: RunConfig) -> dict[str, Any]:
    """The config's ``controller`` section (defaults when a config predates it)."""
    return {**defaults(CONTROLLER.fields), **(config.get("controller") or {})}


def make_estimator(section: dict[str, Any], config: RunConfig, rate_hz: float) -> RigEstimator | KalmanRigEstimator:
    """The ``controller.estimator``: the rig-model Kalman filter or the fixed-bandwidth tracking filters."""
    if section.get("estimator", "kalman") == "kalman":
        estimator = KalmanRigEstimator(
            1.0 / rate_hz,
            accel_psd=float(section["kalman_accel_psd"]),
            road_jerk_psd=float(section["kalman_road_jerk_psd"]),
            bias_psd=float(section["kalman_bias_psd"]),
            angle_noise_rad=float(config["rig"].get("angle_noise_rad") or 0.0),
            innovation_limit=float(section["innovation_limit_counts"]),
            commanded_road_jerk_psd=float(section["kalman_road_jerk_psd_commanded"]),
            quantisation=str(section["kalman_quantisation"]),
            edge_timing=bool(section["edge_timing"]),
        )
        # the gains now, not in the first real-time cycle (the device confirms the resolution)
        estimator.prepare(int(config["rig"]["encoder_counts_per_rev"]))
        return estimator
    return RigEstimator(
        float(section["estimator_bandwidth_hz"]),
        float(section["road_bandwidth_hz"]),
        order=3 if section.get("estimator_order", 2) == 3 else 2,
    )


def make_controller(
    name: str | None,
    config: RunConfig,
    torque: Callable[[float], float] | None = None,
) -> Controller:
    """A :class:`Controller` running law ``name`` (None: ``controller.law``) on the config's model.

    The observer and inverse use ``config['model']`` (the model the controller believes); a
    simulated plant may differ from it (``mismatch`` section, :mod:`sashil.drivers.mismatch`).
    The law takes the section's parameters it declares (:func:`_config_law`). ``torque``: a T*(t)
    signal [N m] for a law with a ``signal`` attribute (``torque-tracking``) instead of its random
    band fraction.
    """
    section = controller_section(config)
    entry, law = _config_law(config, name)
    if law.context is None:  # the law's context holds the model only when it is the rig's Bouc-Wen
        raise ConfigError(f"model.name: the controller runs the bouc-wen model, got {config['model']['name']!r}")
    params = law.context.model
    rig = config["rig"]
    i_max = float(rig["current_max_a"])
    rate_hz = float(config["loop"]["rate_hz"])
    if torque is not None:
        if not hasattr(law, "signal"):
            raise TypeError(f"law {entry.cls.name!r} takes no torque signal")
        setattr(law, "signal", torque)  # noqa: B010 - a law's optional attribute
    tau = section.get("coil_tau_s")
    tau = float(rig["coil_tau_s"] if tau is None else tau)
    return Controller(
        law=law,
        origin=entry.origin,
        estimator=make_estimator(section, config, rate_hz),
        observer=BoucWenObserver(params),
        inverse=HysteresisInverse(params, i_max, float(section["min_authority_nm_per_a"]), section["inverse"]),
        lead=CoilLagCompensator(tau, float(section["lead_horizon_s"]), i_max),
        lead_current_laws=bool(section.get("lead_current_laws", False)),
        current_max_a=i_max,
        model_aided=bool(section["model_aided"]),
        nominal_dt_s=1.0 / rate_hz,
    )
