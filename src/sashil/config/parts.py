"""A run's parts as plain values: what the rig, the controller stage, the safety supervisor and the
loop are each built from, read out of a resolved config once.

The components never index a config. Each takes the part made for it here: a backend its declared
keys (:class:`RigParts`, the keys named by the backend's ``reads`` table), the controller its law,
model and rig facts (:class:`StageParts`), the safety supervisor its limits (:class:`SafetyParts`),
the loop its rate and set-up (:class:`LoopParts`). :class:`RunSpec` gathers them with the plan's own
values: it is frozen, turns into JSON and back, and is all a loop process is sent.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from sashil.config.frozen import freeze, thaw
from sashil.config.keys import read_key
from sashil.config.section_parts import (
    SECTION_PARTS,
    ControllerPart,
    LoopRtPart,
    MismatchPart,
    ModelPart,
    RigPart,
    RtdacPart,
    section_of,
)
from sashil.errors import ConfigError

__all__ = ["LoopParts", "RigParts", "RunSpec", "SafetyParts", "StageParts", "read_key", "read_keys"]


def read_keys(config: Mapping[str, Any], reads: Mapping[str, str], where: str = "options") -> Mapping[str, Any]:
    """The values of the config keys a ``reads`` table declares (``{value name: dotted config key}``),
    by value name, read-only: what a module that declares its keys (an experiment, a road) is given."""
    return freeze({name: read_key(config, path) for name, path in reads.items()}, where)


@dataclass(frozen=True)
class RigParts:
    """A backend's name and the values of the config keys its class declares in ``reads``
    (``{value name: dotted config key}``): a whole ``model``, ``rig``, ``mismatch`` or ``rtdac``
    section as its typed part (:mod:`sashil.config.section_parts`), every other key's value in
    ``values`` by value name."""

    backend: str
    values: Mapping[str, Any]
    model: ModelPart | None = None
    rig: RigPart | None = None
    mismatch: MismatchPart | None = None
    rtdac: RtdacPart | None = None

    @staticmethod
    def backend_of(config: Mapping[str, Any]) -> str:
        """The backend a resolved config names (``driver.name``)."""
        return str(read_key(config, "driver.name"))

    @classmethod
    def read(cls, config: Mapping[str, Any], backend: str, reads: Mapping[str, str]) -> RigParts:
        values: dict[str, Any] = {}
        sections: dict[str, Any] = {}
        for name, path in reads.items():
            if path not in SECTION_PARTS:
                values[name] = read_key(config, path)
            elif name != path:
                raise ConfigError(
                    f"driver {backend!r}: reads the whole section {path!r} as {name!r} (name it {path!r})"
                )
            else:
                sections[path] = SECTION_PARTS[path].read(read_key(config, path), path)
        return cls(backend, freeze(values, "rig parts"), **sections)

    def to_json(self) -> dict[str, Any]:
        """Plain JSON values: each typed section as the section it was read from, or None."""
        sections = {
            name: None if getattr(self, name) is None else section_of(getattr(self, name)) for name in SECTION_PARTS
        }
        return {"backend": self.backend, "values": thaw(self.values), **sections}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RigParts:
        sections: dict[str, Any] = {
            name: part.read(data[name], name) for name, part in SECTION_PARTS.items() if data.get(name) is not None
        }
        return cls(str(data["backend"]), freeze(data["values"], "rig parts"), **sections)


@dataclass(frozen=True)
class StageParts:
    """What the controller stage is built from: the law, the ``controller`` section (the
    controller's own keys and the law's parameters), the model the controller believes, and the
    rig's facts a law and an estimator use."""

    law: str
    controller: ControllerPart
    model: ModelPart
    current_max_a: float
    #: the coil lag the controller assumes: ``controller.coil_tau_s``, else the rig's [s]
    coil_tau_s: float
    counts_per_rev: int
    angle_noise_rad: float
    rate_hz: float

    @classmethod
    def read(cls, config: Mapping[str, Any]) -> StageParts:
        """The parts of a resolved config, each key read strictly (a missing or mistyped one: an error naming it)."""
        controller = ControllerPart.read(read_key(config, "controller"))
        rig = RigPart.read(read_key(config, "rig"))
        return cls(
            law=controller.law,
            controller=controller,
            model=ModelPart.read(read_key(config, "model")),
            current_max_a=rig.current_max_a,
            coil_tau_s=rig.coil_tau_s if controller.coil_tau_s is None else controller.coil_tau_s,
            counts_per_rev=rig.encoder_counts_per_rev,
            angle_noise_rad=rig.angle_noise_rad,
            rate_hz=float(read_key(config, "loop.rate_hz")),
        )

    def to_json(self) -> dict[str, Any]:
        """Plain JSON values: the controller and the model as the sections they were read from."""
        return {**vars(self), "controller": self.controller.section(), "model": section_of(self.model)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> StageParts:
        return cls(
            **{**data, "controller": ControllerPart.read(data["controller"]), "model": ModelPart.read(data["model"])}
        )


@dataclass(frozen=True)
class SafetyParts:
    """The safety supervisor's limits: the current range, the angle interlock (None: off), the
    slew limit, the sensor timeout and whether a device fault trips."""

    current_max_a: float
    angle_limit_deg: float | None
    slew_a_per_s: float
    sensor_timeout_cycles: int
    trip_on_device_fault: bool
    max_angle_rate_rad_s: float = 60.0
    arm_travel_deg: float | None = None
    road_error_max_rad: float = 0.02
    road_error_ms: float = 5.0
    road_limit_ms: float = 50.0
    coil_authority_ms: float = 50.0
    road_grace_ms: float = 150.0

    @classmethod
    def read(cls, config: Mapping[str, Any]) -> SafetyParts:
        safety, rig = config["safety"], config["rig"]
        travel = safety["arm_travel_deg"]
        return cls(
            current_max_a=float(rig["current_max_a"]),
            angle_limit_deg=float(rig["angle_limit_deg"]) if safety["angle_interlock"] else None,
            slew_a_per_s=float(safety["slew_a_per_s"]),
            sensor_timeout_cycles=int(safety["sensor_timeout_cycles"]),
            trip_on_device_fault=bool(safety["trip_on_device_fault"]),
            max_angle_rate_rad_s=float(safety["max_angle_rate_rad_s"]),
            arm_travel_deg=None if travel is None else float(travel),
            road_error_max_rad=float(safety["road_error_max_rad"]),
            road_error_ms=float(safety["road_error_ms"]),
            road_limit_ms=float(safety["road_limit_ms"]),
            coil_authority_ms=float(safety["coil_authority_ms"]),
            road_grace_ms=float(safety["road_grace_ms"]),
        )


@dataclass(frozen=True)
class LoopParts:
    """The loop's rate and timing, its real-time set-up (``loop.rt``), what it may lose, and whether
    it runs in a process of its own on the real clock."""

    rate_hz: float
    spin_margin_us: float
    overrun_policy: str
    warn_interval_s: float
    rt: LoopRtPart
    max_missed_fraction: float
    max_lost_fraction: float
    process: bool

    @classmethod
    def read(cls, config: Mapping[str, Any]) -> LoopParts:
        loop = config["loop"]
        return cls(
            rate_hz=float(loop["rate_hz"]),
            spin_margin_us=float(loop["spin_margin_us"]),
            overrun_policy=str(loop["overrun_policy"]),
            warn_interval_s=float(loop["warn_interval_s"]),
            rt=LoopRtPart.read(loop["rt"]),
            max_missed_fraction=float(loop["max_missed_fraction"]),
            max_lost_fraction=float(config["driver"]["max_lost_fraction"]),
            process=bool(loop["process"]),
        )

    def to_json(self) -> dict[str, Any]:
        """Plain JSON values: the real-time set-up as the section it was read from."""
        return {**vars(self), "rt": section_of(self.rt)}


@dataclass(frozen=True)
class RunSpec:
    """One run, assembled: its parts, the clock it runs on unless its verb chooses the real one
    (``virtual``: simulated time), the plan's own values (``plan``: its ``kind`` and arguments) and
    the experiment's (``options``: the values of the config keys its module declares, by name, as a
    backend declares its own). :meth:`to_json` and :meth:`from_json` carry it to a loop process."""

    rig: RigParts
    stage: StageParts
    safety: SafetyParts
    loop: LoopParts
    virtual: bool
    plan: Mapping[str, Any] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)

    def with_plan(self, plan: Mapping[str, Any]) -> RunSpec:
        """This spec running another plan."""
        return replace(self, plan=freeze(plan, "plan"))

    def to_json(self) -> dict[str, Any]:
        """Plain JSON values: each part a mapping of its fields."""
        return thaw(
            {
                key: value.to_json()
                if isinstance(value, (RigParts, StageParts, LoopParts))
                else vars(value)
                if hasattr(value, "__dataclass_fields__")
                else value
                for key, value in vars(self).items()
            }
        )

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RunSpec:
        return cls(
            rig=RigParts.from_json(data["rig"]),
            stage=StageParts.from_json(data["stage"]),
            safety=SafetyParts(**data["safety"]),
            loop=LoopParts(**{**data["loop"], "rt": LoopRtPart.read(data["loop"]["rt"])}),
            virtual=bool(data["virtual"]),
            plan=freeze(data.get("plan") or {}, "plan"),
            options=freeze(data.get("options") or {}, "options"),
        )
