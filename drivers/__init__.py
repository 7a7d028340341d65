"""sashil.drivers: the rig interface, its backends, their protocol codecs and the rig emulator.

Backends are found by name through the ``sashil.backends`` entry points (after python-can's
interface table), where the built-in ``sim``, ``serial`` and ``can`` are registered exactly as a
lab's own driver package would register its board: the module is imported only when that backend
is asked for.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sashil.drivers.interface import SAFE_COMMAND, RigCapabilities, RigCommand, RigInterface, RigSample, capabilities_of
from sashil.errors import ConfigError, DriverError
from sashil.plugins import BACKENDS_GROUP, entry_point_table, load_class

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

#: backend name -> "module:Class" (the installed ``sashil.backends`` entry points)
BACKENDS: dict[str, str] = {name: plugin.target for name, plugin in entry_point_table(BACKENDS_GROUP).items()}

__all__ = [
    "BACKENDS",
    "SAFE_COMMAND",
    "RigCommand",
    "RigInterface",
    "RigSample",
    "backend_class",
    "declared_capabilities",
    "on_virtual_clock",
    "open_rig",
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


def open_rig(config: RunConfig) -> RigInterface:
    """Build (not yet configure) the rig backend the config's ``driver`` section names."""
    return backend_class(config["driver"]["name"]).from_config(config)  # type: ignore[attr-defined]


def declared_capabilities(config: RunConfig) -> RigCapabilities:
    """What the config's backend declares (the rig object is built; nothing is opened or sent)."""
    rig = open_rig(config)
    try:
        return capabilities_of(rig)
    finally:
        rig.close()


def on_virtual_clock(config: RunConfig) -> bool:
    """Whether runs of this config go on simulated time: a simulated backend whose ``driver.clock`` is not ``real``."""
    return config["driver"]["clock"] != "real" and declared_capabilities(config).simulated
