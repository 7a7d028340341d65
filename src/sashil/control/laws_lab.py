"""The laws a semi-active suspension lab compares itself against (beside :mod:`sashil.control.laws`).

Sign convention as there (seed 001 eq. 13): the damper torque T acts on the arm as −T, on the road
side as +T, and is realisable only when T·θ̇ > 0 and inside the feasible band.

* ``clipped-optimal`` (Dyke, Spencer, Sain & Carlson 1996): the LQR torque T* of
  :mod:`sashil.control.lqr`, and the damper switched on (the 'on' current) when T* and the damper's
  torque have the same sign and T* is the larger, off otherwise: i = i_on·H((T* − T)·T) (their
  eq. 10, the force sensor replaced by the observer's T̂).
* ``lqr-clipped``: the same T* given to the inverse, which clips it to the feasible band.
* ``pdd``, the power-driven damper (Morselli & Zanasi 2008, Mechatronics 18, eq. 21):
  c = sat(−k·θ/θ̇) inside [c_min, c_max], T* = c·θ̇ (the damper cancels the spring when it can).
* ``groundhook-hybrid`` (Ahmadian & Pare 2000, hybrid control): T* = c_hybrid·(w·θ̇2 − (1 − w)·θ̇1),
  a weighted sum of skyhook (w = 1) and groundhook (w = 0).
"""

from __future__ import annotations

from sashil.control.law_api import Law, LawState, Param
from sashil.control.lqr import scaled_lqr_gains
from sashil.errors import ConfigError
from sashil.models.hysteresis import BoucWenParams

__all__ = ["ClippedOptimal", "GroundhookHybrid", "LqrClipped", "PowerDrivenDamper"]


def _model(law: Law, key: str) -> tuple[BoucWenParams, float]:
    """The law context's model and i_max, or ConfigError naming ``controller.<key>``."""
    if law.context is None:
        raise ConfigError(f"controller.{key}: law {law.name!r} needs the rig model (build it with a LawContext)")
    return law.context.model, law.context.current_max_a


class _Lqr(Law):
    """T* = c_n·θ̇ − (k_θ·θ + k_v·θ̇2), the LQR torque on the rig's linear model (:mod:`sashil.control.lqr`,
    Dyke et al. 1996 eqs. 5-8), solved once, when the parameters are set. The weights are relative to
    the rig's own scales (:func:`sashil.control.lqr.scaled_weights`, ω_n² = k/J): the cost is
    q_accel·θ̈2² + q_theta·ω_n⁴·θ² + q_body_dot·ω_n²·θ̇2² + r_torque·(u/J)², so one set of weights is
    the same design on any J and k."""

    q_accel = Param(1.0, low=0.0, doc="weight of the arm acceleration θ̈2²")
    q_theta = Param(0.5, low=0.0, doc="weight of the relative angle θ² (suspension travel), in units of ω_n⁴ = (k/J)²")
    q_body_dot = Param(0.0, low=0.0, doc="weight of the arm rate θ̇2², in units of ω_n² = k/J")
    r_torque = Param(0.0, low=0.0, doc="weight of the torque u beyond c_n·θ̇, in units of 1/J²")
    lqr_current_a = Param(0.0, unit="A", low=0.0, high=10.0, doc="nominal current of the model's viscous part c_n")

    def parameters_changed(self) -> None:
        p, i_max = _model(self, "q_accel")
        if not self.lqr_current_a <= i_max:
            raise ConfigError(
                f"controller.lqr_current_a: expected a current in [0, {i_max:g}] A (rig.current_max_a), got {self.lqr_current_a:g}"
            )
        self.c_n = p.damping(self.lqr_current_a)
        self.design = scaled_lqr_gains(p.J, p.k, self.c_n, self.q_accel, self.q_theta, self.q_body_dot, self.r_torque)
        self.k_theta, self.k_body = self.design.k_theta, self.design.k_body

    def desired(self, state: LawState) -> float:
        """The LQR's desired damper torque T* [N m]."""
        return self.c_n * state.theta_dot_rad_s - self.k_theta * state.theta_rad - self.k_body * state.body_dot_rad_s


class LqrClipped(_Lqr):
    """The LQR torque T* of :class:`_Lqr` through the inverse (clipped to the feasible band)."""

    name = "lqr-clipped"

    def torque(self, state: LawState) -> float:
        return self.desired(state)


class ClippedOptimal(_Lqr):
    """Clipped-optimal control (Dyke, Spencer, Sain & Carlson 1996, eq. 10): i = i_on·H((T* − T̂)·T̂),
    T* the LQR torque of :class:`_Lqr`, T̂ the observer's damper torque (seed 001 eq. 12) in
    place of the measured force: on when both have the same sign and |T*| > |T̂|, else 0 A."""

    name = "clipped-optimal"
    onoff_current_a = Param(None, unit="A", low=0.0, high=10.0, doc="the 'on' current (null: rig.current_max_a)")

    def parameters_changed(self) -> None:
        super().parameters_changed()
        _, i_max = _model(self, "onoff_current_a")
        on = i_max if self.onoff_current_a is None else float(self.onoff_current_a)
        if not on <= i_max:
            raise ConfigError(
                f"controller.onoff_current_a: expected a current in [0, {i_max:g}] A (rig.current_max_a), got {on:g}"
            )
        self.on = on

    def current(self, state: LawState) -> float:
        t_hat = state.torque_hat_nm
        return self.on if (self.desired(state) - t_hat) * t_hat > 0.0 else 0.0


class PowerDrivenDamper(Law):
    """Power-driven damper (Morselli & Zanasi 2008, eq. 21): c = sat(−k_pdd·θ/θ̇) inside
    [c_min, c_max], T* = c·θ̇ through the inverse; k_pdd defaults to the model's spring k, the band to
    the viscous envelope [c1, c1 + c2·i_max] (seed 001 eq. 11)."""

    name = "pdd"
    pdd_gain = Param(None, unit="N m/rad", low=0.0, low_open=True, doc="stiffness the damper cancels (null: model k)")
    c_min = Param(None, unit="N m s/rad", low=0.0, doc="lowest damping (null: c1)")
    c_max = Param(None, unit="N m s/rad", low=0.0, low_open=True, doc="highest damping (null: c1 + c2*i_max)")

    def parameters_changed(self) -> None:
        p, i_max = _model(self, "pdd_gain")
        self.gain = p.k if self.pdd_gain is None else float(self.pdd_gain)
        self.lo = p.c1 if self.c_min is None else float(self.c_min)
        self.hi = p.damping(i_max) if self.c_max is None else float(self.c_max)
        if not self.lo < self.hi:
            raise ConfigError(f"controller.c_max: expected c_max > c_min, got [{self.lo:g}, {self.hi:g}] N m s/rad")

    def torque(self, state: LawState) -> float:
        v = state.theta_dot_rad_s
        if v == 0.0:
            return 0.0
        c = -self.gain * state.theta_rad / v
        c = self.lo if c < self.lo else self.hi if c > self.hi else c
        return c * v


class GroundhookHybrid(Law):
    """Hybrid skyhook-groundhook (Ahmadian & Pare 2000): T* = c_hybrid·(w·θ̇2 − (1 − w)·θ̇1), w the
    weight of skyhook; c_hybrid defaults to the damper's largest viscous damping c1 + c2·i_max."""

    name = "groundhook-hybrid"
    hybrid_weight = Param(0.8, low=0.0, high=1.0, doc="weight of skyhook (1) against groundhook (0)")
    c_hybrid = Param(None, unit="N m s/rad", low=0.0, low_open=True, doc="damping (null: c1 + c2*i_max)")

    def parameters_changed(self) -> None:
        p, i_max = _model(self, "c_hybrid")
        c = p.damping(i_max) if self.c_hybrid is None else float(self.c_hybrid)
        self.c_sky, self.c_ground = c * self.hybrid_weight, c * (1.0 - self.hybrid_weight)

    def torque(self, state: LawState) -> float:
        return self.c_sky * state.body_dot_rad_s - self.c_ground * state.road_dot_rad_s
