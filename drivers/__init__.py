"""sashil.drivers: the rig interface, its backends, their protocol codecs and the rig emulator.

Backends are found by name through a small lazy registry (after python-can's interface table):
the module is imported only when that backend is asked for.
"""

from __future__ import annotations

import importlib
from typing import Any

from sashil.drivers.interface import SAFE_COMMAND, RigCommand, RigInterface, RigSample
from sashil.errors import DriverError

#: backend name -> (module, class)
BACKENDS: dict[str, tuple[str, str]] = {
    "sim": ("sashil.drivers.sim", "SimulatedRig"),
    "serial": ("sashil.drivers.serial_rig", "SerialRig"),
    "can": ("sashil.drivers.can_rig", "CanRig"),
}

__all__ = ["BACKENDS", "SAFE_COMMAND", "RigCommand", "RigInterface", "RigSample", "backend_class", "open_rig"]


def backend_class(name: str) -> type[RigInterface]:
    """The class registered for backend ``name`` (imported on first use)."""
    try:
        module_name, class_name = BACKENDS[name]
    except KeyError:
        raise DriverError(f"driver.name: unknown backend {name!r} (known: {', '.join(BACKENDS)})") from None
    try:
        module = importlib.import_module(module_name)
    except ImportError as err:
        raise DriverError(f"driver {name!r} is not available: {err}") from None
    return getattr(module, class_name)


def open_rig(config: dict[str, Any]) -> RigInterface:
    """Build (not yet configure) the rig backend the config's ``driver`` section names."""
    return backend_class(config["driver"]["name"]).from_config(config)  # type: ignore[attr-defined]
