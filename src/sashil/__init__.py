"""sashil: hardware-in-the-loop control of the SAS rig with a rotary MR damper.

The package's attributes load on first use (PEP 562), so ``import sashil`` and ``sashil --version``
import no numerics: ``sashil.run``, ``sashil.drop_test``, ``sashil.load_run`` and ``sashil.Run``
bring in what they need when they are first touched.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from sashil._version import __version__

if TYPE_CHECKING:
    from sashil.api import Run, load_run
    from sashil.scripting import drop_test, run

#: public name -> the module that defines it
_LAZY = {
    "Run": "sashil.api",
    "load_run": "sashil.api",
    "drop_test": "sashil.scripting",
    "run": "sashil.scripting",
}

__all__ = ["Run", "__version__", "drop_test", "load_run", "run"]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'sashil' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
