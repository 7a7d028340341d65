"""The controller loop stage: estimator -> observer -> law -> inverse -> coil lead -> safety clamp.

``step(sample, t_ns, dt_ns) -> RigCommand`` (the loop's stage protocol). The per-cycle values
(``theta_dot_rad_s``, ``z_hat``, ``torque_hat_nm``, ``torque_cmd_nm``, the band, the currents) are
plain attributes overwritten every cycle, for a recorder to copy; the returned command object is
reused (no allocation per cycle).

The estimator's model acceleration for the next cycle comes from the rig model
(seed 001 eq. 13): ``theta2_ddot = (-k*theta - T_hat)/J`` (the relative channel subtracts theta1_ddot).

Road feed-forward: a plan that drives the road sets ``road_speed_rad_s`` on the command this stage
returns (the sweep does); the change of that speed from one cycle to the next is the road
acceleration the estimator is given for the next period (:mod:`sashil.control.kalman`).

Fallback: when the estimator reports divergence (its innovation out of bounds, e.g. a wildly wrong
J) or a non-finite estimate, the stage commands 0 A (the MR damper's passive, safe state) for the
rest of the run; :meth:`Controller.stats` reports it for summary.json.
"""

from __future__ import annotations

import math

from sashil.control.estimator import RigEstimator
from sashil.control.inverse import CoilLagCompensator, HysteresisInverse
from sashil.control.kalman import KalmanRigEstimator
from sashil.control.laws import Law
from sashil.control.observer import BoucWenObserver
from sashil.drivers.interface import RigCommand, RigSample, clamp_current

NAN = float("nan")


class Controller:
    """One semi-active controller; see the module docstring for the cycle."""

    def __init__(
        self,
        law: Law,
        estimator: RigEstimator | KalmanRigEstimator,
        observer: BoucWenObserver,
        inverse: HysteresisInverse,
        lead: CoilLagCompensator,
        current_max_a: float,
        model_aided: bool = True,
        nominal_dt_s: float = 0.001,
    ):
        self.law = law
        self.estimator = estimator
        self.observer = observer
        self.inverse = inverse
        self.lead = lead
        self.current_max_a = float(current_max_a)
        self.model_aided = bool(model_aided)
        self.nominal_dt_s = float(nominal_dt_s)
        p = observer.params
        self._k_over_j, self._inv_j = p.k / p.J, 1.0 / p.J
        self.command = RigCommand(0.0)
        #: set by an experiment while something outside the model holds the arm (drop-test hold)
        self.held = False
        self._t0_ns: int | None = None
        self._accel = 0.0
        self._road_speed: float | None = None
        self._v_prev = 0.0
        # per-cycle values (recorded by the caller)
        self.time_s = 0.0
        self.theta_rad = 0.0
        self.theta_dot_rad_s = 0.0
        self.body_dot_rad_s = 0.0
        self.body_ddot_rad_s2 = 0.0  # model: (-k*theta - T_hat)/J
        self.road_dot_rad_s = 0.0
        self.z_hat = 0.0
        self.torque_hat_nm = 0.0
        self.torque_cmd_nm = NAN
        self.band_lo_nm = 0.0
        self.band_hi_nm = 0.0
        self.current_target_a = 0.0
        self.current_cmd_a = 0.0
        self.cycles = 0
        self.unsafe_count = 0  # commands the safety clamp had to change (NaN or outside [0, i_max])
        self.fallback = False  # latched when the estimator fails: 0 A for the rest of the run
        self.fallback_at_s: float | None = None
        self.fallback_cycles = 0

    def _fallback_step(self) -> RigCommand:
        """0 A (the safe state of an MR damper) once the estimator has failed; counted per cycle."""
        self.fallback_cycles += 1
        self.cycles += 1
        self.torque_cmd_nm = NAN
        self.current_target_a = self.current_cmd_a = 0.0
        self.command.current_a = 0.0
        return self.command

    def stats(self) -> dict[str, object]:
        """Counters for summary.json: clipped/passive cycles, unsafe commands, the estimator fallback."""
        return {
            "clipped_cycles": self.inverse.clip_count,
            "passive_cycles": self.inverse.passive_count,
            "unsafe_commands": self.unsafe_count,
            "fallback": self.fallback,
            "fallback_at_s": self.fallback_at_s,
            "fallback_cycles": self.fallback_cycles,
            "innovations_out": int(getattr(self.estimator, "innovations_out", 0)),
        }

    @property
    def name(self) -> str:
        return self.law.name

    @property
    def clip_count(self) -> int:
        """Cycles whose target torque lay outside the damper's feasible band (clipped)."""
        return self.inverse.clip_count

    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand:
        if self._t0_ns is None:
            self._t0_ns = t_ns
        dt = dt_ns * 1e-9 if dt_ns > 0 else self.nominal_dt_s
        self.time_s = (t_ns - self._t0_ns) * 1e-9
        est = self.estimator
        # the road speed a plan put on last cycle's command (sweeps): its change is the road's
        # acceleration, known to the estimator instead of inferred from the road encoder alone
        speed = self.command.road_speed_rad_s
        if speed is None or speed != speed:
            road_accel = None
            self._road_speed = None
        else:
            road_accel = 0.0 if self._road_speed is None else (speed - self._road_speed) / dt
            self._road_speed = speed
        est.update(sample, dt, self._accel, road_accel)  # model body acceleration of the last cycle
        theta, v = est.theta_rad, est.theta_dot_rad_s
        if not self.fallback and (getattr(est, "diverged", False) or not math.isfinite(v) or not math.isfinite(theta)):
            # the model cannot explain the motion (innovation out of bounds) or the estimate is not a number:
            # the safe law (0 A: the damper fails passive) for the rest of the run
            self.fallback = True
            self.fallback_at_s = self.time_s
        if self.fallback:
            return self._fallback_step()
        self.theta_rad, self.theta_dot_rad_s = theta, v
        self.body_dot_rad_s, self.road_dot_rad_s = est.body_dot_rad_s, est.road_dot_rad_s
        measured = sample.current_a
        if measured != measured:  # no current sensor reading: assume the last command flows
            measured = self.current_cmd_a
        obs = self.observer
        # z-hat advances over the angle increment of the estimated rate (trapezoidal), not over the
        # filtered angle's increments: a count arriving makes the filtered angle step back and
        # forth by a fraction of a count, enough to flip z (it saturates within ~3e-4 rad)
        torque_hat = obs.update_increment(0.5 * (v + self._v_prev) * dt, v, measured)
        self._v_prev = v
        z = obs.z
        self.z_hat, self.torque_hat_nm = z, torque_hat
        body_ddot = -self._k_over_j * theta - self._inv_j * torque_hat
        self.body_ddot_rad_s2 = body_ddot
        inv = self.inverse
        law = self.law
        if law.direct:
            inv.band(z, v)
            self.torque_cmd_nm = NAN
            target = law.output(self)
            self.band_lo_nm, self.band_hi_nm = inv.band_lo_nm, inv.band_hi_nm
        else:
            inv.band(z, v)
            self.band_lo_nm, self.band_hi_nm = inv.band_lo_nm, inv.band_hi_nm
            torque_cmd = law.output(self)
            self.torque_cmd_nm = torque_cmd
            target = inv.current(torque_cmd, z, v)
        self.current_target_a = target
        cmd = self.lead.command(target, measured)
        # safety clamp: the coil only ever sees a finite current in [0, i_max]
        safe = clamp_current(cmd, self.current_max_a)
        if safe != cmd:  # outside [0, i_max], or NaN (never equal to itself)
            self.unsafe_count += 1
        cmd = safe
        self.current_cmd_a = cmd
        if self.model_aided:
            # an arm held by hand does not accelerate, whatever the model's torques say
            self._accel = 0.0 if self.held else body_ddot
        self.cycles += 1
        self.command.current_a = cmd
        return self.command
