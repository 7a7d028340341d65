"""Bouc-Wen observer: z-hat over the estimated angle increments and the predicted damper torque.

Seed 001 eqs. 9-12 and 17. The hysteretic state does not depend on the current, so the observer
runs the model's own stable, rate-independent z-update
(:meth:`sashil.models.hysteresis.BoucWenZ.advance`) over each cycle's increment of the estimated
relative angle (open-loop model observer; under persistent motion z forgets its initial value).
The controller advances z over the increment of the estimated rate (``update_increment``, see
:mod:`sashil.control.controller`); ``update`` takes angle samples instead.
The torque prediction uses the *measured* coil current where the rig reports it::

    T_hat = alpha(i_meas) * z_hat + c(i_meas) * theta_dot_hat          (eq. 9)
"""

from __future__ import annotations

from sashil.models.hysteresis import BoucWenParams, BoucWenZ, advance_z


class BoucWenObserver:
    """z-hat and T-hat from the estimated angle, its rate and the measured current."""

    __slots__ = ("_constants", "_started", "_theta", "hysteresis", "params", "torque_nm", "z")

    def __init__(self, params: BoucWenParams, z0: float = 0.0):
        self.params = params
        self.hysteresis = BoucWenZ.from_params(params)
        # compile (or load from numba's cache) the z-update now, not in the first real-time cycle:
        # over a link that first cycle would otherwise stall about 0.5 s
        self.hysteresis.advance(0.0, 1e-9)
        law = self.hysteresis
        self._constants = (law.beta, law.gamma, law.delta, law.n, law.z_u)
        self.z = float(z0)
        self.torque_nm = 0.0
        self._theta = 0.0
        self._started = False

    def update(self, theta_rad: float, theta_dot_rad_s: float, current_a: float) -> float:
        """Advance z-hat to ``theta_rad`` and return T-hat at ``current_a``."""
        if self._started:
            self.z = self.hysteresis.advance(self.z, theta_rad - self._theta)
        else:
            self._started = True
        self._theta = theta_rad
        return self._torque(theta_dot_rad_s, current_a)

    def update_increment(self, dtheta_rad: float, theta_dot_rad_s: float, current_a: float) -> float:
        """Advance z-hat over the angle increment ``dtheta_rad`` (a float) and return T-hat at
        ``current_a``: the controller's per-cycle call, straight to the compiled z-update with the
        model's constants (:func:`~sashil.models.hysteresis.advance_z`, what ``hysteresis.advance`` calls)."""
        self.z = z = advance_z(self.z, dtheta_rad, *self._constants)
        self.torque_nm = torque = self.params.torque(z, theta_dot_rad_s, current_a)
        return torque

    def _torque(self, theta_dot_rad_s: float, current_a: float) -> float:
        self.torque_nm = self.params.torque(self.z, theta_dot_rad_s, current_a)
        return self.torque_nm
