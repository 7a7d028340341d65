"""sashil.drivers: the rig interface, its backends, their protocol codecs and the rig emulator.

Backends are found by name through the ``sashil.backends`` entry points (after python-can's
interface table), where the built-in ``sim``, ``serial`` and ``can`` are registered exactly as a
lab's own driver package would register its board: the module is imported only when that backend
is asked for.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sashil.config.parts import RigParts
from sashil.drivers.interface import SAFE_COMMAND, RigCapabilities, RigCommand, RigInterface, RigSample, capabilities_of
from sashil.errors import ConfigError, DriverError
from sashil.plugins import BACKENDS_GROUP, entry_point_table, load_class

#: backend name -> "module:Class" (the installed ``sashil.backends`` entry points)
BACKENDS: dict[str, str] = {name: plugin.target for name, plugin in entry_point_table(BACKENDS_GROUP).items()}

__all__ = [
    "BACKENDS",
    "SAFE_COMMAND",
    "RigCommand",
    "RigInterface",
    "RigSample",
    "backend_class",
    "backend_reads",
    "declared_capabilities",
    "on_virtual_clock",
    "open_rig",
    "rig_parts",
]


def backend_class(name: str) -> type[RigInterface]:
    """The class registered for backend ``name`` (imported on first use)."""
    try:
        target = BACKENDS[name]
    except KeyError:
        raise DriverError(f"driver.name: unknown backend {name!r} (known: {', '.join(BACKENDS)})") from None
    try:
        return load_class(target, f"driver {name!r}")
    except ConfigError as err:
        raise DriverError(f"{err} (the backend is not available)") from None


def backend_reads(name: str) -> Mapping[str, str]:
    """The config keys backend ``name`` is built from: its class's ``reads`` table, ``{value name:
    dotted config key}`` (a section's name alone hands it the whole section)."""
    return dict(getattr(backend_class(name), "reads", {}))


def rig_parts(config: Mapping[str, Any], backend: str | None = None) -> RigParts:
    """The parts of a resolved config's backend (``driver.name``, or ``backend``): the values of
    the config keys the backend declares (:func:`backend_reads`)."""
    name = backend if backend is not None else RigParts.backend_of(config)
    return RigParts.read(config, name, backend_reads(name))


def open_rig(parts: RigParts) -> RigInterface:
    """Build (not yet configure) the rig backend ``parts`` names from the values it declared."""
    return backend_class(parts.backend).from_parts(parts)  # type: ignore[attr-defined]


def declared_capabilities(parts: RigParts) -> RigCapabilities:
    """What the backend of ``parts`` declares (the rig object is built; nothing is opened or sent)."""
    rig = open_rig(parts)
    try:
        return capabilities_of(rig)
    finally:
        rig.close()


def on_virtual_clock(parts: RigParts, clock: str | None) -> bool:
    """Whether runs go on simulated time: a simulated backend whose ``driver.clock`` (``clock``) is not ``real``."""
    return clock != "real" and declared_capabilities(parts).simulated
