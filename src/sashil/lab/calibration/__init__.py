"""``sashil calibrate``: from an unknown damper to a validated model, over any link.

Modules: :mod:`.plan` (the runs to make, from the config's ``calibrate`` section), :mod:`.rig`
(running one step on the rig: the one adapter to the experiment code), :mod:`.analysis` (fit,
held-out validation, identifiability, 95 % intervals by :mod:`sashil.identify.intervals`),
:mod:`.extra` (the extra step that would most shrink the widest interval), :mod:`.report`
(params.yaml, report.md, plots),
:mod:`.session` (:func:`calibrate_rig`: all of it in order) and :mod:`.emulated`
(:func:`calibrate_emulated`: the same against an emulated damper over a pty, for benchmarks).
"""

from sashil.lab.calibration.emulated import calibrate_emulated
from sashil.lab.calibration.session import Outcome, calibrate_rig

__all__ = ["Outcome", "calibrate_emulated", "calibrate_rig"]
