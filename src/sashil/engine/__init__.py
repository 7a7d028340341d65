"""sashil.engine: a run's config resolved and checked, its run assembled once, and the one rule for
where its loop runs.

:func:`~sashil.engine.resolve.resolve` turns where a config comes from into the read-only config a
verb runs with, checked by the schema and by what the components declare.
:func:`assemble` is the only reader of a run's config: it hands each component its parts as plain
values (:class:`~sashil.config.parts.RunSpec`). :func:`run` runs a verb's plan, and
:func:`loop_in_process` decides, for every plan and every verb, whether its loop runs in a process
of its own or in this one. :func:`run` loads on first use, so resolving a config loads no runtime.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from sashil.engine.assemble import assemble, assembled
from sashil.engine.where import loop_in_process

if TYPE_CHECKING:
    from sashil.engine.running import run

_LAZY = {"run": "sashil.engine.running"}

__all__ = ["assemble", "assembled", "loop_in_process", "run"]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'sashil.engine' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
