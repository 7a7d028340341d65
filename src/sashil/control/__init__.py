"""The controller side of a cycle: estimator -> Bouc-Wen observer -> semi-active law -> inverse.

The public law API is here: ``from sashil.control import Law, Param`` (:mod:`sashil.control.law_api`).
Each stage is a small object with plain-float state and no I/O; :class:`~sashil.control.controller.Controller`
composes them into a loop stage and :func:`~sashil.control.registry.make_controller` builds one from
the config's ``controller:`` section.
"""

from sashil.control.law_api import REQUIRED, CommandedRoad, Law, LawContext, LawState, Param

__all__ = ["REQUIRED", "CommandedRoad", "Law", "LawContext", "LawState", "Param"]
