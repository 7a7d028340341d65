"""sashil's experiments as library functions: each takes a resolved config and its options and
returns the :class:`~sashil.api.Run` of the folder it wrote.

* :func:`drop_test` (``sashil drop-test``), :func:`closed_loop` (``sashil run``),
  :func:`calibrate` (``sashil calibrate``), :func:`replay` (``sashil replay``),
  :func:`simulate` (``sashil simulate``), :func:`sweep` (``sashil sweep``), :func:`compare`
  (``sashil compare``);
* :func:`resolve` turns a :class:`ConfigSource` (file, parameters, ``--set``, law, driver, port,
  the verb's options) into the read-only config they take, typed as :class:`RunConfig` (a
  ``TypedDict`` per schema section, generated from the schema: mypy checks each key a script reads);
* progress, operator prompts, results and warnings reach the caller as :class:`Event` objects
  (``on_event``); the command line prints them, a script or a page receives them.

The command line (:mod:`sashil.cli`) and ``sashil.run``/``sashil.drop_test`` are thin callers of
these functions. Names load on first use, so importing this package costs nothing. Each function
lives in a private module of its own (``_drop_test.py``, ...), so a function and its module never
share a name: ``sashil.lab.drop_test`` is always the function.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig
    from sashil.engine.events import Event
    from sashil.engine.resolve import ConfigSource, Option, resolve
    from sashil.engine.sashil_run import closed_loop
    from sashil.lab._calibrate import calibrate
    from sashil.lab._compare import CompareLaw, compare
    from sashil.lab._drop_test import drop_test
    from sashil.lab._replay import replay
    from sashil.lab._simulate import simulate
    from sashil.lab._sweep import sweep
    from sashil.recording.outputs import Outputs

_LAZY = {
    "ConfigSource": "sashil.engine.resolve",
    "Option": "sashil.engine.resolve",
    "resolve": "sashil.engine.resolve",
    "RunConfig": "sashil.config.typed",
    "calibrate": "sashil.lab._calibrate",
    "closed_loop": "sashil.engine.sashil_run",
    "drop_test": "sashil.lab._drop_test",
    "Event": "sashil.engine.events",
    "Outputs": "sashil.recording.outputs",
    "replay": "sashil.lab._replay",
    "simulate": "sashil.lab._simulate",
    "sweep": "sashil.lab._sweep",
    "compare": "sashil.lab._compare",
    "CompareLaw": "sashil.lab._compare",
}

__all__ = [
    "CompareLaw",
    "ConfigSource",
    "Event",
    "Option",
    "Outputs",
    "RunConfig",
    "calibrate",
    "closed_loop",
    "compare",
    "drop_test",
    "replay",
    "resolve",
    "simulate",
    "sweep",
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'sashil.lab' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
