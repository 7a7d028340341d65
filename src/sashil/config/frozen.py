"""A resolved config is read-only: :func:`freeze` turns the nested dicts into :class:`FrozenSection`.

A resolved config is what a run runs with and what ``config.yaml`` records, so nothing may change
it after it is resolved: every mutator of a :class:`FrozenSection` raises ``TypeError`` naming the
key. Reading is a plain ``dict`` read (``config["loop"]["rate_hz"]``), so the per-cycle code pays
nothing. ``copy.deepcopy`` and :func:`thaw` give an ordinary, writable copy, from which a derived
config (a sub-run's) is built and frozen again.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, NoReturn, cast

if TYPE_CHECKING:
    from sashil.config.typed import RunConfig

__all__ = ["FrozenSection", "freeze", "freeze_config", "thaw"]


class FrozenSection(dict[str, Any]):
    """A read-only ``dict`` section of a resolved config."""

    __slots__ = ("_where",)
    _where: str

    def _refuse(self, *_: Any, **__: Any) -> NoReturn:
        raise TypeError(
            f"the resolved config is read-only ({getattr(self, '_where', '') or 'top level'}): "
            "resolve a new config (sashil.engine.resolve) or copy it with sashil.config.frozen.thaw"
        )

    __setitem__ = __delitem__ = _refuse
    clear = pop = popitem = setdefault = update = _refuse
    __ior__ = _refuse

    def __deepcopy__(self, memo: dict[int, Any]) -> dict[str, Any]:
        return thaw(self)

    def __copy__(self) -> dict[str, Any]:
        return dict(self)

    def __reduce__(self) -> tuple[Any, ...]:  # pickles as a plain dict (a process hand-off thaws it)
        return (dict, (thaw(self),))


def freeze(config: Mapping[str, Any], where: str = "") -> FrozenSection:
    """A read-only deep copy of ``config`` (lists become tuples)."""
    section = FrozenSection(
        {key: _freeze_value(value, f"{where}.{key}" if where else str(key)) for key, value in config.items()}
    )
    section._where = where
    return section


def freeze_config(config: Mapping[str, Any]) -> RunConfig:
    """A whole config (one :func:`~sashil.engine.resolve.resolve` checked, or a copy derived from
    such a one: a sub-run's, the simulated plant's) frozen and typed as the resolved config it is."""
    return cast("RunConfig", freeze(config))


def _freeze_value(value: Any, where: str) -> Any:
    if isinstance(value, Mapping):
        return freeze(value, where)
    if isinstance(value, list):
        return tuple(_freeze_value(item, where) for item in value)
    return value


def thaw(config: Mapping[str, Any]) -> dict[str, Any]:
    """A plain, writable deep copy of a (frozen) config: dicts and lists again."""
    return {key: _thaw_value(value) for key, value in config.items()}


def _thaw_value(value: Any) -> Any:
    if isinstance(value, Mapping):
        return thaw(value)
    if isinstance(value, (list, tuple)):
        return [_thaw_value(item) for item in value]
    return copy.deepcopy(value)
