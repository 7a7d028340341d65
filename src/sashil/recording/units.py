"""The unit of a data column, read from its name (docs/architecture.md: every column that carries a unit names it)."""

from __future__ import annotations

#: name suffix -> unit, longest suffixes first (``_rad_s`` before ``_s``)
SUFFIX_UNITS = (
    ("_rad_s2", "rad/s^2"),
    ("_rad_s", "rad/s"),
    ("_deg_s", "deg/s"),
    ("_rad", "rad"),
    ("_deg", "deg"),
    ("_nm", "N m"),
    ("_a", "A"),
    ("_us", "us"),
    ("_ns", "ns"),
    ("_ms", "ms"),
    ("_hz", "Hz"),
    ("_s", "s"),
)

#: columns without a unit suffix and what they hold
DIMENSIONLESS = {
    "z_hat": "1 (Bouc-Wen state, scaled like z)",
    "z_true": "1 (Bouc-Wen state, scaled like z)",
    "seq": "1 (sequence number on the wire)",
    "trip_code": "1 (0: none; see summary.json trips)",
    "transmissibility": "1",
}


def column_unit(name: str) -> str:
    """The unit of column ``name`` (``"1"`` for a plain number)."""
    if name in DIMENSIONLESS:
        return DIMENSIONLESS[name]
    for suffix, unit in SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return "1"
