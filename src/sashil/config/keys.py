"""One value of a resolved config by its dotted key: the one place a key path is followed."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["read_key"]


def read_key(config: Mapping[str, Any], path: str) -> Any:
    """The value at a dotted ``path`` of a config (``rig.coil_tau_s``; a section's name alone gives
    the whole section); KeyError naming the path when it is not there."""
    value: Any = config
    for part in path.split("."):
        if not isinstance(value, Mapping) or part not in value:
            raise KeyError(f"config key {path!r} is not in the resolved config")
        value = value[part]
    return value
