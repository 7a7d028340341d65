"""What a verb writes beside ``data.csv`` after (or while) it runs: ``--format`` files, CAN traces, plots.

Thin glue between the command line and the writers in :mod:`sashil.recording` (formats, can_trace,
plots), so each verb needs one call at the start and one at the end.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sashil import __version__
from sashil.cli.common import formats
from sashil.recording.can_trace import CanTrace
from sashil.recording.formats import can_formats, write_data_formats
from sashil.recording.run_folder import RunFolder


def start_can_trace(args: argparse.Namespace, rig: Any, folder: Path) -> CanTrace | None:
    """The running CAN frame trace ``--format blf|asc|log|mf4`` asks for, attached to ``rig``, or None."""
    port = getattr(getattr(rig, "settings", None), "port", None)
    trace = CanTrace.for_formats(folder, can_formats(formats(args)), port)
    if trace is None:
        return None
    trace.attach(rig)
    return trace.start()


def write_formats(
    args: argparse.Namespace,
    folder: Path,
    config: Mapping[str, Any],
    verb: str,
    columns: Mapping[str, Any] | None = None,
    *,
    exit_status: str,
    **meta: Any,
) -> list[Path]:
    """The data files ``--format mat|parquet`` asks for (from ``columns``, else from data.csv), with
    the run's verb, exit status, sashil version and ``meta`` (controller, current, ...) beside the rows."""
    about = {"verb": verb, "exit_status": exit_status, "sashil_version": __version__, **meta}
    return write_data_formats(folder, formats(args), columns, config, about)


def finish_loop_run(
    args: argparse.Namespace,
    folder: RunFolder,
    config: Mapping[str, Any],
    summary: dict[str, Any],
    trace_stats: dict[str, Any] | None,
    **extra: Any,
) -> None:
    """After a loop run (``sashil run``): the ``--format`` files, ``run.png``, ``timing.png`` (loop
    timing percentiles), and the summary again with ``extra`` keys (the road) and the trace's counts."""
    from sashil.api import load_run
    from sashil.recording.plots import plot_run, plot_timing

    if (folder.path / "data.csv").exists():
        write_formats(
            args,
            folder.path,
            config,
            summary.get("verb", "run"),
            exit_status=summary.get("exit_status", "ok"),
            controller=summary.get("controller"),
        )
        plot_run(folder.path / "run.png", folder.path, {**summary, **extra})
    timing = load_run(folder.path).timing
    if timing is not None and len(timing.get("lateness_ns", ())):
        plot_timing(folder.path / "timing.png", [(str(summary.get("controller") or "run"), timing)])
    if trace_stats is not None:
        extra["can_trace"] = trace_stats
    if extra:  # what the verb knows beside the session's summary (the road, the trace's counts)
        summary.update(extra)
        folder.write_summary(summary)
