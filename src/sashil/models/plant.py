"""The SAS rig plant: arm on a torsion spring with the rotary MR damper (seed 001 eqs. 13-17).

    J * theta2_ddot = -k*theta - c(i)*theta_dot - alpha(i)*z + T_in,    theta = theta2 - theta1

theta1 is the road/wheel-side angle (0 on the bench for a drop test), T_in an optional input
torque. Rewritten in the relative angle the plant integrates:

    J * theta_ddot = -k*theta - c(i)*theta_dot - alpha(i)*z + T_in - J*theta1_ddot

Besides the seed model the plant has what a real rig adds (docs/architecture.md): a
first-order coil lag from commanded to actual current, the current limits [0, i_max], and (in the
sensor model of the simulated backend, not here) encoder quantisation and noise.

Integration per sub-step h: the coil current follows its exact first-order response; the arm takes
a trapezoidal-rule step of the linear part (solved in closed form; A-stable, second order, energy
conserving without damping) with the hysteretic torque alpha*z_mid, z_mid the mean of z at the
start and z predicted at the end of the sub-step; z itself advances over the angle increment with
:func:`~sashil.models.hysteresis.advance_z` (rate-independent, bounded). The sub-step is
:func:`rig_substep`, a plain function of floats compiled with numba.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from sashil.models._jit import jit, loop_kernel
from sashil.models.hysteresis import BoucWenParams, BoucWenZ, advance_z

#: road-side motion: t [s] -> (theta1 [rad], theta1_dot [rad/s], theta1_ddot [rad/s^2]); a profile
#: whose theta1_ddot is always 0 may say so with an attribute ``accelerates = False`` (the plant then
#: skips the road's force, which is 0)
RoadProfile = Callable[[float], "tuple[float, float, float]"]


@dataclass(slots=True)
class PlantState:
    """The true state of the simulated rig."""

    time_s: float = 0.0
    theta_rad: float = 0.0  # relative angle theta = theta2 - theta1
    theta_dot_rad_s: float = 0.0
    z: float = 0.0
    current_a: float = 0.0
    theta_road_rad: float = 0.0
    theta_road_dot_rad_s: float = 0.0
    torque_in_nm: float = 0.0


@loop_kernel(
    lambda: (0.0, 0.0, 0.0, 0.0, 1e-3, 0.0, 0.0, 1.0, 109.0, 0.7, 1.5, 1.0, 1.0, 873.0, 1.0, 700.0, 0.099, 0.9, 0.0)
)
@jit
def rig_substep(
    theta: float,
    v: float,
    z: float,
    i: float,
    h: float,
    cmd: float,
    decay: float,
    J: float,
    k: float,
    c1: float,
    c2: float,
    alpha1: float,
    alpha2: float,
    beta: float,
    gamma: float,
    delta: float,
    n: float,
    z_u: float,
    force: float,
) -> tuple[float, float, float, float]:
    """One sub-step h of the released arm (seed 001 eqs. 13-17); returns (theta, v, z, i).

    ``force`` is the torque from outside the arm-spring-damper: T_in - J*theta1_ddot. The coil
    current follows its exact first-order response towards ``cmd`` (``decay`` = exp(-h/tau)). The
    linear part takes a trapezoidal-rule step solved in closed form for the new rate; the
    hysteretic torque uses the mean of z at the start and z predicted at the end (z advanced over
    the angle increment of a predictor step that holds z); z then advances over the corrected
    angle increment with :func:`~sashil.models.hysteresis.advance_z`.
    """
    i_next = cmd + (i - cmd) * decay
    i_mid = 0.5 * (i + i_next)
    c = c1 + c2 * i_mid
    alpha = alpha1 + alpha2 * i_mid
    gain = h / J
    lhs = 1.0 + 0.25 * gain * h * k + 0.5 * gain * c
    rhs0 = v * (2.0 - lhs) + gain * (-k * theta + force)
    v_next = (rhs0 - gain * alpha * z) / lhs
    dtheta = 0.5 * h * (v + v_next)
    if (z >= z_u and dtheta >= 0.0) or (z <= -z_u and dtheta <= 0.0):
        # saturated in the direction of motion: z stays at its bound
        return theta + dtheta, v_next, z, i_next
    z_pred = advance_z(z, dtheta, beta, gamma, delta, n, z_u)
    v_next = (rhs0 - gain * alpha * 0.5 * (z + z_pred)) / lhs
    theta_next = theta + 0.5 * h * (v + v_next)
    z_next = advance_z(z, theta_next - theta, beta, gamma, delta, n, z_u)
    return theta_next, v_next, z_next, i_next


def _coil_drive(current_a: float, current_max_a: float) -> float:
    """The current the coil's driver can drive towards: [0, i_max], NaN -> 0 A. The driver
    saturates as the host's command clamp does (``sashil.drivers.interface.clamp_current``, which
    the backends and the safety supervisor apply before a command reaches a plant)."""
    if current_a != current_a:  # NaN
        return 0.0
    return min(max(current_a, 0.0), current_max_a)


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
        self.hysteresis = BoucWenZ.from_params(params)
        self._coefficients = (
            params.J,
            params.k,
            params.c1,
            params.c2,
            params.alpha1,
            params.alpha2,
            params.beta,
            params.gamma,
            params.delta,
            params.n,
            self.hysteresis.z_u,
        )
        # compile (or load from numba's cache) now, not in the first real-time cycle
        rig_substep(0.0, 0.0, 0.0, 0.0, 1e-3, 0.0, 0.0, *self._coefficients, 0.0)
        self.coil_tau_s = float(coil_tau_s)
        self.current_max_a = float(current_max_a)
        self.max_step_s = float(max_step_s)
        self.road = road
        self.torque_in = torque_in
        self.state = PlantState()
        self._held_at: float | None = None
        self._split_dt = -1.0
        self._split = (1, 0.0, 0.0)  # sub-steps, their length and the coil's decay over one

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

    def step(self, dt: float, current_cmd_a: float) -> PlantState:
        """Advance the rig by ``dt`` seconds with the coil driven towards ``current_cmd_a``."""
        if dt <= 0.0:
            return self.state
        if dt != self._split_dt:
            count = max(1, math.ceil(dt / self.max_step_s - 1e-9))
            h = dt / count
            decay = math.exp(-h / self.coil_tau_s) if self.coil_tau_s > 0.0 else 0.0
            self._split_dt, self._split = dt, (count, h, decay)
        count, h, decay = self._split
        # floats only: numba compiles one signature (an int here would compile another mid-run)
        cmd = _coil_drive(float(current_cmd_a), self.current_max_a)
        st = self.state
        theta, v, z, i, t = st.theta_rad, st.theta_dot_rad_s, st.z, st.current_a, st.time_s
        road, torque_in = self.road, self.torque_in
        tin = 0.0
        if self._held_at is not None:
            for _ in range(count):
                i = cmd + (i - cmd) * decay
            t += count * h
        else:
            J, k, c1, c2, alpha1, alpha2, beta, gamma, delta, n, z_u = self._coefficients
            force = 0.0
            # a road that never accelerates (a wheel whose speed steps are applied as jumps) adds no force
            forced = torque_in is not None or (road is not None and getattr(road, "accelerates", True))
            for _ in range(count):
                if forced:
                    t_mid = t + 0.5 * h
                    tin = 0.0 if torque_in is None else float(torque_in(t_mid))
                    force = tin - (0.0 if road is None else J * road(t_mid)[2])
                theta, v, z, i = rig_substep(
                    theta, v, z, i, h, cmd, decay, J, k, c1, c2, alpha1, alpha2, beta, gamma, delta, n, z_u, force
                )
                t += h
        st.theta_rad, st.theta_dot_rad_s, st.z, st.current_a, st.time_s = theta, v, z, i, t
        if road is not None:
            st.theta_road_rad, st.theta_road_dot_rad_s, _ = road(t)
        st.torque_in_nm = tin
        return st
