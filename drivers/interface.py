"""The rig interface every backend implements (after ros2_control's hardware lifecycle).

Lifecycle: ``configure()`` opens communication, ``activate()`` lets commands energise the damper,
then cycles of ``read(t_ns, dt_ns)`` / ``write(cmd, t_ns, dt_ns)``, then ``deactivate()`` (commands
the safe current, 0 A; callable from any state, never raises for a closed link) and ``close()``
(idempotent). The object is a context manager whose exit deactivates and closes.

The simulated backend is a peer implementation of this interface, not a flag in another one.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

TWO_PI = 2.0 * math.pi

#: sample status flags (the same bits travel in the serial and CAN protocols)
FLAG_WATCHDOG = 0x01  # the device's watchdog cut the current (no valid command in time)
FLAG_HELD = 0x02  # (sim/emulator) the simulated operator holds the arm
FLAG_STUCK_SENSOR = 0x04  # (emulator fault injection) the encoder value is frozen
FLAG_OVERCURRENT = 0x08
FLAG_FAULT = 0x80

#: RigSample edge time when the sample carries no edge for that encoder
NO_EDGE = -1


@dataclass(slots=True)
class RigSample:
    """One sensor sample from the rig, in the device's own units plus the conversion to SI."""

    seq: int  # device sequence number (wraps at 2**16 on the wire)
    time_ns: int  # host time the sample belongs to
    device_time_us: int  # device clock
    arm_counts: int  # arm encoder (theta2)
    road_counts: int  # road/wheel-side encoder (theta1)
    current_a: float  # measured coil current
    flags: int
    counts_per_rev: int
    #: device time [us] of the arm encoder's last count change (NO_EDGE: none reported), and its
    #: direction (+1 the count went up, -1 down, 0 none); the count boundary it crossed is
    #: arm_counts - arm_edge_dir / 2 (protocol.md "Encoder edges")
    arm_edge_us: int = NO_EDGE
    arm_edge_dir: int = 0
    road_edge_us: int = NO_EDGE  # the same for the road encoder
    road_edge_dir: int = 0
    #: what a backend that closes the road's and the coil's loops on the host saw at its last write:
    #: the road angle's error from its reference [rad] (NaN: no host road loop, or no road commanded),
    #: the road output held at its bound, and the coil's current loop held at its authority bound
    road_error_rad: float = math.nan
    road_at_limit: bool = False
    coil_at_authority: bool = False

    @property
    def theta_rad(self) -> float:
        """Relative angle theta = theta2 - theta1 [rad]."""
        return (self.arm_counts - self.road_counts) * TWO_PI / self.counts_per_rev

    @property
    def theta_road_rad(self) -> float:
        """Road/wheel-side angle theta1 [rad]."""
        return self.road_counts * TWO_PI / self.counts_per_rev


@dataclass(slots=True)
class RigCommand:
    """What the host asks of the rig for one cycle."""

    current_a: float = 0.0  # coil current setpoint
    road_speed_rad_s: float | None = None  # road-wheel motor speed (sweeps); None: unchanged


SAFE_COMMAND = RigCommand(0.0)


def clamp_current(current_a: float, current_max_a: float) -> float:
    """The coil current a command may ask for: ``current_a`` clipped to [0, i_max], NaN -> 0 A.

    The one clamp of the command (safety supervisor, backends, emulated device; the simulated plant's
    coil driver saturates alike): MR dampers fail passive, so 0 A is both the floor and the safe
    state (docs/architecture.md).
    """
    if current_a != current_a:  # NaN
        return 0.0
    return min(max(current_a, 0.0), current_max_a)


class RigState(Enum):
    UNCONFIGURED = "unconfigured"
    CONFIGURED = "configured"
    ACTIVE = "active"
    CLOSED = "closed"


@dataclass(frozen=True)
class RigCapabilities:
    """What a backend can do, declared by it (as ros2_control's hardware description) so that the
    runner and the verbs ask instead of probing attributes."""

    #: the backend plays the drop test's operator (holds the arm, lets go): ``operator_hold`` returns True
    operator_hold: bool = False
    #: the coil can start a run already carrying a current (``set_initial_current``)
    initial_current: bool = False
    #: ``RigCommand.road_speed_rad_s`` drives the road wheel (a motor, or a simulated one)
    road_actuator: bool = False
    #: the device's sample timer paces the loop (``read`` blocks until the next sample)
    device_paced: bool = False
    #: a link with counters (``link_stats()``) and a safe state the device confirms
    link: bool = False
    #: CAN frames a trace can tap (``frame_sink``)
    can_frames: bool = False
    #: the highest loop rate the backend supports [Hz] (None: the loop's own limit)
    max_rate_hz: float | None = None
    #: a simulation, not hardware: it may run on simulated time (``driver.clock: virtual``) and a
    #: verb may pick a demonstration default (``sashil run``'s road) that would be wrong on a bench
    simulated: bool = False
    #: the backend reports the plant's true damper torque (a simulation): ``plant_truth`` returns it
    #: and the arm acceleration it causes, which no sensor of a real rig measures
    true_torque: bool = False
    #: the road motor can be driven both ways; False: one direction only (a road whose speed changes
    #: sign is refused before anything is energised)
    road_reverses: bool = True
    #: a sample's ``current_a`` is a measured coil current; False: nothing senses it (NaN), so a stop
    #: can confirm the outputs at rest but not 0 A
    current_sensed: bool = True


class PlantTruth(NamedTuple):
    """What a simulated plant knows of itself at the last sample and no sensor measures."""

    #: the damper torque T = alpha(i)*z + c(i)*theta_dot (seed 001 eq. 9)
    damper_torque_nm: float
    #: the arm's angular acceleration theta2_ddot = (-k*theta - T)/J (seed 001 eq. 13, the road side driven)
    arm_accel_rad_s2: float


def capabilities_of(rig: object) -> RigCapabilities:
    """``rig.capabilities``; a bare rig's for a duck-typed stand-in that declares none (a test double)."""
    declared = getattr(rig, "capabilities", None)
    return declared if isinstance(declared, RigCapabilities) else RigCapabilities()


class RigInterface(ABC):
    """Abstract rig: one damper coil to command, two encoders and a current sensor to read."""

    #: backend name in the registry
    name: str = "abstract"
    #: what this backend can do (backends override; the default is a bare rig)
    capabilities: RigCapabilities = RigCapabilities()

    def __init__(self) -> None:
        self.state = RigState.UNCONFIGURED

    # lifecycle -----------------------------------------------------------------------------
    @abstractmethod
    def configure(self) -> None:
        """Open communication and check the device; nothing is energised."""

    @abstractmethod
    def activate(self) -> None:
        """From now on ``write`` commands reach the damper."""

    @abstractmethod
    def read(self, t_ns: int, dt_ns: int) -> RigSample:
        """The newest sample at host time ``t_ns`` (``dt_ns``: measured period since the last read)."""

    @abstractmethod
    def write(self, cmd: RigCommand, t_ns: int, dt_ns: int) -> None:
        """Send the cycle's command."""

    @abstractmethod
    def deactivate(self) -> None:
        """Command the safe current (0 A). Callable from any state; must not raise on a dead link."""

    @abstractmethod
    def close(self) -> None:
        """Release the link. Idempotent."""

    # operator ------------------------------------------------------------------------------
    def operator_hold(self, theta_rad: float, release_after_s: float) -> bool:
        """Ask the rig's operator to hold the arm at ``theta_rad`` and let go after a while.

        Returns True when the backend plays the operator itself (simulated rig, emulator), False
        when a person has to do it (the bench): the drop test then waits for the hold.
        """
        return False

    # simulation ----------------------------------------------------------------------------
    def plant_truth(self) -> PlantTruth:
        """The plant's true damper torque and arm acceleration at the last sample; only a backend
        that declares ``capabilities.true_torque`` (a simulation) has them."""
        raise NotImplementedError(f"{self.name}: the backend does not report the plant's true torque")

    # context manager -----------------------------------------------------------------------
    def __enter__(self) -> RigInterface:
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self.deactivate()
        finally:
            self.close()
