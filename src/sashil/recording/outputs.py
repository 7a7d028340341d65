"""What a run writes beside its stream, chosen by the caller: the folder, ``--format`` files, CAN
traces and the rerun live view.

:class:`Outputs` is the part of a run that is not the config: where the folder goes and what is
written or shown beside ``data.csv``. The helpers here open and close those writers for the
experiments in :mod:`sashil.lab`, so each experiment needs one call at the start and one at the end.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil._version import __version__
from sashil.errors import ConfigError
from sashil.recording.formats import can_formats, check_formats, write_data_formats

if TYPE_CHECKING:
    from sashil.config.section_parts import ModelPart

__all__ = ["IN_RUN_FOLDER", "Outputs"]

#: ``rerun_save`` meaning ``live.rrd`` in the run folder (a marker no path can equal)
IN_RUN_FOLDER = "{run folder}/live.rrd"


@dataclass(frozen=True)
class Outputs:
    """Where a run's folder goes and what is written or shown beside its data."""

    #: the run folder (None: ``runs/<UTC timestamp>-<verb>/``); an existing non-empty one is refused
    out: str | Path | None = None
    #: extra data formats (``mat``, ``parquet``) and CAN traces (``blf``, ``asc``, ``log``, ``mf4``)
    formats: Sequence[str] = ()
    #: spawn the rerun viewer and stream the run to it
    rerun_viewer: bool = False
    #: the address a spawned viewer listens on
    rerun_bind: str = "127.0.0.1"
    #: stream to a running rerun viewer at this URL
    rerun_connect: str | None = None
    #: record the live view to this ``.rrd`` file (:data:`IN_RUN_FOLDER`: ``live.rrd`` in the folder)
    rerun_save: str | Path | None = None

    @property
    def live_view(self) -> bool:
        return bool(self.rerun_viewer or self.rerun_connect or self.rerun_save)

    def check(self, driver: str) -> None:
        """ConfigError for a format the driver cannot write (before anything runs)."""
        check_formats(list(self.formats) or None, driver)

    def check_folder_only(self, verb: str) -> None:
        """ConfigError when formats or a live view are asked of a verb that writes its folder only
        (it has no loop to stream and no ``--format``)."""
        asked = [*(f"--format {name}" for name in self.formats), *(["a live view (rerun)"] if self.live_view else [])]
        if asked:
            raise ConfigError(f"sashil {verb} writes its run folder only: {', '.join(asked)} is not available")

    def open_rerun(self, columns: Sequence[str], name: str, folder: Path) -> Any:
        """The :class:`~sashil.recording.rerun_log.RerunLog` asked for, or None."""
        if not self.live_view:
            return None
        from sashil.recording.rerun_log import RerunLog

        save = self.rerun_save
        if save == IN_RUN_FOLDER:
            save = Path(folder) / "live.rrd"
        return RerunLog.open(
            columns, save=save, viewer=self.rerun_viewer, connect=self.rerun_connect, name=name, bind=self.rerun_bind
        )

    def open_live_tap(
        self, model: ModelPart, current_max_a: float, columns: Sequence[str], name: str, folder: Path
    ) -> Any:
        """A :class:`~sashil.recording.rerun_log.LiveTap` for a loop run, or None without a live view.
        The feasible torque band of ``model`` (its ``name`` and ``params``) up to ``current_max_a``
        is added for the Bouc-Wen model."""
        if not self.live_view:
            return None
        from sashil.recording.rerun_log import LiveTap

        band = None
        if model.name == "bouc-wen" and "z_hat" in columns and "theta_dot_rad_s" in columns:
            band = (model.params, float(current_max_a))
        extra = ("lateness_us",) + (("band_lo_nm", "band_hi_nm") if band is not None else ())
        return LiveTap(self.open_rerun(tuple(columns) + extra, name, folder), band=band)

    def can_trace(self, folder: Path, port: str | None) -> Any:
        """The CAN frame trace the formats ask for, into ``folder``, not started, or None."""
        from sashil.recording.can_trace import CanTrace  # the CAN backend's registry, loaded when traced

        return CanTrace.for_formats(folder, can_formats(tuple(self.formats)), port)

    def start_can_trace(self, rig: Any, folder: Path) -> Any:
        """The running CAN frame trace the formats ask for, attached to ``rig``, or None."""
        trace = self.can_trace(folder, getattr(getattr(rig, "settings", None), "port", None))
        if trace is None:
            return None
        trace.attach(rig)
        return trace.start()

    def follow_can_trace(self, folder: Path, port: str | None, source: Callable[[], Iterable[Any]]) -> Any:
        """The running CAN frame trace the formats ask for, fed by ``source`` (the frames of a rig
        held by the loop process), or None."""
        trace = self.can_trace(folder, port)
        return None if trace is None else trace.follow(source).start()

    def write_formats(
        self,
        folder: Path,
        verb: str,
        columns: Mapping[str, Any] | None = None,
        *,
        exit_status: str,
        **meta: Any,
    ) -> list[Path]:
        """The data files the formats ask for (from ``columns``, else from data.csv), with the run's
        verb, exit status, sashil version and ``meta`` (controller, current, ...) beside the rows."""
        about = {"verb": verb, "exit_status": exit_status, "sashil_version": __version__, **meta}
        return write_data_formats(folder, tuple(dict.fromkeys(self.formats)), columns, about)
