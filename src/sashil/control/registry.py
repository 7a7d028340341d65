"""Controllers by name: ``make_controller(name, config)`` builds the law from the ``controller:`` section.

Bad input is one line naming the key: an unknown law, a law without its parameter, a target the
damper cannot reach (a target-damping c_target outside [c1, c1 + c2*i_max] of the model). During a
run an unreachable *torque* is clipped to the feasible band and counted, never an error.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from sashil.config.sections import CONTROL_LAWS
from sashil.control.controller import Controller
from sashil.control.estimator import RigEstimator
from sashil.control.inverse import CoilLagCompensator, HysteresisInverse
from sashil.control.kalman import KalmanRigEstimator
from sashil.control.laws import (
    Groundhook,
    Law,
    Passive,
    Skyhook,
    SkyhookAdd,
    SkyhookOnOff,
    TargetDamping,
    TorqueTracking,
    band_limited_fraction,
    damping_for_ratio,
)
from sashil.control.observer import BoucWenObserver
from sashil.errors import ConfigError
from sashil.models.hysteresis import BoucWenParams
from sashil.models.registry import rig_params

LAWS = CONTROL_LAWS

__all__ = ["LAWS", "controller_section", "make_controller", "make_law"]


def controller_section(config: dict[str, Any]) -> dict[str, Any]:
    """The config's ``controller`` section (defaults when a config predates it)."""
    from sashil.config.schema import defaults
    from sashil.config.sections import CONTROLLER

    return {**defaults(CONTROLLER.fields), **(config.get("controller") or {})}


def _need(section: dict[str, Any], key: str, law: str, what: str) -> float:
    value = section.get(key)
    if value is None:
        raise ConfigError(
            f"controller.{key}: law {law!r} needs {key} ({what}); set it in the config's controller: section"
        )
    if not value > 0:
        raise ConfigError(f"controller.{key}: expected a number > 0 for law {law!r}, got {value!r}")
    return float(value)


def _on_current(section: dict[str, Any], i_max: float) -> float:
    """The 'on' current of the two-state laws (``onoff_current_a``, default i_max)."""
    on = section.get("onoff_current_a")
    on = i_max if on is None else float(on)
    if not 0.0 <= on <= i_max:
        raise ConfigError(f"controller.onoff_current_a: expected a current in [0, {i_max:g}] A, got {on:g}")
    return on


def make_law(name: str, section: dict[str, Any], params: BoucWenParams, i_max: float, rate_hz: float) -> Law:
    """The law ``name`` with its parameters from ``section`` (checked against the model's band)."""
    if name == "passive":
        current = float(section.get("current_a") or 0.0)
        if not 0.0 <= current <= i_max:
            raise ConfigError(
                f"controller.current_a: expected a current in [0, {i_max:g}] A (rig.current_max_a), got {current:g}"
            )
        return Passive(current)
    if name == "target-damping":
        c_target: Any = section.get("c_target")
        zeta: Any = section.get("zeta")
        if c_target is None and zeta is None:
            raise ConfigError(
                "controller.zeta: law 'target-damping' needs zeta (damping ratio) or c_target (N m s/rad)"
            )
        if c_target is not None and zeta is not None:
            raise ConfigError("controller.c_target: give either c_target or zeta for law 'target-damping', not both")
        c_lo, c_hi = params.c1, params.c1 + params.c2 * i_max
        scale = damping_for_ratio(1.0, params.k, params.J)
        if zeta is not None:
            c_target = damping_for_ratio(float(zeta), params.k, params.J)
            if not c_lo <= c_target <= c_hi:
                raise ConfigError(
                    f"controller.zeta: {zeta:g} is outside what the damper can do: zeta in "
                    f"[{c_lo / scale:.4g}, {c_hi / scale:.4g}] (c(i) = c1 + c2*i for i in [0, {i_max:g}] A)"
                )
        elif not c_lo <= float(c_target) <= c_hi:
            raise ConfigError(
                f"controller.c_target: {c_target:g} N m s/rad is outside what the damper can do: "
                f"[{c_lo:.4g}, {c_hi:.4g}] (c(i) = c1 + c2*i for i in [0, {i_max:g}] A)"
            )
        return TargetDamping(float(c_target))
    if name == "skyhook":
        return Skyhook(_need(section, "c_sky", name, "sky damping in N m s/rad"))
    if name == "skyhook-onoff":
        return SkyhookOnOff(_on_current(section, i_max))
    if name == "skyhook-add":
        on = _on_current(section, i_max)
        crossover = section.get("crossover_hz")
        w = math.sqrt(2.0 * params.k / params.J) if crossover is None else 2.0 * math.pi * float(crossover)
        return SkyhookAdd(w, on)
    if name == "groundhook":
        return Groundhook(_need(section, "c_ground", name, "ground damping in N m s/rad"))
    if name == "torque-tracking":
        fraction = section.get("tracking_fraction") or [0.1, 0.9]
        if len(fraction) != 2 or not 0.0 <= fraction[0] < fraction[1] <= 1.0:
            raise ConfigError(
                f"controller.tracking_fraction: expected [low, high] with 0 <= low < high <= 1, got {fraction!r}"
            )
        bandwidth = float(section.get("tracking_bandwidth_hz") or 2.0)
        if not 0.0 < bandwidth < rate_hz / 2:
            raise ConfigError(
                f"controller.tracking_bandwidth_hz: expected a number in (0, {rate_hz / 2:g}) Hz, got {bandwidth:g}"
            )
        table = band_limited_fraction(
            bandwidth, fraction[0], fraction[1], int(section.get("tracking_seed") or 0), rate_hz
        )
        return TorqueTracking(fraction=table, rate_hz=rate_hz)
    raise ConfigError(f"controller.law: unknown law {name!r} (known: {', '.join(LAWS)})")


def make_estimator(
    section: dict[str, Any], config: dict[str, Any], rate_hz: float
) -> RigEstimator | KalmanRigEstimator:
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
    config: dict[str, Any],
    torque: Callable[[float], float] | None = None,
) -> Controller:
    """A :class:`Controller` running law ``name`` (None: ``controller.law``) on the config's model.

    The observer and inverse use ``config['model']`` (the model the controller believes); a
    simulated plant may differ from it (``mismatch`` section, :mod:`sashil.models.mismatch`).
    ``torque``: for law ``torque-tracking``, a T*(t) signal [N m] instead of the random band fraction.
    """
    section = controller_section(config)
    name = section["law"] if name is None else name
    if name not in LAWS:
        raise ConfigError(f"controller.law: unknown law {name!r} (known: {', '.join(LAWS)})")
    params = rig_params(config["model"])
    rig = config["rig"]
    i_max = float(rig["current_max_a"])
    rate_hz = float(config["loop"]["rate_hz"])
    if name == "torque-tracking" and torque is not None:
        law: Law = TorqueTracking(torque=torque)
    else:
        law = make_law(name, section, params, i_max, rate_hz)
    tau = section.get("coil_tau_s")
    tau = float(rig["coil_tau_s"] if tau is None else tau)
    return Controller(
        law=law,
        estimator=make_estimator(section, config, rate_hz),
        observer=BoucWenObserver(params),
        inverse=HysteresisInverse(params, i_max, float(section["min_authority_nm_per_a"]), section["inverse"]),
        lead=CoilLagCompensator(tau, float(section["lead_horizon_s"]), i_max),
        current_max_a=i_max,
        model_aided=bool(section["model_aided"]),
        nominal_dt_s=1.0 / rate_hz,
    )
