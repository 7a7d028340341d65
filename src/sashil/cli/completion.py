"""Shell completion of the ``sashil`` command line (optional: ``pip install 'sashil[completion]'``).

With argcomplete installed, ``eval "$(register-python-argcomplete sashil)"`` in the shell's start-up
file completes verbs, options, choices and ``--set`` keys (``--set loop.<TAB>`` lists
``loop.rate_hz=``, ``loop.rt.priority=``, ... from the config schema). Without it, nothing changes.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator, Mapping
from typing import Any

from sashil.config.schema import Section
from sashil.config.sections import SCHEMA
from sashil.errors import ConfigError


def config_keys(schema: Mapping[str, Any], prefix: str = "") -> Iterator[str]:
    """Every settable dotted key of a config schema (``loop.rate_hz``, ``loop.rt.priority``, ...)."""
    for key, spec in schema.items():
        if isinstance(spec, Section):
            yield from config_keys(spec.fields, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}"


def law_keys() -> Iterator[str]:
    """``controller.<param>`` of every registered law's parameters (each once)."""
    from sashil.control.law_registry import known_laws

    try:
        laws = known_laws()
    except ConfigError:  # a broken plug-in: complete the rest
        return
    yield from dict.fromkeys(f"controller.{key}" for entry in laws for key in entry.cls.params())


def set_completer(prefix: str, **_: Any) -> list[str]:
    """argcomplete completer of ``--set``: the dotted keys that start with ``prefix``, each with ``=``
    (the schema's keys and the registered laws' parameters)."""
    keys = [*config_keys(SCHEMA), *law_keys()]
    return [f"{key}=" for key in dict.fromkeys(keys) if key.startswith(prefix)]


def enable(parser: argparse.ArgumentParser) -> None:
    """Attach the ``--set`` completer and hand the parser to argcomplete, when it is installed (it
    answers the shell and exits when the shell asks for completions, and does nothing otherwise)."""
    try:
        import argcomplete
    except ImportError:
        return
    subparsers = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    for sub in subparsers:
        for verb_parser in sub.choices.values():
            for action in verb_parser._actions:
                if "--set" in action.option_strings:
                    action.completer = set_completer
    argcomplete.autocomplete(parser)
