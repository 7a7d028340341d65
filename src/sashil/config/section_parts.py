"""Whole config sections a backend is built from, as frozen typed values: the damper ``model``,
the ``rig``, the simulated plant's ``mismatch`` and the RT-DAC's ``rtdac`` section.

Each is read strictly from a resolved config (the schema, :mod:`sashil.config.sections`, has already
checked it): every field's key must be there with a value of the field's type, else one
:class:`~sashil.errors.ConfigError` names the key. A backend then reads fields, never keys.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from types import UnionType
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from sashil.config.frozen import freeze, thaw
from sashil.config.keys import read_key
from sashil.errors import ConfigError

__all__ = [
    "SECTION_PARTS",
    "CalibratePart",
    "ControllerPart",
    "LoopRtPart",
    "MismatchPart",
    "ModelPart",
    "RigPart",
    "RtdacPart",
    "read_fields",
    "section_of",
]

Part = TypeVar("Part")


def _fits(value: Any, hint: Any) -> bool:
    """Whether ``value`` is of the type ``hint`` names (the kinds a config holds)."""
    origin = get_origin(hint)
    if origin in (Union, UnionType):
        return any(_fits(value, arm) for arm in get_args(hint))
    if origin is Literal:
        return value in get_args(hint)
    if origin is tuple:
        item = get_args(hint)[0]
        return isinstance(value, (list, tuple)) and all(_fits(one, item) for one in value)
    if hint is type(None):
        return value is None
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if origin is Mapping or hint is Mapping:
        return isinstance(value, Mapping)
    return isinstance(value, hint)


def _plain(value: Any, hint: Any, where: str) -> Any:
    """``value`` as its field holds it: a float as ``float``, a list as a tuple, a mapping frozen."""
    if isinstance(value, Mapping):
        return freeze(value, where)
    if isinstance(value, list):
        return tuple(value)
    if hint is float or (get_origin(hint) in (Union, UnionType) and float in get_args(hint) and value is not None):
        return float(value)
    return value


def read_fields(cls: type[Part], section: Mapping[str, Any], where: str) -> Part:
    """A ``cls`` (a frozen dataclass) of ``section``'s keys named as its fields: ConfigError naming
    ``where.key`` when one is missing or of another type."""
    hints = get_type_hints(cls)
    values: dict[str, Any] = {}
    for field in fields(cls):  # type: ignore[arg-type]
        key = f"{where}.{field.name}"
        if field.name not in section:
            raise ConfigError(f"{key}: missing from the resolved config")
        value = section[field.name]
        if not _fits(value, hints[field.name]):
            raise ConfigError(f"{key}: expected {hints[field.name]}, got {value!r}")
        values[field.name] = _plain(value, hints[field.name], key)
    return cls(**values)


def section_of(part: Any) -> dict[str, Any]:
    """A part as the plain section it was read from (JSON values, mappings and lists writable)."""
    return thaw(asdict(part))


@dataclass(frozen=True)
class ModelPart:
    """The ``model`` section: the damper model's name and its parameters by symbol (the model checks its own)."""

    name: Literal["bouc-wen", "dahl", "lugre", "bingham"]
    params: Mapping[str, Any]

    @classmethod
    def read(cls, section: Mapping[str, Any], where: str = "model") -> ModelPart:
        return read_fields(cls, section, where)


@dataclass(frozen=True)
class RigPart:
    """The ``rig`` section: the physical rig around the damper."""

    coil_tau_s: float
    current_max_a: float
    encoder_counts_per_rev: int
    angle_noise_rad: float
    current_noise_a: float
    noise_seed: int
    plant_max_step_s: float
    angle_limit_deg: float

    @classmethod
    def read(cls, section: Mapping[str, Any], where: str = "rig") -> RigPart:
        return read_fields(cls, section, where)


@dataclass(frozen=True)
class MismatchPart:
    """The ``mismatch`` section: how the simulated plant differs from the model the controller uses."""

    fraction: float
    pattern: Literal["alternate", "plus", "minus", "random"]
    seed: int
    params: Mapping[str, Any]
    coil_tau: float
    encoder_counts_per_rev: int | None
    angle_noise_rad: float | None
    current_noise_a: float | None

    @classmethod
    def read(cls, section: Mapping[str, Any], where: str = "mismatch") -> MismatchPart:
        return read_fields(cls, section, where)


@dataclass(frozen=True)
class RtdacPart:
    """The ``rtdac`` section: how the RT-DAC/USB2 is found and how the rig is wired to it
    (:mod:`sashil.config.rtdac_section` says what each key means)."""

    manufacturer: str
    serial: str | None
    vendor_id: int | None
    product_id: int | None
    usb_backend: str | None
    transfer_timeout_ms: float
    application: str | None
    map_dir: str | None
    arm_encoder: int
    arm_counts_per_rev: int
    arm_reversed: bool
    road_encoder: int | None
    road_counts_per_rev: int
    road_reversed: bool
    coil_output: Literal["pwm", "da"]
    coil_channel: int
    coil_map_current_a: tuple[float, ...]
    coil_map_output: tuple[float, ...]
    coil_sense_ad: int | None
    coil_sense_a_per_v: float
    coil_sense_offset_v: float
    coil_loop_ki_per_s: float
    road_output: Literal["none", "pwm", "da"]
    road_channel: int
    road_direction_bit: int | None
    road_output_per_rad_s: float
    road_kp_per_rad: float
    road_lag_s: float
    road_output_limit: float
    pwm_prescaler: int | None
    pwm_mode: Literal["12-bit", "8-bit"]
    confirmed: tuple[str, ...]
    bringup_current_max_a: float
    bringup_road_output: float
    coil_loop_authority: float
    heartbeat_bit: int | None

    @classmethod
    def read(cls, section: Mapping[str, Any], where: str = "rtdac") -> RtdacPart:
        return read_fields(cls, section, where)


@dataclass(frozen=True)
class ControllerPart:
    """The ``controller`` section: the law, the controller's own keys (the estimator, the observer's
    inverse and the coil-lag lead; :data:`sashil.config.sections.CONTROLLER` says what each means)
    and, in ``params``, the section's other keys: the law's parameters, which the law checks."""

    law: str
    estimator: str
    kalman_accel_psd: float
    kalman_road_jerk_psd: float
    kalman_road_jerk_psd_commanded: float
    kalman_quantisation: str
    edge_timing: bool
    kalman_bias_psd: float
    innovation_limit_counts: float
    estimator_bandwidth_hz: float
    estimator_order: int
    road_bandwidth_hz: float
    model_aided: bool
    inverse: str
    min_authority_nm_per_a: float
    lead_horizon_s: float
    lead_current_laws: bool
    #: the coil lag the controller assumes [s] (None: the rig's)
    coil_tau_s: float | None
    tune_ramp_s: float
    params: Mapping[str, Any]

    @classmethod
    def read(cls, section: Mapping[str, Any], where: str = "controller") -> ControllerPart:
        own = {field.name for field in fields(cls)} - {"params"}
        params = {key: value for key, value in section.items() if key not in own}
        return read_fields(cls, {**section, "params": params}, where)

    def section(self) -> dict[str, Any]:
        """The section as the config holds it: the controller's keys and the law's parameters side by side."""
        plain = section_of(self)
        return {**{key: value for key, value in plain.items() if key != "params"}, **plain["params"]}


@dataclass(frozen=True)
class LoopRtPart:
    """The ``loop.rt`` section: the loop's best-effort real-time set-up (priority, CPU, memory lock,
    the garbage collector, timer slack and the interpreter's switch interval)."""

    priority: int
    cpu: int | None
    mlockall: bool
    gc: Literal["disable", "freeze", "none"]
    timer_slack_ns: int
    gil_switch_us: int

    @classmethod
    def read(cls, section: Mapping[str, Any], where: str = "loop.rt") -> LoopRtPart:
        return read_fields(cls, section, where)


@dataclass(frozen=True)
class CalibratePart:
    """The ``calibrate`` section: the plan of ``sashil calibrate`` (the drops and road chirps to fit,
    the held-out runs, the fit's model and its intervals' blocks)."""

    theta0_deg: float
    currents_a: tuple[float, ...]
    small_theta0_deg: float
    small_currents_a: tuple[float, ...]
    drop_duration_s: float
    road_currents_a: tuple[float, ...]
    road_amplitude_deg: float
    road_f_start_hz: float
    road_f_stop_hz: float
    road_duration_s: float
    road_ramp_s: float
    validate_theta0_deg: float
    validate_currents_a: tuple[float, ...]
    validate_road_currents_a: tuple[float, ...]
    max_rig_time_s: float
    model: Literal["bouc-wen", "dahl", "lugre", "bingham", "all"]
    inertia_kg_m2: float | None
    profile_n: bool
    interval_block_s: float
    extra_steps: int

    @classmethod
    def read(cls, config: Mapping[str, Any]) -> CalibratePart:
        """The ``calibrate`` section of a resolved config."""
        return read_fields(cls, read_key(config, "calibrate"), "calibrate")


#: the sections a backend receives typed when its ``reads`` names the whole section, by section name
SECTION_PARTS: dict[str, type[ModelPart] | type[RigPart] | type[MismatchPart] | type[RtdacPart]] = {
    "model": ModelPart,
    "rig": RigPart,
    "mismatch": MismatchPart,
    "rtdac": RtdacPart,
}
