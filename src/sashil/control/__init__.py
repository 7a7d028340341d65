"""The controller side of a cycle: estimator -> Bouc-Wen observer -> semi-active law -> inverse.

Each stage is a small object with plain-float state and no I/O (DESIGN.md, data flow of one
control cycle); :class:`~sashil.control.controller.Controller` composes them into a loop stage and
:func:`~sashil.control.registry.make_controller` builds one from the config's ``controller:`` section.
"""
