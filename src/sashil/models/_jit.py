"""Compile the pure model kernels with numba (a dependency); ``SASHIL_NO_JIT=1`` runs them as Python.

The kernels are plain Python functions of floats (math only), so the same code is the documented
law, the real-time step of the simulated rig and the inner loop of identification. numba turns a
call of the rig's sub-step from ~3 us into ~0.5 us; ``cache=True`` keeps the compile to the first
run on a machine.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable)

#: the kernels a loop cycle can call, by qualified name: (kernel, a function returning arguments that
#: compile it, or load it from numba's cache, for the signature the cycle calls it with). Filled by
#: :func:`loop_kernel`; :mod:`sashil.runtime.warmup` calls each before the loop's first deadline.
LOOP_KERNELS: dict[str, tuple[Callable[..., Any], Callable[[], tuple[Any, ...]]]] = {}


def loop_kernel(warm_arguments: Callable[[], tuple[Any, ...]]) -> Callable[[F], F]:
    """Register a compiled kernel that a loop cycle calls (directly or from another kernel), with
    the arguments of a call of the cycle's signature (the same types: float64 scalars, C arrays)."""

    def register(kernel: F) -> F:
        LOOP_KERNELS[f"{kernel.__module__}.{kernel.__name__}"] = (kernel, warm_arguments)
        return kernel

    return register


_PACKAGE = Path(__file__).resolve().parent.parent
#: sources whose compiled kernels call each other: numba's cache checks only a function's own file,
#: so a change in one (e.g. advance_z) would leave a stale copy inlined in the others' caches
_KERNEL_SOURCES = (
    "models/*.py",
    "identify/kernels.py",
    "identify/boucwen_benchmark.py",
    "identify/friction.py",
    "drivers/encoder_edges.py",
    "drivers/sim_advance.py",
)


def refresh_stale_cache(package: Path = _PACKAGE) -> bool:
    """Drop numba's cached kernels when any kernel source changed since they were cached.

    A digest of the sources is kept beside the cache (``models/__pycache__/jit-sources.sha256``);
    when it differs, every ``*.nbi``/``*.nbc`` of the kernel folders is removed, so each kernel
    compiles once from the current sources. Best effort (a read-only install keeps its cache).
    Returns True when the cache was dropped.
    """
    files = sorted({path for pattern in _KERNEL_SOURCES for path in package.glob(pattern)})
    digest = hashlib.sha256()
    for path in files:
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    stamp = package / "models" / "__pycache__" / "jit-sources.sha256"
    try:
        if stamp.is_file() and stamp.read_text().strip() == digest.hexdigest():
            return False
        for folder in {path.parent / "__pycache__" for path in files}:
            for cached in [*folder.glob("*.nbi"), *folder.glob("*.nbc")]:
                cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest.hexdigest() + "\n")
    except OSError:
        return False
    return True


try:
    if os.environ.get("SASHIL_NO_JIT"):
        raise ImportError("SASHIL_NO_JIT is set")
    from numba import njit as _njit

    JIT = True
    refresh_stale_cache()

    def jit(function: F) -> F:
        return _njit(cache=True)(function)  # type: ignore[return-value]

except ImportError:  # pragma: no cover - numba is a dependency; this keeps the laws usable without it
    JIT = False

    def jit(function: F) -> F:
        return function
