"""A run's config composed from where it comes from, all its steps in one pass, each step validated
by the schema: the file (or a mapping, or the defaults), a parameter file, the law and the ``--set``
values, each verb option, ``--driver`` and ``--port``.

:func:`compose` returns the composed config with the step that set each key last (the file,
``--params FILE``, ``--set``, the option) and the parameters a new law replaced, so that the
resolution (:func:`sashil.engine.resolve.resolve`), which knows the laws, checks the law once, on
the whole config, and names the step a failing key came from. Where a verb cannot run the config's
model, the step that chose it is named (:func:`check_model`).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sashil.config import Config, apply_params, read_config
from sashil.config.frozen import thaw
from sashil.config.overrides import parse_override, set_values
from sashil.config.schema import validate
from sashil.config.sections import SCHEMA
from sashil.errors import ConfigError
from sashil.models.registry import MODEL_PARAMS

__all__ = ["Composed", "ConfigSource", "Option", "check_model", "compose"]


@dataclass(frozen=True)
class Option:
    """A verb option that sets a config key: its name as the user gave it (``--duration``), the
    dotted key (``run.duration_s``) and the value (None: not given, the config's value stands)."""

    name: str
    key: str
    value: Any


@dataclass(frozen=True)
class ConfigSource:
    """Where a run's config comes from, in the order :func:`resolve` applies it."""

    #: a YAML file, an already-loaded mapping (checked like a file), or None for the defaults
    config: str | Path | Mapping[str, Any] | None = None
    #: a parameter file from ``sashil identify`` that replaces the model
    params: str | Path | None = None
    #: the law (``--controller``): a registered name, ``package.module:Class`` or ``file.py:Class``
    controller: str | None = None
    #: ``--set`` texts, ``section.key=value`` with a YAML value
    sets: Sequence[str] = ()
    #: the verb's own options, each a config key
    options: Sequence[Option] = ()
    driver: str | None = None
    port: str | None = None


@dataclass(frozen=True)
class Composed:
    """A config composed from all its steps: the config, the step that set each of its
    ``controller`` keys last (``controller.<key>`` -> the step's name, as a message names it; every
    key of the first step's section is the first step's), and the parameters of a law that a later
    ``controller.law`` replaced, and no later step set again."""

    config: Config
    steps: Mapping[str, str]
    replaced: frozenset[str] = frozenset()


def compose(source: ConfigSource, verb: str | None, models: Sequence[str]) -> Composed:
    """The config of ``source``, its steps applied in order: the file (or mapping, or defaults),
    ``params``, the law then each ``--set``, the verb's options, ``--driver``, ``--port``. Each step
    is validated by the schema, naming the step; after the options, a model ``verb`` cannot run
    (not in ``models``) is refused (:func:`check_model`)."""
    if isinstance(source.config, Mapping):
        config, first = validate(thaw(source.config), SCHEMA, "config"), "config"
    else:
        config, first = read_config(source.config), "defaults" if source.config is None else str(source.config)
    steps = {f"controller.{key}": first for key in config.get("controller") or {}}
    if source.params is not None:
        config = apply_params(config, source.params)
    sets = [parse_override(text) for text in source.sets]
    law = [(["controller", "law"], source.controller)] if source.controller else []
    changes = [(law + sets, "--set" if sets else "--controller")]  # the law before its --set keys
    changes += [
        ([(option.key.split("."), option.value)], option.name) for option in source.options if option.value is not None
    ]
    replaced: set[str] = set()
    for values, name in changes:
        if values:
            config, gone = set_values(config, values, name)
            own = {path[1] for path, _ in values if len(path) == 2 and path[0] == "controller"}
            replaced = (replaced - own) | gone
            steps.update({f"controller.{key}": name for key in own})
    check_model(config, source, verb, models)
    if source.params is not None and _mismatched(config.get("mismatch") or {}):
        logging.getLogger("sashil").warning(
            "--params %s: the config's mismatch: section is applied on top of these parameters "
            "(the simulated plant differs from them)",
            source.params,
        )
    for key, value, name in (("name", source.driver, "--driver"), ("port", source.port, "--port")):
        if value is not None:
            config, _ = set_values(config, [(["driver", key], value)], name)
    return Composed(config, steps, frozenset(replaced))


def check_model(config: Config, source: ConfigSource, verb: str | None, models: Sequence[str]) -> None:
    """ConfigError, one line naming where the model came from (``--set model.name``, ``--params``
    or ``--config``), when the verb cannot run the config's model."""
    name = config["model"]["name"]
    if name in models:
        return
    sets = [item for item in source.sets if item.partition("=")[0].strip() == "model.name"]
    if sets:
        where = f"--set {sets[-1]}"
    elif source.params is not None:
        where = f"--params {source.params}"
    else:
        where = f"--config {source.config if not isinstance(source.config, Mapping) else '(mapping)'}"
    who = f"sashil {verb}" if verb else "this verb"
    raise ConfigError(
        f"{where}: a {name} model; {who} runs {' or '.join(models)} models only (the rig plant and the "
        f"controller's observer are Bouc-Wen); sashil simulate runs {', '.join(MODEL_PARAMS)}"
    )


def _mismatched(section: Mapping[str, Any]) -> bool:
    """Whether a ``mismatch`` section changes the simulated plant at all."""
    return bool(
        section.get("fraction")
        or any(section.get("params", {}).values())
        or section.get("coil_tau")
        or any(section.get(key) is not None for key in ("encoder_counts_per_rev", "angle_noise_rad", "current_noise_a"))
    )
