"""Semi-active laws: what the damper should do this cycle (a desired torque T*, or a current).

Sign convention (seed 001 eq. 13): the damper torque T acts on the arm as -T, on the road side as
+T, and dissipates power T*theta_dot. A law's T* is realisable only when T*·theta_dot > 0 and
inside the feasible band; the inverse (:mod:`sashil.control.inverse`) clips and counts the rest.

* ``passive``: a constant current, no inverse.
* ``target-damping``: T* = c_target*theta_dot, c_target given or from a damping ratio
  zeta = c_target / (2*sqrt(k*J)) of the model (the damper then acts as a linear damper).
* ``skyhook`` (continuous): T* = c_sky*theta2_dot, a damper to the "sky" on the body (arm).
* ``skyhook-onoff``: i_max when theta2_dot*theta_dot > 0, else 0 A (two-state Karnopp skyhook).
* ``skyhook-add``: the mixed skyhook / acceleration-driven-damper on-off law (Savaresi & Spelta
  2007): below the crossover frequency w_f (theta2_ddot^2 <= w_f^2*theta2_dot^2) on when
  theta2_dot*theta_dot > 0 (skyhook), above it on when theta2_ddot*theta_dot > 0 (ADD);
  theta2_ddot = (-k*theta - T_hat)/J from the model. It approximates the lower envelope of the
  soft and the hard passive damper at every frequency.
* ``groundhook``: T* = -c_ground*theta1_dot, a damper to the ground on the road/wheel side.
* ``torque-tracking``: follows a given T*(t), or a band-limited random fraction r(t) of the
  feasible band, T* = T(0) + r(t)*(T(i_max) - T(0)) (for testing the inverse).

Each is a :class:`~sashil.control.law_api.Law` and registers through the ``sashil.laws`` entry
points in ``pyproject.toml``, exactly as a lab's own law does (:mod:`sashil.control.law_registry`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from sashil.control.law_api import Law, LawState, Param
from sashil.errors import ConfigError


def _current_in_range(key: str, value: float, law: Law) -> None:
    """ConfigError naming ``controller.<key>`` when ``value`` lies outside the rig's [0, i_max]."""
    if law.context is not None and not 0.0 <= value <= law.context.current_max_a:
        i_max = law.context.current_max_a
        raise ConfigError(
            f"controller.{key}: expected a current in [0, {i_max:g}] A (rig.current_max_a), got {value:g}"
        )


class Passive(Law):
    """A constant current (no inverse): the damper as a passive damper of c(i), alpha(i)."""

    name = "passive"
    reads_state = False
    current_a = Param(0.0, unit="A", low=0.0, high=10.0, doc="the constant current")

    def label(self) -> str:
        return f"passive {self.current_a:g} A"

    def parameters_changed(self) -> None:
        _current_in_range("current_a", self.current_a, self)

    def current(self, state: LawState) -> float:
        return self.current_a


class TargetDamping(Law):
    """T* = c_target*theta_dot: the damper as a linear damper; c_target given, or from the damping
    ratio zeta = c_target / (2*sqrt(k*J)) of the model, inside [c1, c1 + c2*i_max] (seed 001 eq. 16)."""

    name = "target-damping"
    c_target = Param(None, unit="N m s/rad", low=0.0, low_open=True, doc="linear damping")
    zeta = Param(None, low=0.0, low_open=True, high=10.0, doc="damping ratio instead of c_target")

    def parameters_changed(self) -> None:
        c_target, zeta = self.c_target, self.zeta
        if c_target is None and zeta is None:
            raise ConfigError(
                "controller.zeta: law 'target-damping' needs zeta (damping ratio) or c_target (N m s/rad): "
                "add --set controller.zeta=VALUE"
            )
        if c_target is not None and zeta is not None:
            raise ConfigError("controller.c_target: give either c_target or zeta for law 'target-damping', not both")
        self.c = float(c_target if c_target is not None else 0.0)
        ctx = self.context
        if ctx is None:
            if zeta is not None:
                raise ConfigError("controller.zeta: needs the rig model (build the law with a LawContext)")
            return
        p, i_max = ctx.model, ctx.current_max_a
        c_lo, c_hi = p.c1, p.c1 + p.c2 * i_max
        scale = damping_for_ratio(1.0, p.k, p.J)
        if zeta is not None:
            self.c = damping_for_ratio(float(zeta), p.k, p.J)
            if not c_lo <= self.c <= c_hi:
                raise ConfigError(
                    f"controller.zeta: {zeta:g} is outside what the damper can do: zeta in "
                    f"[{c_lo / scale:.4g}, {c_hi / scale:.4g}] (c(i) = c1 + c2*i for i in [0, {i_max:g}] A)"
                )
        elif not c_lo <= self.c <= c_hi:
            raise ConfigError(
                f"controller.c_target: {self.c:g} N m s/rad is outside what the damper can do: "
                f"[{c_lo:.4g}, {c_hi:.4g}] (c(i) = c1 + c2*i for i in [0, {i_max:g}] A)"
            )

    def torque(self, state: LawState) -> float:
        return self.c * state.theta_dot_rad_s


class Skyhook(Law):
    """Continuous skyhook: T* = c_sky*theta2_dot, a damper from the arm (body) to the "sky"."""

    name = "skyhook"
    c_sky = Param(unit="N m s/rad", low=0.0, low_open=True, doc="sky damping")

    def torque(self, state: LawState) -> float:
        return self.c_sky * state.body_dot_rad_s


class _OnOff(Law):
    """The 'on' current of a two-state law (null: the rig's maximum current)."""

    onoff_current_a = Param(None, unit="A", low=0.0, high=10.0, doc="the 'on' current (null: rig.current_max_a)")

    def parameters_changed(self) -> None:
        on = self.onoff_current_a
        if on is None:
            on = self.context.current_max_a if self.context is not None else 1.0
        _current_in_range("onoff_current_a", on, self)
        self.on, self.off = float(on), 0.0


class SkyhookOnOff(_OnOff):
    """Two-state Karnopp skyhook: the 'on' current when theta2_dot*theta_dot > 0, else 0 A."""

    name = "skyhook-onoff"

    def current(self, state: LawState) -> float:
        return self.on if state.body_dot_rad_s * state.theta_dot_rad_s > 0.0 else self.off


class SkyhookAdd(_OnOff):
    """Mixed skyhook / acceleration-driven-damper on-off law (Savaresi & Spelta 2007).

    Below the crossover w_f (theta2_ddot^2 <= w_f^2*theta2_dot^2) on when theta2_dot*theta_dot > 0
    (skyhook), above it on when theta2_ddot*theta_dot > 0 (ADD); theta2_ddot = (-k*theta - T_hat)/J
    from the model (seed 001 eq. 13). It approximates the lower envelope of the soft and the hard
    passive damper at every frequency.
    """

    name = "skyhook-add"
    crossover_hz = Param(
        None, unit="Hz", low=0.0, low_open=True, high=500.0, doc="crossover (null: sqrt(2) x natural frequency)"
    )

    def parameters_changed(self) -> None:
        super().parameters_changed()
        if self.crossover_hz is not None:
            w = 2.0 * math.pi * float(self.crossover_hz)
        elif self.context is not None:
            w = math.sqrt(2.0 * self.context.model.k / self.context.model.J)
        else:
            raise ConfigError("controller.crossover_hz: needs a value or the rig model (a LawContext)")
        self.w2 = w * w

    def current(self, state: LawState) -> float:
        vb, ab, v = state.body_dot_rad_s, state.body_ddot_rad_s2, state.theta_dot_rad_s
        if ab * ab <= self.w2 * vb * vb:
            return self.on if vb * v > 0.0 else self.off
        return self.on if ab * v > 0.0 else self.off


class Groundhook(Law):
    """Groundhook: T* = -c_ground*theta1_dot, a damper from the road (wheel) side to the ground."""

    name = "groundhook"
    c_ground = Param(unit="N m s/rad", low=0.0, low_open=True, doc="ground damping")

    def torque(self, state: LawState) -> float:
        return -self.c_ground * state.road_dot_rad_s


def band_limited_fraction(
    bandwidth_hz: float, low: float, high: float, seed: int = 0, rate_hz: float = 1000.0, duration_s: float = 60.0
) -> np.ndarray:
    """A seeded random signal in [low, high], low-passed to ``bandwidth_hz`` (periodic table).

    White Gaussian noise through a periodic (FFT) brick-wall low-pass, then scaled so that its
    extremes are ``low`` and ``high``.
    """
    n = int(round(duration_s * rate_hz))
    rng = np.random.default_rng(seed)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    freqs = np.fft.rfftfreq(n, 1.0 / rate_hz)
    spectrum[freqs > bandwidth_hz] = 0.0
    spectrum[0] = 0.0
    signal = np.fft.irfft(spectrum, n)
    signal = (signal - signal.min()) / (signal.max() - signal.min())
    return low + (high - low) * signal


class TorqueTracking(Law):
    """Follows a band-limited random fraction r(t) of the feasible band,
    T* = T(0) + r(t)*(T(i_max) - T(0)), or a given signal T*(t) (``signal``): for testing the inverse."""

    name = "torque-tracking"
    tracking_bandwidth_hz = Param(2.0, unit="Hz", low=0.0, low_open=True, high=500.0, doc="bandwidth of the random T*")
    tracking_fraction = Param([0.1, 0.9], doc="[low, high] fraction of the feasible band")
    tracking_seed = Param(0, low=0, doc="seed of the random T*")

    #: a signal T*(t) [N m] set from Python instead of the random band fraction
    signal: Callable[[float], float] | None = None

    def parameters_changed(self) -> None:
        fraction = self.tracking_fraction
        if len(fraction) != 2 or not 0.0 <= fraction[0] < fraction[1] <= 1.0:
            raise ConfigError(
                f"controller.tracking_fraction: expected [low, high] with 0 <= low < high <= 1, got {fraction!r}"
            )
        rate_hz = self.context.rate_hz if self.context is not None else 1000.0
        if not self.tracking_bandwidth_hz < rate_hz / 2:
            raise ConfigError(
                f"controller.tracking_bandwidth_hz: expected a number in (0, {rate_hz / 2:g}) Hz, "
                f"got {self.tracking_bandwidth_hz:g}"
            )
        table = band_limited_fraction(self.tracking_bandwidth_hz, fraction[0], fraction[1], self.tracking_seed, rate_hz)
        self.fraction = [float(x) for x in table]
        self.rate_hz = rate_hz

    def torque(self, state: LawState) -> float:
        if self.signal is not None:
            return self.signal(state.time_s)
        table = self.fraction
        r = table[int(state.time_s * self.rate_hz) % len(table)]
        return state.band_lo_nm + r * (state.band_hi_nm - state.band_lo_nm)


def damping_for_ratio(zeta: float, k: float, J: float) -> float:
    """c = 2*zeta*sqrt(k*J): the linear damping of damping ratio ``zeta`` for the arm on its spring."""
    return 2.0 * zeta * math.sqrt(k * J)
