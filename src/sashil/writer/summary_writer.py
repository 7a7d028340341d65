"""The one writer of a run folder's record of what ran and how it ended: ``config.yaml`` when the
run starts (the resolved config, exactly what ran) and ``summary.json`` when it stops (the one
schema of :mod:`sashil.recording.summary_schema`, with the run's start and end and its provenance).

A verb, the session, the compare and the sets of runs hand it their documents, the config at the
start and the summary's keys at the stop; no other module writes either file. The summary is
written once per folder: a second stop is a bug (RuntimeError).
"""

from __future__ import annotations

import json
import platform
import socket
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sashil._version import __version__
from sashil.config import dump_config
from sashil.recording.summary_schema import normalise
from sashil.writer.run_folder import RunFolder, utc_now

__all__ = ["SUMMARY_FILE", "provenance", "write_config", "write_summary"]

#: the run's summary, in every run folder
SUMMARY_FILE = "summary.json"


def write_config(folder: RunFolder, config: Mapping[str, Any], note: str | None = None) -> Path:
    """The run's start: ``config.yaml``, the resolved config, after ``note`` as YAML comment lines
    when given."""
    head = "".join(f"# {line}\n" for line in note.splitlines()) if note else ""
    return folder.write_text("config.yaml", head + dump_config(config))


def write_summary(folder: RunFolder, summary: Mapping[str, Any]) -> Path:
    """The run's stop: ``summary.json``, ``summary`` in the one schema with the folder's start, the
    end (now) and the provenance; once per folder (a second write is a bug: RuntimeError)."""
    if folder.summary_written:
        raise RuntimeError(f"{folder.path}: summary.json is written once, at the end of the run")
    folder.summary_written = True
    doc = {
        **normalise(summary, folder.verb),
        "started_utc": folder.started_utc.isoformat(),
        "ended_utc": utc_now().isoformat(),
        "provenance": provenance(),
    }
    return folder.write_text(SUMMARY_FILE, json.dumps(doc, indent=2, allow_nan=False) + "\n")


def git_revision() -> str | None:
    """The git revision sashil runs from, when it runs from a checkout."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=2,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


def provenance() -> dict[str, Any]:
    """What describes the software and machine a run came from."""
    return {
        "sashil_version": __version__,
        "git_revision": git_revision(),
        "host": socket.gethostname(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "command_line": sys.argv[:],
    }
