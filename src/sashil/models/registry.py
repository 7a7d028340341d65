"""Model names, their parameter symbols, and checks of a ``model`` section / parameter file.

Plain data and the seed's floats: the config schema checks a ``model`` section with
:func:`check_model_section` without loading a model's numerics.
"""

from __future__ import annotations

from typing import Any

from sashil.errors import ConfigError
from sashil.models.seed import BOUC_WEN_SEED

#: model name -> its parameter symbols (seed 001 names; docs/architecture.md parameter-file shape)
MODEL_PARAMS: dict[str, tuple[str, ...]] = {
    "bouc-wen": tuple(BOUC_WEN_SEED),
    "dahl": ("J", "k", "c1", "c2", "kwa", "kwb", "rho"),
    "lugre": ("J", "k", "sigma_a", "sigma_b", "sigma0", "sigma1", "sigma2", "a0"),
    "bingham": ("J", "k", "c0", "c0_i", "fc", "fc_i", "f0"),
}

#: the models a rig verb runs: the simulated and emulated rig's plant and the controller's observer
#: are Bouc-Wen (``sashil simulate`` runs every model of :data:`MODEL_PARAMS`)
RIG_MODELS: tuple[str, ...] = ("bouc-wen",)


def check_model(section: dict[str, Any], source: str, where: str, complete: bool = False) -> dict[str, Any]:
    """Check a ``{name, params}`` model section; return it with float parameters.

    Unknown symbols, non-numbers and (for the rig's Bouc-Wen model) values that break the analytic
    bound are one-line ConfigErrors naming ``source`` and the key.
    """
    prefix = f"{where}." if where else ""
    name = section.get("name", "bouc-wen")
    if name not in MODEL_PARAMS:
        raise ConfigError(f"{source}: {prefix}model: unknown model {name!r} (known: {', '.join(MODEL_PARAMS)})")
    symbols = MODEL_PARAMS[name]
    params = section.get("params") or {}
    if not isinstance(params, dict):
        raise ConfigError(f"{source}: {prefix}params: expected a mapping of {name} parameters, got {params!r}")
    out: dict[str, float] = {}
    for key, value in params.items():
        if key not in symbols:
            raise ConfigError(f"{source}: {prefix}params.{key}: not a {name} parameter (expected {', '.join(symbols)})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
            raise ConfigError(f"{source}: {prefix}params.{key}: expected a number, got {value!r}")
        out[key] = float(value)
    if complete or name != "bouc-wen":
        missing = [s for s in symbols if s not in out]
        if missing:
            raise ConfigError(f"{source}: {prefix}params: missing {', '.join(missing)} for model {name}")
    if name == "bouc-wen":
        merged = {**BOUC_WEN_SEED, **out}
        for key in ("J", "n", "delta"):
            if merged[key] <= 0:
                raise ConfigError(f"{source}: {prefix}params.{key}: expected a number > 0, got {merged[key]:g}")
        for key in ("k", "c1", "alpha1"):
            if merged[key] < 0:
                raise ConfigError(f"{source}: {prefix}params.{key}: expected a number >= 0, got {merged[key]:g}")
        if merged["beta"] + merged["gamma"] <= 0:
            raise ConfigError(
                f"{source}: {prefix}params.beta+gamma: expected > 0 (bounded z), got {merged['beta'] + merged['gamma']:g}"
            )
        out = merged
    return {"name": name, "params": out}


def check_model_section(given: Any, section: dict[str, Any], source: str, where: str) -> dict[str, Any]:
    """The schema's check of a config's ``model`` section (:class:`~sashil.config.schema.Section`
    ``check``): ``section`` is ``given`` merged over the defaults, whose parameters are the Bouc-Wen
    seed's, so another model keeps only the parameters ``given`` names."""
    if section.get("name") != "bouc-wen":
        params = given.get("params") if isinstance(given, dict) else None
        section = {**section, "params": dict(params or {})}
    return check_model(section, source, where)
