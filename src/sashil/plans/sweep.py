"""A sweep's plan, built where its loop runs: the run's law on the road of its plan (a chirp, or one
frequency of a stepped sine), the road motor commanded each cycle and the true damper torque recorded
where the rig reports it."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from sashil.control.controller import SIGNALS
from sashil.control.registry import make_controller
from sashil.drivers.interface import RigCommand, RigInterface, RigSample, capabilities_of
from sashil.roads.profiles import SweepRoad, road_of

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec
    from sashil.models.plant import RoadProfile

__all__ = ["CONTROLLER_SIGNALS", "KIND", "SweepStage", "build", "stage"]

#: the plan's kind (``RunSpec.plan["kind"]``; its values: ``road``, the road's spec, and ``duration_s``)
KIND = "sweep"

#: the controller's signals a sweep records
CONTROLLER_SIGNALS = SIGNALS


class SweepStage:
    """Loop stage: run ``controller`` (any stage with the controller's attributes) and command the
    road speed. It keeps no data: the runner's stream records every cycle, with the controller's
    signals and the true damper torque of a rig that reports it (``torque_true_nm``: a simulated
    plant's, its capability ``true_torque``; NaN elsewhere). The stage that runs, given its rig
    (:meth:`attach_rig`), hands the road to come to the controller, for a law that reads the road ahead
    (``duration_s``: how long it will be commanded, None: until stopped)."""

    def __init__(self, controller: Any, road: RoadProfile, duration_s: float | None = None):
        self.controller = controller
        self.duration_s = duration_s
        #: the controller is the config's law: a loop process can make its own (:meth:`spec`)
        self.from_config = False
        #: the controller's signals (a current law's own output, current_law_a, too) and the true torque
        self.signal_names = (*getattr(controller, "signal_names", CONTROLLER_SIGNALS), "torque_true_nm")
        self.road = road
        self._truth: RigInterface | None = None
        self.torque_true_nm = math.nan
        self._t0: int | None = None
        #: what the loop process's twin of this stage counted (:meth:`absorb`), None: it ran here
        self.seen: dict[str, Any] | None = None

    def __getattr__(self, name: str) -> Any:  # the controller's signals (NaN for a stage without them)
        if name in CONTROLLER_SIGNALS or name == "current_law_a":
            return getattr(self.__dict__["controller"], name, math.nan)
        raise AttributeError(name)

    def attach_rig(self, rig: RigInterface) -> None:
        """Meet the rig this stage runs on, before its loop starts: its true damper torque recorded
        when it reports one, and the road to come handed to the controller."""
        self._truth = rig if capabilities_of(rig).true_torque else None
        attach = getattr(self.controller, "attach_road", None)
        if attach is not None:
            road = self.road
            attach(lambda t: road(t)[1], self.duration_s)

    def spec(self) -> dict[str, Any] | None:
        """What a loop process builds this run from (the config's law on the same road:
        :func:`stage`), or None when it cannot (a controller not the config's law, a road
        without a spec)."""
        if not self.from_config or not isinstance(self.road, SweepRoad):
            return None
        return {"kind": KIND, "road": self.road.spec, "duration_s": self.duration_s}

    def facts(self) -> dict[str, Any]:
        """The controller's counts after the run (its clipped cycles, its summary statistics)."""
        stats = getattr(self.controller, "stats", None)
        return {"clip_count": int(getattr(self.controller, "clip_count", 0)), "stats": stats() if stats else None}

    def absorb(self, facts: dict[str, Any]) -> None:
        """Take the :meth:`facts` of the same run in the loop process (:attr:`clip_count`, :meth:`stats`)."""
        self.seen = facts

    @property
    def clip_count(self) -> int:
        """The controller's clipped cycles (as the loop process's controller counted them, when it ran there)."""
        seen = self.__dict__.get("seen")
        return int(seen["clip_count"]) if seen is not None else int(getattr(self.controller, "clip_count", 0))

    def stats(self) -> dict[str, Any] | None:
        """The controller's summary statistics (the loop process's controller's, when it ran there)."""
        seen = self.__dict__.get("seen")
        if seen is not None:
            return seen["stats"]
        stats = getattr(self.controller, "stats", None)
        return stats() if stats is not None else None

    def step(self, sample: RigSample, t_ns: int, dt_ns: int) -> RigCommand | None:
        if self._t0 is None:
            self._t0 = t_ns
        t = (t_ns - self._t0) * 1e-9
        if self._truth is not None:
            self.torque_true_nm = self._truth.plant_truth().damper_torque_nm
        cmd = self.controller.step(sample, t_ns, dt_ns)
        cmd.road_speed_rad_s = self.road(t)[1]
        return cmd


def stage(run: RunSpec, rig: RigInterface) -> SweepStage:
    """A sweep run's stage built in a loop process: the run's law on the road of its plan, for
    ``duration_s`` of it."""
    stage = SweepStage(make_controller(None, run.stage), road_of(run.plan["road"]), run.plan.get("duration_s"))
    stage.attach_rig(rig)
    return stage


def build(run: RunSpec, rig: RigInterface, prompt: Callable[[str], None]) -> tuple[SweepStage, str, str]:
    """One run of a sweep built in a loop process (a chirp, or one frequency of a stepped sine): the
    run's law on the road of its plan (``run.plan``), its label and the road's shape."""
    return stage(run, rig), run.stage.law, str(run.plan["road"].get("shape"))
