"""The one ``summary.json`` schema every verb writes (``schema_version`` 2).

Every summary has the common keys below, whatever the verb; a verb adds its own keys beside them
(a drop test's metrics per current under ``runs``, a sweep's ``points``, a loop run's
``realtime``, ...). :func:`normalise` fills the common keys a verb did not set, so readers
(``sashil.load_run``, ``sashil report``, your scripts) can rely on them:

=================  ====================================================================
``schema_version`` 2 (raised when a common key changes meaning or is removed; 2: ``controller``
                   is the law's name, never the path or module it was given by, beside
                   ``controller_origin``; a compare folder lists each law's run folder in ``runs``)
``verb``           the verb that wrote the folder: run, drop-test, sweep, simulate, ...
``exit_status``    ok | stopped | safety_trip | deadline_missed | lossy | error
``exit_code``      the process exit code of that status (0, 130, 3, 4, 5, 1 or the error's)
``error``          one line, or null
``driver``         sim | serial | can | rtdac (or a lab's backend), or null when no rig was driven (simulate)
``controller``     what commanded the damper, by the law's name (``passive 0.5 A``,
                   ``skyhook``, ...), or null
``controller_origin`` where the law came from: ``built-in``, ``package NAME``, ``file PATH``
                   or ``module NAME`` (from ``controller_stats.law.origin`` when a verb does
                   not say), or null
``timing``         loop timing ``{rate_hz, cycles, missed_deadlines, lateness_us: {p50, p99,
                   max}, compute_us: {...}}``, or null (no loop, or one per sub-run)
``trips``          safety trips ``[{time_s, kind, reason}, ...]`` (of every sub-run), or []
``runs``           sub-runs ``[{folder, ...}, ...]`` (a drop test: one per current, ``folder``
                   ``.`` when the folder itself is the run), or []
``started_utc``    ISO 8601 times, and ``provenance`` (version, git revision, host, command)
``ended_utc``
=================  ====================================================================
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from sashil.errors import exit_code_of

SCHEMA_VERSION = 2


#: the common keys and their value when a verb does not set them
COMMON_DEFAULTS: dict[str, Any] = {
    "error": None,
    "driver": None,
    "controller": None,
    "controller_origin": None,
    "timing": None,
    "trips": [],
    "runs": [],
}


def _finite(value: Any) -> Any:
    """JSON has no NaN/inf: they become null, at any depth."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(item) for item in value]
    return value


def normalise(summary: Mapping[str, Any], verb: str | None) -> dict[str, Any]:
    """``summary`` with ``schema_version`` and every common key (verb's own keys kept as given)."""
    doc: dict[str, Any] = {"schema_version": SCHEMA_VERSION}
    doc["verb"] = summary.get("verb", verb)
    status = summary.get("exit_status", "ok")
    if not isinstance(status, str):  # an old writer's 0 / non-zero
        status = "ok" if status == 0 else "error"
    doc["exit_status"] = status
    doc["exit_code"] = summary.get("exit_code", exit_code_of(status))
    for key, default in COMMON_DEFAULTS.items():
        doc[key] = summary.get(key, list(default) if isinstance(default, list) else default)
    if doc["controller_origin"] is None:  # a controller's run reports its law's origin in its stats
        stats = summary.get("controller_stats")
        law = stats.get("law") if isinstance(stats, Mapping) else None
        if isinstance(law, Mapping) and isinstance(law.get("origin"), str) and law["origin"]:
            doc["controller_origin"] = law["origin"]
    if not doc["trips"] and doc["runs"]:
        doc["trips"] = [
            {**trip, "run": entry.get("folder")} for entry in doc["runs"] for trip in (entry.get("trips") or [])
        ]
    for key, value in summary.items():
        if key not in doc:
            doc[key] = value
    return _finite(doc)
