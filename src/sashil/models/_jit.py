"""Compile the pure model kernels with numba (a dependency); ``SASHIL_NO_JIT=1`` runs them as Python.

The kernels are plain Python functions of floats (math only), so the same code is the documented
law, the real-time step of the simulated rig and the inner loop of identification. numba turns a
call of the rig's sub-step from ~3 us into ~0.5 us; ``cache=True`` keeps the compile to the first
run on a machine.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TypeVar

F = TypeVar("F", bound=Callable)

try:
    if os.environ.get("SASHIL_NO_JIT"):
        raise ImportError("SASHIL_NO_JIT is set")
    from numba import njit as _njit

    JIT = True

    def jit(function: F) -> F:
        return _njit(cache=True)(function)  # type: ignore[return-value]

except ImportError:  # pragma: no cover - numba is a dependency; this keeps the laws usable without it
    JIT = False

    def jit(function: F) -> F:
        return function
