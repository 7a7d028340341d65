"""The SAS rig plant: arm on a torsion spring with the rotary MR damper (seed 001 eqs. 13-17).

    J * theta2_ddot = -k*theta - c(i)*theta_dot - alpha(i)*z + T_in,    theta = theta2 - theta1

theta1 is the road/wheel-side angle (0 on the bench for a drop test), T_in an optional input
torque. Rewritten in the relative angle the plant integrates:

    J * theta_ddot = -k*theta - c(i)*theta_dot - alpha(i)*z + T_in - J*theta1_ddot

Besides the seed model the plant has what a real rig adds (DESIGN.md, issue "Foundation"): a
first-order coil lag from commanded to actual current, the current limits [0, i_max], and (in the
sensor model of the simulated backend, not here) encoder quantisation and noise.

Integration per sub-step h: the coil current follows its exact first-order response; the arm takes
a trapezoidal-rule step of the linear part (solved in closed form; A-stable, second order, energy
conserving without damping) with the hysteretic torque alpha*z_mid, z_mid the mean of z at the
start and z predicted at the end of the sub-step along the previous sub-step's slope dz/dtheta;
z itself advances over the angle increment
with :class:`~sashil.models.hysteresis.BoucWenZ` (rate-independent, bounded).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from sashil.models.hysteresis import BoucWenParams, BoucWenZ

#: road-side motion: t [s] -> (theta1 [rad], theta1_dot [rad/s], theta1_ddot [rad/s^2])
RoadProfile = Callable[[float], "tuple[float, float, float]"]


@dataclass(slots=True)
class RigState:
    """The true state of the simulated rig."""

    time_s: float = 0.0
    theta_rad: float = 0.0  # relative angle theta = theta2 - theta1
    theta_dot_rad_s: float = 0.0
    z: float = 0.0
    current_a: float = 0.0
    theta_road_rad: float = 0.0
    theta_road_dot_rad_s: float = 0.0
    torque_in_nm: float = 0.0


class RigPlant:
    """Arm + spring + Bouc-Wen MR damper + coil lag; ``step(dt, current_cmd)`` advances it."""

    def __init__(
        self,
        params: BoucWenParams,
        coil_tau_s: float = 0.010,
        current_max_a: float = 1.0,
        max_step_s: float = 0.001,
        road: RoadProfile | None = None,
        torque_in: Callable[[float], float] | None = None,
    ):
        self.params = params
        self._coefficients = (params.J, params.k, params.c1, params.c2, params.alpha1, params.alpha2)
        self.hysteresis = BoucWenZ.from_params(params)
        self.coil_tau_s = float(coil_tau_s)
        self.current_max_a = float(current_max_a)
        self.max_step_s = float(max_step_s)
        self.road = road
        self.torque_in = torque_in
        self.state = RigState()
        self._held_at: float | None = None
        self._slope = 0.0  # dz/dtheta of the last sub-step (the z predictor)
        self._decay_h = -1.0
        self._split_dt = -1.0
        self._split_count = 1
        self._decay = 0.0

    # --- operator actions (what a person does to the bench rig) -------------------------------
    def hold(self, theta_rad: float) -> None:
        """Hold the arm still at ``theta_rad`` (the operator pressing the arm down)."""
        self._held_at = float(theta_rad)
        st = self.state
        self.hysteresis_settle(theta_rad)
        st.theta_rad = float(theta_rad)
        st.theta_dot_rad_s = 0.0

    def release(self) -> None:
        """Let go of the arm."""
        self._held_at = None

    @property
    def held(self) -> bool:
        return self._held_at is not None

    def hysteresis_settle(self, theta_rad: float) -> None:
        """Move z as the damper would while the arm is pressed from its angle to ``theta_rad``."""
        st = self.state
        st.z = self.hysteresis.advance(st.z, theta_rad - st.theta_rad)

    # --- dynamics ----------------------------------------------------------------------------
    def damper_torque(self) -> float:
        """T = alpha(i)*z + c(i)*theta_dot at the current state (seed 001 eq. 9)."""
        st = self.state
        return self.params.torque(st.z, st.theta_dot_rad_s, st.current_a)

    def step(self, dt: float, current_cmd_a: float) -> RigState:
        """Advance the rig by ``dt`` seconds with the coil driven towards ``current_cmd_a``."""
        if dt <= 0.0:
            return self.state
        if dt != self._split_dt:
            self._split_dt = dt
            self._split_count = max(1, math.ceil(dt / self.max_step_s - 1e-9))
        count = self._split_count
        h = dt / count
        cmd = min(max(current_cmd_a, 0.0), self.current_max_a)
        J, k, c1, c2, alpha1, alpha2 = self._coefficients
        advance = self.hysteresis.advance
        z_u = self.hysteresis.z_u
        if h != self._decay_h:
            self._decay_h = h
            self._decay = math.exp(-h / self.coil_tau_s) if self.coil_tau_s > 0.0 else 0.0
        decay = self._decay
        st = self.state
        theta, v, z, i, t = st.theta_rad, st.theta_dot_rad_s, st.z, st.current_a, st.time_s
        road, torque_in = self.road, self.torque_in
        road_acc = 0.0
        tin = 0.0
        held = self._held_at is not None
        slope = self._slope
        for _ in range(count):
            i_next = cmd + (i - cmd) * decay
            i_mid = 0.5 * (i + i_next)
            c = c1 + c2 * i_mid
            alpha = alpha1 + alpha2 * i_mid
            t_mid = t + 0.5 * h
            if road is not None:
                road_acc = road(t_mid)[2]
            if torque_in is not None:
                tin = torque_in(t_mid)
            if held:
                v_next = 0.0
                theta_next = theta
                z_next = z
            else:
                # trapezoidal rule for the linear part (A-stable, 2nd order, keeps the energy of
                # an undamped oscillator), solved in closed form for v_next
                gain = h / J
                lhs = 1.0 + 0.25 * gain * h * k + 0.5 * gain * c
                rhs0 = v * (2.0 - lhs) + gain * (-k * theta + tin - J * road_acc)
                # predictor with z held at its start value, corrector with the sub-step mean of z
                v_pred = (rhs0 - gain * alpha * z) / lhs
                dtheta = 0.5 * h * (v + v_pred)
                if (z >= z_u and dtheta >= 0.0) or (z <= -z_u and dtheta <= 0.0):
                    # saturated in the direction of motion: z stays at its bound
                    v_next = v_pred
                    theta_next = theta + 0.5 * h * (v + v_next)
                    z_next = z
                else:
                    # predict z at the end of the sub-step along the last sub-step's slope
                    # dz/dtheta (>= 0 by eq. 17), correct the torque with the mean of z
                    z_pred = z + slope * 2.0 * dtheta
                    z_pred = z_u if z_pred > z_u else (-z_u if z_pred < -z_u else z_pred)
                    v_next = (rhs0 - gain * alpha * 0.5 * (z + z_pred)) / lhs
                    theta_next = theta + 0.5 * h * (v + v_next)
                    z_next = advance(z, theta_next - theta)
                    if theta_next != theta:
                        slope = (z_next - z) / (theta_next - theta)
            theta, v, z, i, t = theta_next, v_next, z_next, i_next, t + h
        st.theta_rad, st.theta_dot_rad_s, st.z, st.current_a, st.time_s = theta, v, z, i, t
        self._slope = slope
        if road is not None:
            st.theta_road_rad, st.theta_road_dot_rad_s, _ = road(t)
        st.torque_in_nm = tin
        return st
