"""sashil.testing: test a control law in a lab's own CI, on the simulated rig on the virtual clock.

* :class:`SimRig`: the simulated rig with a damper of the lab's choice and seeded noise;
  :func:`run_law` runs a law on a road for a duration and returns the
  :class:`~sashil.api.Run` that :func:`sashil.load_run` gives;
* :func:`check_law` / :func:`assert_law_contract`: the contract check of a law class, one line per
  fault naming the law and the fault;
* :func:`compare_with_passive`: comfort and travel against the best constant current, and the share
  of the optimal bound.

It is also a pytest plugin, registered by sashil's entry point in the group ``pytest11``: installing
sashil gives a lab's tests the fixture ``sashil_rig`` (:mod:`sashil.testing.plugin`). Names load on
first use, so the plugin costs pytest's start-up nothing.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sashil.testing.comparison import Comparison, compare_with_passive
    from sashil.testing.contract import ContractReport, assert_law_contract, check_law
    from sashil.testing.rig import DEFAULT_ROAD, SimRig, run_law

_LAZY = {
    "Comparison": "sashil.testing.comparison",
    "compare_with_passive": "sashil.testing.comparison",
    "ContractReport": "sashil.testing.contract",
    "assert_law_contract": "sashil.testing.contract",
    "check_law": "sashil.testing.contract",
    "DEFAULT_ROAD": "sashil.testing.rig",
    "SimRig": "sashil.testing.rig",
    "run_law": "sashil.testing.rig",
}

__all__ = [
    "DEFAULT_ROAD",
    "Comparison",
    "ContractReport",
    "SimRig",
    "assert_law_contract",
    "check_law",
    "compare_with_passive",
    "run_law",
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'sashil.testing' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
