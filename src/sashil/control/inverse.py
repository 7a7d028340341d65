"""Inverse hysteresis: the coil current that makes the damper give a desired torque.

Seed 001 eqs. 9-12 solved for the current (research/peers_boucwen.md section 4.2)::

    T(i)  = (alpha1 + alpha2*i)*z + (c1 + c2*i)*v      linear in i, slope D = alpha2*z + c2*v
    i*    = (T* - alpha1*z - c1*v) / D,  clipped to [0, i_max]
    i*    = 0  when |D| < min_authority (the current changes nothing)

Because T is linear (so monotone) in i, the clipped i* is the current whose predicted torque is
closest to T* inside the feasible band [T(0), T(i_max)] at the observed (z, v): a T* outside the
band gets the nearer end, counted as clipped. This holds also just after a reversal, when z has not
yet followed the rate and T(0) has the opposite sign to v.

``mode="rule"`` is the earlier comparison inverse that, in addition, commands 0 A whenever
T*·v <= 0 ("the damper can only dissipate"): right for the viscous part, wrong while z lags the rate.

``mode="viscous"`` is the comparison inverse that ignores the hysteresis (alpha = 0) and keeps the
T*·v <= 0 rule: i* = (T* - c1*v) / (c2*v).

Coil lag (:class:`CoilLagCompensator`): the coil follows its command with a first-order lag tau,
``i(t+H) = i_cmd + (i_now - i_cmd)*exp(-H/tau)``; commanding
``i_cmd = i_now + (i* - i_now) / (1 - exp(-H/tau))`` (clipped) brings the measured current
``i_now`` to i* within the horizon H if held; re-evaluated every cycle (receding horizon) each
period closes gain*(1 - exp(-T/tau)) of the gap. H = 0 turns the compensation off.
"""

from __future__ import annotations

import math

from sashil.models.hysteresis import BoucWenParams

#: the inverses by name: the band-closest one, the T*·v rule, the viscous-only one
INVERSE_MODES = ("full", "rule", "viscous")


class HysteresisInverse:
    """T* -> i* for the Bouc-Wen damper (per-cycle, plain floats, no allocation)."""

    __slots__ = (
        "band_hi_nm",
        "band_lo_nm",
        "clip_count",
        "clipped",
        "i_max",
        "min_authority",
        "mode",
        "params",
        "passive_count",
        "rule",
        "viscous_only",
    )

    def __init__(self, params: BoucWenParams, i_max: float, min_authority_nm_per_a: float = 1e-3, mode: str = "full"):
        if mode not in INVERSE_MODES:
            raise ValueError(f"inverse mode must be one of {', '.join(INVERSE_MODES)}, got {mode!r}")
        self.params = params
        self.i_max = float(i_max)
        self.min_authority = float(min_authority_nm_per_a)
        self.mode = mode
        self.viscous_only = mode == "viscous"
        self.rule = mode != "full"  # 0 A when T*·v <= 0
        self.band_lo_nm = 0.0
        self.band_hi_nm = 0.0
        self.clipped = False
        self.clip_count = 0  # cycles whose T* lay outside the feasible band
        self.passive_count = 0  # cycles at 0 A by the T*·v rule or for too little authority

    def band(self, z: float, v: float) -> tuple[float, float]:
        """Set the feasible band [T(0), T(i_max)] at state (z, v); returns eq. 9's line (T(0), dT/di)."""
        at_zero, per_ampere = self.params.torque_line(z, v)
        self.band_lo_nm = at_zero
        self.band_hi_nm = at_zero + per_ampere * self.i_max
        return at_zero, per_ampere

    def current(self, torque_nm: float, z: float, v: float) -> float:
        """i* for the desired torque ``torque_nm`` at the observed z and rate v."""
        at_zero, authority = self.band(z, v)
        return self.solve(torque_nm, at_zero, authority, v)

    def solve(self, torque_nm: float, at_zero: float, authority: float, v: float) -> float:
        """i* for ``torque_nm`` on the line :meth:`band` set this cycle (``at_zero`` = T(0), ``authority``
        = dT/di) at the rate ``v``: the controller sets the band once a cycle and solves on it."""
        if self.viscous_only:  # the comparison inverse without the hysteresis (alpha = 0)
            at_zero, authority = self.params.torque_line(0.0, v)
        if self.rule and torque_nm * v <= 0.0:
            self.clipped = False
            self.passive_count += 1
            return 0.0
        if -self.min_authority < authority < self.min_authority:
            self.clipped = False
            self.passive_count += 1
            return 0.0
        i = (torque_nm - at_zero) / authority
        if i < 0.0:
            self.clipped = True
            self.clip_count += 1
            return 0.0
        if i > self.i_max:
            self.clipped = True
            self.clip_count += 1
            return self.i_max
        if i != i:  # a NaN target: the damper's safe state
            self.clipped = True
            self.clip_count += 1
            return 0.0
        self.clipped = False
        return i


class CoilLagCompensator:
    """Lead for the coil's first-order lag: reach the target current within ``horizon_s``."""

    __slots__ = ("gain", "horizon_s", "i_max", "tau_s")

    def __init__(self, tau_s: float, horizon_s: float, i_max: float):
        self.tau_s = float(tau_s)
        self.horizon_s = float(horizon_s)
        self.i_max = float(i_max)
        active = self.tau_s > 0.0 and self.horizon_s > 0.0
        self.gain = 1.0 / (1.0 - math.exp(-self.horizon_s / self.tau_s)) if active else 1.0

    def command(self, target_a: float, measured_a: float) -> float:
        """The coil command for ``target_a`` given the current flowing now (``measured_a``)."""
        if self.gain == 1.0 or measured_a != measured_a:
            return target_a
        cmd = measured_a + (target_a - measured_a) * self.gain
        if cmd < 0.0:
            return 0.0
        if cmd > self.i_max:
            return self.i_max
        return cmd
