"""The public law API: what a semi-active law is, its parameters, and what it reads each cycle.

A law is a class with a ``name``, parameters declared as :class:`Param` class attributes, and one
of two outputs:

* ``torque(state) -> float``: the desired damper torque T* [N m]; the hysteresis inverse picks the
  current whose predicted torque ``alpha(i)*z_hat + c(i)*theta_dot`` (seed 001 eq. 17) is closest;
* ``current(state) -> float``: the coil current [A] directly, bypassing the inverse.

::

    from sashil.control import Law, Param

    class SoftSkyhook(Law):
        name = "soft-skyhook"
        c_sky = Param(1.0, unit="N m s/rad", low=0.0, doc="sky damping")

        def torque(self, state):
            return self.c_sky * state.body_dot_rad_s

Parameters are set from ``controller.<name>`` in a config or ``--set controller.<name>=v`` and
checked by the config schema's own code (:class:`sashil.config.schema.Field`), so a bad value is
the same one-line error as any other key. A :class:`Param` without a default is required.

Optional hooks: ``parameters_changed()`` runs after the parameters are set (derive gains here, or
raise :class:`~sashil.errors.ConfigError` naming ``controller.<param>``), ``reset()`` before a run.
``self.context`` (a :class:`LawContext`: the controller's model, the current range, the loop rate)
is set before ``parameters_changed()``.

The road ahead: a law with ``reads_road_ahead = True`` reads, each cycle, the road angle and rate
of the next :meth:`Law.preview_cycles` cycles (``state.road_ahead_rad``,
``state.road_ahead_dot_rad_s``), which the plan that commands the road supplies (a run on a road
profile, ``compare``, a sweep): the commanded speeds exactly, the angles as the measured road angle
plus the commanded motion from now on. Before the run it is handed the whole commanded road once
(:meth:`Law.plan_road`), so it may plan before the first cycle. Such a law under a plan with no road
(a drop test, ``--road none``, a replay) is refused when the config is resolved.

A law that raises, or returns NaN, an infinity or a non-number, ends the run at 0 A
(:class:`~sashil.errors.LawError`); the controller checks every output.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from sashil.config.schema import Field
from sashil.errors import ConfigError
from sashil.models.hysteresis import BoucWenParams

__all__ = ["REQUIRED", "CommandedRoad", "Law", "LawContext", "LawState", "Param"]


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: the default of a parameter that has none: the config must set it
REQUIRED: Any = _Required()

_KINDS = {bool: "bool", int: "int", float: "float", str: "str", list: "float_list"}


class Param:
    """A law parameter: its default, unit, bounds and meaning; read on an instance as ``self.<name>``.

    ``default`` fixes the kind (float, int, bool, str, a list of numbers); ``None`` is a number
    that may be left null (the law then derives it); no default makes the parameter required.
    ``low_open``: the value must be strictly greater than ``low``. ``choices``: for a string.
    """

    def __init__(
        self,
        default: Any = REQUIRED,
        *,
        unit: str = "",
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
        choices: tuple[str, ...] = (),
        doc: str = "",
        kind: str | None = None,
    ):
        self.default = default
        self.unit, self.doc = unit, doc
        self.low, self.high, self.low_open, self.choices = low, high, low_open, tuple(choices)
        self.required = default is REQUIRED
        if kind is None:
            if default is REQUIRED or default is None:
                kind = "float"
            elif choices:
                kind = "choice"
            else:
                kind = _KINDS.get(type(default), "")
                if not kind:
                    raise TypeError(f"Param: no parameter kind for a default of type {type(default).__name__}")
        if default is None:
            kind += "?"
        self.field = Field(
            kind,
            None if self.required else default,
            low=low,
            high=high,
            low_open=low_open,
            choices=self.choices,
            doc=doc,
        )
        self.name = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: object, owner: type | None = None) -> Any:
        if obj is None:
            return self
        return self.default  # an instance holds its own value in __dict__; this is the fallback

    def describe(self) -> str:
        """``1.0 N m s/rad, > 0`` style summary of the default, unit and bounds."""
        default = "required" if self.required else ("null" if self.default is None else repr(self.default))
        unit = f" {self.unit}" if self.unit else ""
        bounds = self.field.expected()
        return f"{default}{unit} ({bounds})"


@dataclass(frozen=True)
class LawContext:
    """What a law may know of the rig it runs on: the controller's model (seed 001 eqs. 9-17),
    the coil's current range [0, current_max_a], the loop's rate and the coil's first-order lag
    the controller assumes (``controller.coil_tau_s``, else ``rig.coil_tau_s``; 0: none known)."""

    model: BoucWenParams
    current_max_a: float
    rate_hz: float
    coil_tau_s: float = 0.0


@dataclass(frozen=True)
class CommandedRoad:
    """The road a plan will command, sampled every loop period ``dt_s`` from the run's first cycle:
    ``rate_rad_s[k]`` the road speed θ̇1 commanded at cycle k (held over that period, as the road
    motor's speed loop holds it) and ``theta_rad[k]`` the road angle θ1 at cycle k that those speeds
    give from 0 (``theta_rad[k] = dt_s * sum(rate_rad_s[:k])``)."""

    dt_s: float
    rate_rad_s: np.ndarray
    theta_rad: np.ndarray


_EMPTY = np.zeros(0)


class LawState:
    """What a law reads each cycle (overwritten in place by the controller; never keep a reference
    to it across cycles). Angles are relative (theta = theta2 - theta1), body is the arm (theta2),
    road the wheel side (theta1)."""

    __slots__ = (
        "band_hi_nm",
        "band_lo_nm",
        "body_ddot_rad_s2",
        "body_dot_rad_s",
        "current_a",
        "road_ahead_dot_rad_s",
        "road_ahead_rad",
        "road_dot_rad_s",
        "road_rad",
        "theta_dot_rad_s",
        "theta_rad",
        "time_s",
        "torque_hat_nm",
        "z_hat",
    )

    def __init__(self) -> None:
        #: seconds since the controller's first cycle
        self.time_s = 0.0
        #: relative angle theta = theta2 - theta1 [rad] and its rate [rad/s] (the estimator's)
        self.theta_rad = 0.0
        self.theta_dot_rad_s = 0.0
        #: the arm's (body) rate and model acceleration (-k*theta - T_hat)/J (seed 001 eq. 13)
        self.body_dot_rad_s = 0.0
        self.body_ddot_rad_s2 = 0.0
        #: the road (wheel) side's rate [rad/s]
        self.road_dot_rad_s = 0.0
        #: the observer's damper torque T_hat = alpha(i)*z_hat + c(i)*theta_dot [N m] and its z_hat
        self.torque_hat_nm = 0.0
        self.z_hat = 0.0
        #: the feasible torque band at this z_hat and rate: [T(0 A), T(i_max)] ordered [N m]
        self.band_lo_nm = 0.0
        self.band_hi_nm = 0.0
        #: the coil current measured this cycle [A]
        self.current_a = 0.0
        #: the road (wheel) side's angle theta1 [rad] (the estimator's)
        self.road_rad = 0.0
        #: a law that reads the road ahead: the road angle theta1 at the next N cycles' samples
        #: [rad] (the measured angle now plus the commanded motion) and the road speed commanded over
        #: each of the next N periods, this one first [rad/s]; empty for any other law
        self.road_ahead_rad: np.ndarray = _EMPTY
        self.road_ahead_dot_rad_s: np.ndarray = _EMPTY


class Law:
    """Base of every semi-active law (see the module docstring for the contract)."""

    #: the name ``controller.law`` and ``--controller`` select it by
    name: ClassVar[str] = ""
    #: whether the law reads the rig's state each cycle. True (the default): the estimator, the
    #: Bouc-Wen observer, the feasible band and the coil lead run for it. False (a law that ignores
    #: the state, such as a constant current): it runs as a constant-current stage without them,
    #: and a drop test records no controller columns for it.
    reads_state: ClassVar[bool] = True
    #: whether the law reads the road ahead (``state.road_ahead_rad``, ``state.road_ahead_dot_rad_s``
    #: over :meth:`preview_cycles`, and :meth:`plan_road` before the run): only a plan that commands
    #: the road can run it
    reads_road_ahead: ClassVar[bool] = False

    def label(self) -> str:
        """What a run calls the law in its summary and plots (``controller``): its name by default."""
        return self.name

    def __init__(self, context: LawContext | None = None, **params: Any):
        self.context = context
        self.set_parameters(params, defaults=True)

    # -- parameters ------------------------------------------------------------------------------
    @classmethod
    def params(cls) -> dict[str, Param]:
        """The declared parameters by name, in declaration order (base classes first)."""
        out: dict[str, Param] = {}
        for klass in reversed(cls.__mro__):
            for key, value in vars(klass).items():
                if isinstance(value, Param):
                    out[key] = value
        return out

    @classmethod
    def output_kind(cls) -> str:
        """``"torque"`` or ``"current"``: which output the class implements ("" for neither, or both)."""
        has_torque = cls.torque is not Law.torque
        has_current = cls.current is not Law.current
        if has_torque == has_current:
            return ""
        return "torque" if has_torque else "current"

    def set_parameters(self, values: Mapping[str, Any], defaults: bool = False) -> None:
        """Check and set parameters (``controller.<name>`` in messages), then ``parameters_changed()``.

        ``defaults``: also set every parameter not in ``values`` to its default (a required one
        missing is an error). A value refused by the checks or by ``parameters_changed()`` leaves
        the law with the values it had (a running law can be retuned safely)."""
        checked = self.check_parameters(values, defaults)
        before = {key: self.__dict__[key] for key in checked if key in self.__dict__}
        self.__dict__.update(checked)
        try:
            self.parameters_changed()
        except BaseException:  # refused: the law keeps the values it had
            for key in checked:
                if key in before:
                    self.__dict__[key] = before[key]
                else:
                    self.__dict__.pop(key, None)
            if before:
                self.parameters_changed()
            raise

    def check_parameters(self, values: Mapping[str, Any], defaults: bool = False) -> dict[str, Any]:
        """``values`` checked against the declared parameters (unknown names, kinds, bounds; the
        same code as a config key), as the law would store them; nothing is set. ``defaults``: see
        :meth:`set_parameters`. ConfigError naming ``controller.<name>`` for the first bad one."""
        declared = self.params()
        for key in values:
            if key not in declared:
                known = ", ".join(declared) or "none"
                raise ConfigError(
                    f"controller.{key}: law {self.name!r} has no parameter {key} (its parameters: {known})"
                )
        checked: dict[str, Any] = {}
        for key, param in declared.items():
            if key in values:
                checked[key] = param.field.check(values[key], f"controller.{key}")
            elif defaults:
                if param.required:
                    raise ConfigError(missing_parameter(self.name, param))
                checked[key] = param.field.check(param.default, f"controller.{key}")
        return checked

    def parameter_values(self) -> dict[str, Any]:
        """The current value of every parameter (what a run folder's config records)."""
        return {key: getattr(self, key) for key in self.params()}

    # -- hooks -----------------------------------------------------------------------------------
    def parameters_changed(self) -> None:
        """Called after parameters are set: derive what the law needs from them."""

    def reset(self) -> None:
        """Called before a run: clear any state the law keeps between cycles."""

    def preview_cycles(self) -> int:
        """How many cycles of the road ahead the law reads each cycle (a law that reads the road ahead)."""
        return 0

    def plan_road(self, road: CommandedRoad) -> None:
        """Called once before the run of a law that reads the road ahead, with the whole road the
        plan will command: plan here, before the first cycle, not in one."""

    # -- outputs (a law implements exactly one) --------------------------------------------------
    def torque(self, state: LawState) -> float:
        """The desired damper torque T* [N m] (through the inverse)."""
        raise NotImplementedError

    def current(self, state: LawState) -> float:
        """The coil current [A] (no inverse)."""
        raise NotImplementedError


def missing_parameter(law: str, param: Param) -> str:
    """The one-line error for a required parameter left unset, with the option that sets it."""
    what = ", ".join(part for part in (param.doc, param.unit) if part)
    what = f" ({what})" if what else ""
    return (
        f"controller.{param.name}: law {law!r} needs {param.name}{what}: "
        f"add --set controller.{param.name}=VALUE or set it in the config's controller: section"
    )
