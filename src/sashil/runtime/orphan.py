"""A loop whose session died ends the run alone: every row on disk, and a summary that says so.

The loop process has already stopped at 0 A with the road at rest (its shutdown path). The
session's recorder wrote rows up to the stream's ``recorded`` word; the rest, down to the safe
state's row, is appended to ``data.csv`` here in the same format, and ``timing.npz`` and
``summary.json`` are written (``exit_status: error``, ``stop_reason``: the session died). The
stream file stays, marked ``died``, until the next run's :func:`~sashil.runtime.stream.remove_stale`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sashil.errors import SashilError
from sashil.recording.run_folder import RunFolder
from sashil.recording.summary_writer import write_summary
from sashil.runtime.runner import end_summary
from sashil.runtime.stream import RECORDED_W, Stream
from sashil.runtime.stream_recorder import append, format_block

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec


def finish_alone(
    stream: Stream,
    writer: Any,
    data: Path,
    spec: RunSpec,
    end: dict[str, Any],
    timing: Any,
    verb: str = "run",
) -> None:
    """Append the unrecorded rows to ``data`` (the run's data.csv, or a drop's cycles file) and
    write the documents of its folder for ``verb`` (module doc)."""
    start, stop = int(stream.header[RECORDED_W]), writer.rows_committed
    folder = data.parent
    fd = os.open(data, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    try:
        if os.fstat(fd).st_size == 0:
            append(fd, ",".join(stream.columns) + "\n")
        append(fd, format_block(stream.columns, stream.block(start, stop)))
        os.fsync(fd)
    finally:
        os.close(fd)
    stream.header[RECORDED_W] = stop
    stream.set_state("died")
    run = RunFolder(folder, verb)
    run.write_timing(timing)
    error = SashilError(f"{end['stop_reason']}: the loop stopped at 0 A and wrote the rest of the data itself")
    write_summary(
        run,
        {
            "verb": verb,
            **end_summary(
                end,
                exit_status="error",
                timing=timing.summary(),
                error=error,
                realtime=end["realtime"],
                recording={"rows_written": stop, "rows_dropped": 0, "written_by": "the loop process"},
            ),
            "controller": spec.stage.law,
            "driver": spec.rig.backend,
            "tuning": end["tuning"],
            "loop_process": {"pid": os.getpid(), "threads": end["threads"], "session_died": True},
        },
    )
