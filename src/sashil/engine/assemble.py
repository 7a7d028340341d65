"""A run's config read once into its parts (:class:`~sashil.config.parts.RunSpec`).

The rig's parts are the values of the keys its backend declares (``reads``), the experiment's
options those of the keys its module declares (its ``READS``), the stage's the
``controller`` section with the model and the rig facts a law uses, the safety supervisor's its
limits, the loop's its rate and set-up. Whether the run goes on simulated time follows from the
backend (a simulated one) and ``driver.clock``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from sashil.config.frozen import freeze
from sashil.config.parts import LoopParts, RigParts, RunSpec, SafetyParts, StageParts, read_keys
from sashil.drivers import on_virtual_clock, rig_parts

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["assemble", "assembled"]


def assemble(
    config: RunConfig,
    plan: Mapping[str, Any] | None = None,
    reads: Mapping[str, str] | None = None,
    *,
    drives_rig: bool = True,
) -> RunSpec:
    """The run of a resolved ``config`` (:func:`sashil.engine.resolve.resolve`) under ``plan`` (its
    ``kind`` and values, as the plan's ``spec()`` gives them; None: none yet). ``reads``: the
    experiment's own keys (``{value name: dotted config key}``), read into ``options``.
    ``drives_rig`` False: a verb that drives no rig (``simulate``, a model on recorded inputs),
    whose model need not be one a backend can run: the rig's parts are its backend's name alone,
    and no backend is asked whether it runs on simulated time."""
    if drives_rig:
        rig = rig_parts(config)
        virtual = on_virtual_clock(rig, config["driver"]["clock"])
    else:
        rig, virtual = RigParts(RigParts.backend_of(config), freeze({}, "rig parts")), False
    return RunSpec(
        rig=rig,
        stage=StageParts.read(config),
        safety=SafetyParts.read(config),
        loop=LoopParts.read(config),
        virtual=virtual,
        plan=freeze(plan or {}, "plan"),
        options=read_keys(config, reads or {}),
    )


def assembled(config: RunConfig | RunSpec, reads: Mapping[str, str]) -> RunSpec:
    """``config`` assembled with an experiment's ``reads``, or, already assembled, the run itself: for
    the library functions a caller hands either a resolved config or the experiment's run."""
    return config if isinstance(config, RunSpec) else assemble(config, reads=reads)
