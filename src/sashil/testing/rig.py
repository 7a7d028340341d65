"""The simulated rig a lab's tests run their law on, and :func:`run_law`.

A run goes through the same library code as ``sashil compare`` runs each law with
(:func:`sashil.lab._compare.run_job`: the law's stage, the road, the one runner
:func:`~sashil.runtime.runner.run_plan` on the virtual clock, the metrics of the stream), into a run
folder that :func:`sashil.load_run` reads: ``config.yaml`` (rerunning it with
``sashil compare --config`` repeats the run), ``data.csv``, ``timing.npz`` and ``summary.json``
with the law's metrics (``run.metrics``: RMS θ̈2, RMS θ, peak current, coil energy).
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from sashil.api import Run, load_run
from sashil.config.parts import StageParts
from sashil.config.typed import RunConfig
from sashil.control.registry import law_run_label
from sashil.engine.resolve import ConfigSource, Option, resolve
from sashil.lab._compare import LawJob, folder_name, law_summary, run_job
from sashil.plugins import check_not_importing
from sashil.roads.option import RoadParts, parse_road
from sashil.scripting import law_spec, set_items
from sashil.writer.documents import Documents
from sashil.writer.folder_writer import FolderWriter
from sashil.writer.run_folder import RunFolder

__all__ = ["DEFAULT_ROAD", "SimRig", "run_law", "warm_up"]

#: the road a law runs on when a test names none: ISO 8608 class C, as ``sashil compare``'s default
DEFAULT_ROAD = "iso8608:C"


@dataclass(frozen=True)
class SimRig:
    """The simulated rig on the virtual clock, with a damper of the lab's choice and seeded noise.

    ``damper``: the Bouc-Wen parameters (seed 001 eqs. 9-17) that differ from the seed's, as
    ``{"c2": 2.0}`` (symbols of ``model.params``), or the path of a parameter file that
    ``sashil identify`` or ``sashil calibrate`` wrote. The plant and the controller's observer both
    use it. ``seed`` seeds the encoders' angle noise (``angle_noise_rad``, Gaussian, on each encoder
    before it is counted) and the coil current sensor's (``current_noise_a``); the same seed gives
    the same run, row for row. ``sets``: any other config keys, as ``--set`` takes them
    (``{"rig.coil_tau_s": 0.02}``). ``out``: the folder the runs' folders go in (when None, a new
    temporary folder per run, left for the caller to read)."""

    damper: Mapping[str, float] | str | Path | None = None
    seed: int = 0
    angle_noise_rad: float = 1e-4
    current_noise_a: float = 0.002
    rate_hz: float = 1000.0
    sets: Mapping[str, Any] = field(default_factory=dict)
    out: Path | None = None

    def with_seed(self, seed: int) -> SimRig:
        """This rig with another noise seed."""
        return replace(self, seed=seed)

    def config(
        self,
        law: str | type,
        *,
        road: str = DEFAULT_ROAD,
        duration_s: float = 10.0,
        params: Mapping[str, Any] | None = None,
    ) -> RunConfig:
        """The resolved, read-only config of ``law`` with ``params`` on ``road`` for ``duration_s``
        on this rig (ConfigError for a bad key, parameter or road, before anything runs)."""
        damper_file = None
        sets: dict[str, Any] = {
            "driver.name": "sim",
            "driver.clock": "virtual",
            "rig.noise_seed": int(self.seed),
            "rig.angle_noise_rad": float(self.angle_noise_rad),
            "rig.current_noise_a": float(self.current_noise_a),
            "loop.rate_hz": float(self.rate_hz),
            **dict(self.sets),
        }
        if isinstance(self.damper, Mapping):
            sets.update({f"model.params.{key}": float(value) for key, value in self.damper.items()})
        elif self.damper is not None:
            damper_file = self.damper
        sets.update({f"controller.{key}": value for key, value in (params or {}).items()})
        source = ConfigSource(
            params=damper_file,
            controller=law_spec(law),
            sets=tuple(set_items(sets)),
            options=(
                Option("road", "compare.road", str(road)),
                Option("duration_s", "compare.duration_s", float(duration_s)),
            ),
        )
        return resolve(source, "compare")

    def run(self, law: str | type, *, road: str = DEFAULT_ROAD, duration_s: float = 10.0, **params: Any) -> Run:
        """:func:`run_law` on this rig: ``rig.run(SoftSkyhook, road="sine:1.2:1", c_sky=2.0)``."""
        return run_law(law, road=road, duration_s=duration_s, params=params, rig=self)


def run_law(
    law: str | type,
    *,
    road: str = DEFAULT_ROAD,
    duration_s: float = 10.0,
    params: Mapping[str, Any] | None = None,
    rig: SimRig | None = None,
) -> Run:
    """Run ``law`` (a Law class, a registered name, ``module:Class`` or ``file.py:Class``) with its
    ``params`` on ``road`` (``--road`` syntax) for ``duration_s`` of rig time on ``rig`` (the default
    :class:`SimRig` when None), and return the run folder as :func:`sashil.load_run` gives it.

    A law that fails (raises, returns NaN or an infinity) does not raise here: the run ends at 0 A,
    as on the bench, and ``run.summary["exit_status"]`` and ``["error"]`` say why (the contract check,
    :func:`sashil.testing.check_law`, turns that into a fault line)."""
    check_not_importing("sashil.testing.run_law")  # a script's law file imported for its class runs nothing
    rig = rig if rig is not None else SimRig()
    config = rig.config(law, road=road, duration_s=duration_s, params=params)  # bad input: ConfigError here
    label = law_run_label(StageParts.read(config))
    root = Path(rig.out) if rig.out is not None else Path(tempfile.mkdtemp(prefix="sashil-testing-"))
    folder = RunFolder.create(_free(root / folder_name(label)), "compare")
    documents = Documents([FolderWriter(folder, "compare", {}, several=False)])
    documents.start(None, config)
    result = run_job(LawJob(label, config, road, float(duration_s), str(folder.path)))
    _, road_text = parse_road(road, RoadParts.read(config))
    documents.summary(None, law_summary(result, config, f"{road}: {road_text}", float(duration_s)))
    return load_run(folder.path)


def _free(path: Path) -> Path:
    """``path``, or ``path-2``, ``path-3``... when it is taken (several runs of one law in a test)."""
    candidate, n = path, 1
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.name}-{n}")
    return candidate


def warm_up() -> None:
    """Load what the first run of a process loads late (scipy's signal tools for the metrics, numba's
    kernels of the plant and the observer, the road's tables) with half a second of the skyhook law,
    so each test's own run costs only its rig time."""
    with tempfile.TemporaryDirectory(prefix="sashil-warm-") as folder:
        rig = SimRig(out=Path(folder), sets={"compare.settle_s": 0.1})
        run_law("skyhook", duration_s=0.5, params={"c_sky": 1.0}, rig=rig)
