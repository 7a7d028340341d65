"""The rig's wiring to an RT-DAC/USB2, as plain values: the ``rtdac`` section's wiring keys.

The host's backend reads its channels from it, and the emulated bench is wired by it (so an
emulator and a host on one config fit). Nothing here is INTECO's: the public source says nothing of
what the SAS rig wires where (the section's docs say which defaults guess).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

from sashil.config.section_parts import RtdacPart


@dataclass(frozen=True)
class Wiring:
    """The rig's wiring to the board (the ``rtdac`` section's wiring keys), as plain values."""

    arm_encoder: int = 0
    arm_counts_per_rev: int = 4096
    arm_reversed: bool = False
    road_encoder: int | None = 1
    road_counts_per_rev: int = 4096
    road_reversed: bool = False
    coil_output: str = "pwm"
    coil_channel: int = 0
    coil_map_current_a: tuple[float, ...] = (0.0, 1.0)
    coil_map_output: tuple[float, ...] = (0.0, 1.0)
    coil_sense_ad: int | None = None
    coil_sense_a_per_v: float = 0.2
    coil_sense_offset_v: float = 0.0
    coil_loop_ki_per_s: float = 20.0
    road_output: str = "da"
    road_channel: int = 0
    road_direction_bit: int | None = None
    road_output_per_rad_s: float = 0.5
    road_kp_per_rad: float = 20.0
    road_lag_s: float = 0.02
    road_output_limit: float = 10.0
    pwm_prescaler: int | None = None
    pwm_mode: str = "12-bit"
    coil_loop_authority: float = 0.25
    heartbeat_bit: int | None = None
    confirmed: tuple[str, ...] = ()
    bringup_current_max_a: float = 0.3
    bringup_road_output: float = 0.25

    @classmethod
    def from_part(cls, part: RtdacPart, **changes: Any) -> Wiring:
        """The ``rtdac`` section's wiring, with ``changes`` over it."""
        return replace(cls(**{f.name: getattr(part, f.name) for f in fields(cls)}), **changes)
