"""LQR on the rig's linear model: the gains of the clipped-optimal and lqr-clipped laws.

The rig (seed 001 eq. 13) with the damper's viscous part at a nominal current i_n kept in the
plant and the rest of the damper torque as the input u:

    J θ̈2 = −k θ − c_n θ̇ − u,   θ = θ2 − θ1,   c_n = c1 + c2·i_n (seed 001 eq. 11)

State x = [θ, θ̇2] (relative angle, arm rate); the road rate θ̇1 enters as a disturbance, white for an
ISO 8608 road of waviness 2 (its velocity PSD is flat), which is the assumption of the quarter-car
LQR (Dyke, Spencer, Sain & Carlson 1996, Smart Mater. Struct. 5, eqs. 5-8):

    ẋ = A x + B u,  A = [[0, 1], [−k/J, −c_n/J]],  B = [0, −1/J]ᵀ
    θ̈2 = C x + D u,  C = [−k/J, −c_n/J],  D = −1/J

Cost ∫ q_a θ̈2² + q_θ θ² + q_v θ̇2² + r u² dt, i.e. Q = q_a CᵀC + diag(q_θ, q_v), cross term
N = q_a CᵀD, R = q_a D² + r; the gain K = R⁻¹(BᵀP + Nᵀ) from the continuous algebraic Riccati
equation (scipy.linalg.solve_continuous_are), u* = −K x. A solution whose closed loop has a pole
at or near the imaginary axis (the cost does not see a mode the spring leaves undamped) is no
design: ConfigError.

The laws give the weights relative to the rig's own scales (:func:`scaled_weights`): with
ω_n² = k/J, the cost is ∫ q_a θ̈2² + q̂_θ ω_n⁴ θ² + q̂_v ω_n² θ̇2² + r̂ (u/J)² dt, every term an
acceleration squared and q_a, q̂_θ, q̂_v, r̂ plain numbers. In the time τ = ω_n t, with the angle as
it is, the rate θ̇2/ω_n, the acceleration θ̈2/ω_n² and the input u/k, the model and this cost depend
on the weights and the nominal damping ratio ζ_n = c_n/(2√(kJ)) alone: one set of weights gives
the same design, the same gains in units of k and √(kJ) and the same closed-loop poles over ω_n, on
any J and k. With r̂ = q̂_v = 0 the input sets θ̈2 freely and the design is the double integrator's:
the closed loop asked for is θ̈2 = −√q̂_θ·ω_n²·θ − √2·q̂_θ^¼·ω_n·θ̇2 (road at rest), the spring
softened to √q̂_θ·k and a skyhook of damping ratio q̂_θ^¼/√2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sashil.errors import ConfigError

__all__ = ["LqrDesign", "lqr_gains", "scaled_lqr_gains", "scaled_weights"]


@dataclass(frozen=True)
class LqrDesign:
    """The solved design: u* = −(k_theta·θ + k_body·θ̇2) [N m]; closed-loop poles [1/s]."""

    k_theta: float
    k_body: float
    poles: tuple[complex, complex]


def lqr_gains(
    J: float, k: float, c_n: float, q_accel: float, q_theta: float, q_body_dot: float, r_torque: float
) -> LqrDesign:
    """The LQR gains of the model in the module docstring; ConfigError naming ``controller.<key>``
    when the weights give no problem to solve or the Riccati equation has no stabilising solution."""
    from scipy.linalg import solve_continuous_are

    if q_accel == 0.0 and q_theta == 0.0 and q_body_dot == 0.0:
        raise ConfigError(
            "controller.q_accel: q_accel, q_theta and q_body_dot are all 0: the LQR has nothing to minimise"
        )
    A = np.array([[0.0, 1.0], [-k / J, -c_n / J]])
    B = np.array([[0.0], [-1.0 / J]])
    C = np.array([[-k / J, -c_n / J]])
    D = -1.0 / J
    Q = q_accel * C.T @ C + np.diag([q_theta, q_body_dot])
    N = q_accel * C.T * D
    R = np.array([[q_accel * D * D + r_torque]])
    if not R[0, 0] > 0.0:
        raise ConfigError(
            "controller.r_torque: must be > 0 when q_accel is 0 (the LQR's input weight R = q_accel·D² + r is then 0)"
        )
    try:
        P = solve_continuous_are(A, B, Q, R, s=N)
    except (np.linalg.LinAlgError, ValueError) as err:
        raise ConfigError(
            f"controller.q_theta: the LQR has no stabilising solution for these weights ({err})"
        ) from None
    K = np.linalg.solve(R, B.T @ P + N.T)
    poles = np.linalg.eigvals(A - B @ K)
    # stabilising: every closed-loop pole left of -1e-3·ω_n (a slower mode is the solver's rounding
    # of a pole on the imaginary axis, not a design)
    margin = 1e-3 * max(1.0, float(np.sqrt(abs(k) / J)))
    if not (np.all(np.isfinite(K)) and np.all(poles.real < -margin)):
        raise ConfigError(
            "controller.q_theta: the LQR has no stabilising solution for these weights "
            f"(closed-loop poles {', '.join(f'{p:.3g}' for p in poles)})"
        )
    return LqrDesign(float(K[0, 0]), float(K[0, 1]), (complex(poles[0]), complex(poles[1])))


def scaled_weights(
    J: float, k: float, q_accel: float, q_theta: float, q_body_dot: float, r_torque: float
) -> tuple[float, float, float, float]:
    """The absolute weights of :func:`lqr_gains` from the relative ones of the module docstring:
    (q_a, q̂_θ·(k/J)², q̂_v·k/J, r̂/J²). A rig without a spring (k = 0) has no ω_n: its travel and
    rate terms vanish."""
    w2 = max(k, 0.0) / J
    return q_accel, q_theta * w2 * w2, q_body_dot * w2, r_torque / (J * J)


def scaled_lqr_gains(
    J: float, k: float, c_n: float, q_accel: float, q_theta: float, q_body_dot: float, r_torque: float
) -> LqrDesign:
    """:func:`lqr_gains` with the weights relative to the rig's scales (:func:`scaled_weights`);
    the same ConfigErrors, judged on the weights as given."""
    if q_accel == 0.0 and q_theta == 0.0 and q_body_dot == 0.0:
        raise ConfigError(
            "controller.q_accel: q_accel, q_theta and q_body_dot are all 0: the LQR has nothing to minimise"
        )
    if q_accel == 0.0 and not k > 0.0:
        raise ConfigError(
            "controller.q_theta: the LQR has no stabilising solution for these weights (without a spring, "
            "k = 0, the travel and rate weights, relative to k/J, vanish, and q_accel is 0)"
        )
    return lqr_gains(J, k, c_n, *scaled_weights(J, k, q_accel, q_theta, q_body_dot, r_torque))
