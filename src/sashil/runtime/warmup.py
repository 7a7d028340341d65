"""Warm-up before the loop's first deadline: what a first cycle would otherwise do late.

* Every compiled kernel a cycle can call (:data:`sashil.models._jit.LOOP_KERNELS`: the Bouc-Wen
  z-update, the plant's sub-step, the simulated rig's read (sub-steps and edge search), the Kalman filter's edge
  cycle and their helpers, and the preview plan's model and its adjoint, which a law reading the road
  ahead runs before the first deadline) is called once
  with the cycle's signature, so numba compiles it, or loads it from its cache, now. A cached
  kernel still loads lazily on its first call in each process (15-23 ms), and on an empty cache
  (a fresh install) it compiles (seconds): then a progress line says so before it starts.
* The law's first call: a lab's law may import or build what it needs on its first call. It is
  called once on a representative state (an arm swinging through its rest angle, the damper in
  its feasible band) and then ``reset()``, so it starts the run from its own initial state; what it
  returns or raises there is ignored (the run's own cycles check it: a failing law ends at 0 A).
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from typing import Any

from sashil.control.law_api import LawState
from sashil.models._jit import JIT, LOOP_KERNELS

#: the modules whose kernels a cycle can call (imported here so that each registers its kernels)
KERNEL_MODULES = (
    "sashil.models.hysteresis",
    "sashil.models.plant",
    "sashil.control.edge_kalman",
    "sashil.control.preview_plan",
    "sashil.drivers.encoder_edges",
    "sashil.drivers.sim_advance",
)


def _quiet(line: str) -> None:
    return None


def _cached(kernel: Any) -> bool:
    """Whether numba's cache holds an entry for ``kernel`` (its index file exists). Best effort: a
    numba without that attribute counts as cached (no progress line)."""
    index = getattr(getattr(getattr(kernel, "_cache", None), "_cache_file", None), "_index_path", None)
    return index is None or os.path.exists(index)


def warm_kernels(say: Callable[[str], None] = _quiet) -> list[str]:
    """Compile (or load) every loop kernel for the cycle's signature; returns their names. ``say``
    gets one line first when some have to be compiled (an empty or stale cache)."""
    for module in KERNEL_MODULES:
        importlib.import_module(module)
    kernels = sorted(LOOP_KERNELS.items())
    if JIT:
        cold = [name for name, (kernel, _) in kernels if not getattr(kernel, "signatures", ()) and not _cached(kernel)]
        if cold:
            say(
                f"compiling {len(cold)} numba kernel(s) for the loop (first run on this machine or after an "
                "update; cached from then on): a few seconds ..."
            )
    for _, (kernel, arguments) in kernels:
        kernel(*arguments())
    return [name for name, _ in kernels]


#: the representative state a law is first called on: the seed rig's arm at rest angle, swinging at
#: its drop test's peak rate (the seed drop: ~5 deg at 1.66 Hz), with the observer's torque at 1 A
REPRESENTATIVE_STATE = {
    "time_s": 0.5,
    "theta_rad": 0.0,
    "theta_dot_rad_s": 0.5,
    "body_dot_rad_s": 0.5,
    "body_ddot_rad_s2": 0.0,
    "road_dot_rad_s": 0.0,
    "torque_hat_nm": 3.0,
    "z_hat": 1.0,
    "band_lo_nm": 1.35,
    "band_hi_nm": 3.0,
    "current_a": 1.0,
}


def warm_law(controller: Any) -> bool:
    """Call ``controller``'s law once on :data:`REPRESENTATIVE_STATE`, then ``reset()`` it. Returns
    whether there was a law to warm (a controller with ``law`` and its ``state``)."""
    law = getattr(controller, "law", None)
    state = getattr(controller, "state", None)
    if law is None or state is None:
        return False

    probe = LawState()
    for name, value in REPRESENTATIVE_STATE.items():
        setattr(probe, name, value)
    output = law.current if getattr(controller, "direct", False) else law.torque
    try:
        output(probe)
    except Exception:  # the run's first cycle meets it again, and ends at 0 A with its message
        pass
    try:
        law.reset()
    except Exception:  # likewise: the first cycle resets the law again
        pass
    return True


def controller_of(plan: Any) -> Any:
    """The controller a plan runs (the plan itself, or its ``controller``), or None."""
    if hasattr(plan, "law") and hasattr(plan, "state"):
        return plan
    return getattr(plan, "controller", None)


def warm_up(plan: Any, say: Callable[[str], None] = _quiet) -> None:
    """Everything the first cycle of ``plan`` would do late: the loop kernels, the law's first call."""
    warm_kernels(say)
    warm_law(controller_of(plan))
