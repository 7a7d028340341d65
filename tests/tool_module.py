"""A script of ``tools/`` loaded as a module, so a test calls its functions as the script does."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

TOOLS = Path(__file__).resolve().parents[1] / "tools"


def load_tool(stem: str, name: str | None = None) -> ModuleType:
    """``tools/STEM.py`` as a module named ``name`` (default ``stem``), registered in ``sys.modules``
    before it runs, since a dataclass looks its module up there while the class is made."""
    spec = importlib.util.spec_from_file_location(name or stem, TOOLS / f"{stem}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module
