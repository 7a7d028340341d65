"""Plant mismatch: a simulated plant that differs from the model the controller believes.

The config's ``mismatch`` section offsets each Bouc-Wen parameter of the *plant* by a fraction
(``fraction`` with a sign ``pattern``, or per parameter in ``params``), scales the coil lag, and
may change the plant's encoder quantisation and sensor noise. The controller keeps using
the config's ``model`` and ``rig.coil_tau_s``; only the simulated rig sees the changed values, so
every result can be shown with an imperfect model, as on a real rig.

Note on this parametrisation: the hysteretic bound z_u = (delta/(beta+gamma))^(1/n) with n ~ 0.1
amplifies a change of delta/(beta+gamma) about tenfold, so patterns that move delta and beta in
opposite directions change the yield torque alpha*z_u by a factor, not by 10 %.
"""

from __future__ import annotations

import random
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from sashil.config.frozen import freeze, thaw
from sashil.config.section_parts import MismatchPart, ModelPart, RigPart, section_of
from sashil.errors import ConfigError
from sashil.models.hysteresis import BoucWenParams

PARAMETER_ORDER = tuple(BoucWenParams.__dataclass_fields__)  # J, k, c1, c2, alpha1, alpha2, beta, gamma, delta, n


def mismatch_fractions(section: Mapping[str, Any]) -> dict[str, float]:
    """Per-parameter fractions of the ``mismatch`` section (pattern first, ``params`` overriding)."""
    fraction = float(section.get("fraction", 0.0) or 0.0)
    pattern = section.get("pattern", "alternate")
    if pattern == "alternate":
        signs = [1.0 if index % 2 == 0 else -1.0 for index in range(len(PARAMETER_ORDER))]
    elif pattern == "plus":
        signs = [1.0] * len(PARAMETER_ORDER)
    elif pattern == "minus":
        signs = [-1.0] * len(PARAMETER_ORDER)
    elif pattern == "random":
        rng = random.Random(int(section.get("seed", 0) or 0))
        signs = [rng.choice((-1.0, 1.0)) for _ in PARAMETER_ORDER]
    else:
        raise ConfigError(f"mismatch.pattern: expected one of 'alternate', 'plus', 'minus', 'random', got {pattern!r}")
    out = {key: sign * fraction for key, sign in zip(PARAMETER_ORDER, signs, strict=True)}
    for key, value in (section.get("params") or {}).items():
        if key not in PARAMETER_ORDER:
            raise ConfigError(
                f"mismatch.params.{key}: not a bouc-wen parameter (expected {', '.join(PARAMETER_ORDER)})"
            )
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not -0.9 <= value <= 10.0:
            raise ConfigError(f"mismatch.params.{key}: expected a fraction in [-0.9, 10], got {value!r}")
        out[key] = float(value)
    return out


def plant_parts(model: ModelPart, rig: RigPart, mismatch: MismatchPart | None) -> tuple[ModelPart, RigPart]:
    """The simulated plant's model and rig: ``model`` and ``rig`` after the ``mismatch`` section
    (None: unchanged)."""
    params = thaw(model.params)
    for key, frac in mismatch_fractions(vars(mismatch) if mismatch is not None else {}).items():
        if key in params:
            params[key] = params[key] * (1.0 + frac)
    if params.get("beta", 1.0) + params.get("gamma", 0.0) <= 0:
        raise ConfigError("mismatch: the plant's beta + gamma must stay > 0 (bounded z)")
    if mismatch is None:
        return replace(model, params=freeze(params, "model.params")), rig
    changed = {
        key: getattr(mismatch, key)
        for key in ("encoder_counts_per_rev", "angle_noise_rad", "current_noise_a")
        if getattr(mismatch, key) is not None
    }
    return replace(model, params=freeze(params, "model.params")), replace(
        rig, coil_tau_s=rig.coil_tau_s * (1.0 + mismatch.coil_tau), **changed
    )


def plant_sections(
    model: Mapping[str, Any], rig: Mapping[str, Any], mismatch: Mapping[str, Any] | None
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The simulated plant's ``model`` and ``rig`` sections (:func:`plant_parts`) of whole sections of
    a resolved config: copies of the given ones after the ``mismatch`` section (None or empty: unchanged)."""
    plant_model, plant_rig = plant_parts(
        ModelPart.read(model), RigPart.read(rig), MismatchPart.read(mismatch) if mismatch else None
    )
    return section_of(plant_model), section_of(plant_rig)
