"""The one resolution of a run's config: file, parameters, ``--set``, the law, the driver, the port
and the verb's own options, checked by the schema and by what the components declare (the law's
parameters, the backend's capabilities, whether a road parses), into a read-only config.

The config layer reads and validates a file against the schema (:mod:`sashil.config`); what a
component declares is checked here, above the components: :func:`load_config` and
:func:`apply_values` are the config's loaders with the law's own check after them.

Every verb and ``sashil.run(...)`` describe where their config comes from as a
:class:`ConfigSource`; :func:`resolve` applies it in a fixed order and resolves what depends on
the backend (its declared capabilities): the clock a verb runs on, the loop rate the backend can
keep, ``sashil run``'s default road. The result is frozen (:mod:`sashil.config.frozen`): nothing
downstream writes into it, and ``config.yaml`` records exactly what ran. A key a verb cannot honour
is refused in one line naming it, never silently replaced.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from sashil.config import Config, read_config
from sashil.config.compose import ConfigSource, Option, compose
from sashil.config.frozen import freeze_config
from sashil.config.overrides import parse_override, set_values
from sashil.config.parts import StageParts
from sashil.control import law_config
from sashil.drivers import declared_capabilities, rig_parts
from sashil.engine import checks as verb_checks
from sashil.errors import ConfigError
from sashil.models.registry import RIG_MODELS
from sashil.roads.syntax import DEFAULT_SIM_ROAD

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = [
    "ConfigSource",
    "Option",
    "apply_overrides",
    "apply_values",
    "check_controller",
    "default_config",
    "load_config",
    "resolve",
]

#: verbs that run on the real clock whatever the backend
REAL_CLOCK_VERBS = ("run",)
#: verbs that drive no rig (a model on recorded inputs): no key of theirs depends on a backend, and
#: their model need not be one the rig can run
RIGLESS_VERBS = ("simulate",)
#: verb -> ``function(config, named)`` that checks the verb's own keys beyond the schema
#: (``named(key)`` is the option that set a key, or the key)
VERB_CHECKS: dict[str, Callable[[RunConfig, Callable[[str], str]], None]] = {
    "drop-test": verb_checks.check_drops,
    "run": verb_checks.check_run,
    "simulate": verb_checks.check_simulate,
    "sweep": verb_checks.check_sweep,
    "compare": verb_checks.check_compare,
}


def check_controller(config: Config, source: str, replaced: Collection[str] = ()) -> None:
    """Check the config's law and its parameters (:func:`sashil.control.law_config.check_controller`;
    ``replaced``: the parameters of a law that ``controller.law`` has just replaced)."""
    section = config.get("controller")
    if not isinstance(section, dict):
        raise ConfigError(f"{source}: controller: expected a mapping, got {section!r}")
    law_config.check_controller(section, StageParts.read(config), {"controller.law": source}, replaced)


def default_config() -> Config:
    """The default config, checked: simulated rig, seed parameters, 1 kHz, the passive law at 0 A."""
    return load_config(None)


def load_config(path: str | Path | None = None) -> Config:
    """A config file read and validated (:func:`sashil.config.read_config`; None: the defaults), its
    law and parameters checked, naming the file."""
    config = read_config(path)
    check_controller(config, "defaults" if path is None else str(path))
    return config


def apply_values(config: Mapping[str, Any], values: Sequence[tuple[list[str], Any]], source: str) -> dict[str, Any]:
    """A copy of ``config`` with each ``(dotted path, value)`` set in order
    (:func:`sashil.config.overrides.set_values`), checked as a config file is: the schema, then the
    law (``source``: the option named in error messages); ``config`` itself when there is nothing to set."""
    if not values:
        return config  # type: ignore[return-value]
    out, replaced = set_values(config, values, source)
    check_controller(out, source, replaced)
    return out


def apply_overrides(config: Mapping[str, Any], overrides: Iterable[str], source: str = "--set") -> dict[str, Any]:
    """A checked copy of ``config`` with each ``section.key=value`` override applied in order
    (``source``: the option named in error messages)."""
    return apply_values(config, [parse_override(text, source) for text in overrides], source)


def resolve(source: ConfigSource, verb: str | None = None, models: Sequence[str] | None = None) -> RunConfig:
    """The read-only config ``verb`` runs with, from ``source``. Its steps are composed in one pass
    by the config layer (:func:`sashil.config.compose.compose`: the file (or defaults), ``params``,
    the law then each ``--set``, the verb's options, ``--driver``/``--port``, each validated by the
    schema), keeping the step each key came from; the law is checked once, on the whole config, an
    error naming the step that set the failing key; then the backend-dependent keys and the verb's
    own checks. Everything is checked before anything is opened or written; a model the verb cannot
    run (not in ``models``, default the rig models) is refused. The result is a
    :class:`~sashil.config.frozen.FrozenSection` typed as :class:`~sashil.config.typed.RunConfig`
    (the schema's sections, generated from it), so mypy checks every read of it."""
    composed = compose(source, verb, models if models is not None else RIG_MODELS)
    config = composed.config
    parts = StageParts.read(config)
    law = law_config.check_controller(config["controller"], parts, composed.steps, composed.replaced)
    checked = cast("RunConfig", config)  # composed and checked: what is frozen below
    if verb not in RIGLESS_VERBS:
        _resolve_backend(config, source, verb)
    check = VERB_CHECKS.get(verb or "")
    if check is not None:  # the verb's own checks of its keys, naming the option that set each
        check(checked, lambda key: _named(source, key))
    if verb not in RIGLESS_VERBS:  # a law that reads the road ahead needs a plan that commands one
        verb_checks.check_road_ahead(checked, verb, lambda key: _named(source, key), law.spec, law.cls.reads_road_ahead)
    return freeze_config(config)


def _resolve_backend(config: Config, source: ConfigSource, verb: str | None) -> None:
    """The keys that depend on the backend's declared capabilities, set in ``config`` before it is frozen."""
    caps = declared_capabilities(rig_parts(config))
    driver = config["driver"]
    if source.port is not None and not caps.link:
        raise ConfigError(
            f"--port {source.port}: the driver is {driver['name']}, which has no port; add --driver serial or --driver can"
        )
    clock = driver["clock"]
    if verb in REAL_CLOCK_VERBS:
        if clock == "virtual":
            raise ConfigError(
                f"driver.clock: virtual: sashil {verb} runs on the real clock; leave driver.clock null "
                "(or real), or run the simulated rig on virtual time with sashil drop-test, sweep or compare"
            )
        driver["clock"] = "real"
    elif clock is None:
        driver["clock"] = "virtual" if caps.simulated else "real"
    rate = float(config["loop"]["rate_hz"])
    where = _named(source, "loop.rate_hz")
    if caps.max_rate_hz is not None and rate > caps.max_rate_hz:
        raise ConfigError(
            f"{where}: {rate:g} Hz is above what the {driver['name']} backend can do ({caps.max_rate_hz:g} Hz)"
        )
    if verb == "run" and config["run"]["road"] is None:
        config["run"]["road"] = DEFAULT_SIM_ROAD if caps.simulated else "none"
    verb_checks.check_road_reverses(config, verb, caps.road_reverses, lambda key: _named(source, key))


def _named(source: ConfigSource, key: str) -> str:
    """How the user gave ``key``: the verb option that set it, else the key itself."""
    for option in source.options:
        if option.key == key and option.value is not None:
            return option.name
    return key
