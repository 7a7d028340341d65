"""Verbs made of several runs (a drop test's currents, a stepped sweep's frequencies, the
calibration plan's steps): one folder, a sub-folder per run, one error rule, one summary.

:func:`ending` is the one error rule of every summary (the status, the one line and the exit code
of what ended a run), :class:`RunSet` the one engine of a verb of several runs: it makes the
sub-folders, writes each run's ``summary.json`` and the folder's, and stops the set at the first
run that fails (what ran before it is kept). Every ``summary.json`` goes through
:func:`~sashil.recording.summary_writer.write_summary` and its one schema
(:mod:`sashil.recording.summary_schema`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sashil.errors import exit_code_of, status_of
from sashil.recording.run_folder import RunFolder
from sashil.recording.summary_writer import write_summary

__all__ = ["RUN_LEVEL_KEYS", "RunSet", "ending"]

#: what a loop run reports about itself: at the top of summary.json when the folder holds one run
RUN_LEVEL_KEYS = ("timing", "link", "realtime", "can_trace")


def ending(error: BaseException | None) -> dict[str, Any]:
    """The summary keys of how a run ended: ``exit_status``, ``error`` (one line) and ``exit_code``."""
    if error is None:
        return {"exit_status": "ok", "error": None, "exit_code": 0}
    status = status_of(error)
    return {
        "exit_status": status,
        "error": str(error) or type(error).__name__,
        "exit_code": exit_code_of(status, error),
    }


class RunSet:
    """The runs of one verb in ``folder``: each in a sub-folder of ``sub_root`` (default the folder
    itself) when there are ``several``, else the folder is the run. ``common``: the keys every
    summary of the set carries (verb, driver, controller, ...)."""

    def __init__(
        self,
        folder: RunFolder,
        verb: str,
        common: Mapping[str, Any],
        several: bool = True,
        sub_root: Path | None = None,
    ):
        self.folder, self.verb, self.common, self.several = folder, verb, dict(common), several
        self.sub_root = sub_root if sub_root is not None else folder.path
        self.entries: list[dict[str, Any]] = []
        self.error: BaseException | None = None
        self._subs: dict[str, RunFolder] = {}

    def folder_for(self, name: str) -> RunFolder:
        """Where run ``name`` writes: its sub-folder (created), or the folder itself for a single run."""
        if not self.several:
            return self.folder
        if name not in self._subs:
            self._subs[name] = RunFolder.create(self.sub_root / name, self.verb)
        return self._subs[name]

    def _folder_key(self, name: str) -> str:
        if not self.several:
            return "."
        return str((self.sub_root / name).relative_to(self.folder.path))

    @property
    def failed(self) -> bool:
        return self.error is not None

    def add(self, name: str, entry: Mapping[str, Any], error: BaseException | None = None) -> dict[str, Any]:
        """Record run ``name`` (its metrics in ``entry``) and how it ended; writes its own summary
        when it has a sub-folder. The first failing run is the set's error."""
        row = {
            "folder": self._folder_key(name),
            **entry,
            **{k: v for k, v in ending(error).items() if k != "exit_code"},
        }
        self.entries.append(row)
        if self.several:  # the run's own summary: its entry's values of the common keys win (its controller)
            common = {key: row.get(key, value) for key, value in self.common.items()}
            run_level = {key: row.get(key) for key in RUN_LEVEL_KEYS}
            write_summary(
                self.folder_for(name),
                {**common, "verb": self.verb, **ending(error), **run_level, "runs": [{**row, "folder": "."}]},
            )
        if error is not None and self.error is None:
            self.error = error
        return row

    def finish(self, **extra: Any) -> dict[str, Any]:
        """Write the folder's summary.json: the common keys, how the set ended (its first failure),
        the run-level keys of a single run at the top, every run's entry, and ``extra``."""
        single = self.entries[0] if len(self.entries) == 1 else {}
        summary = {
            **self.common,
            "verb": self.verb,
            **ending(self.error),
            **{key: single.get(key) for key in RUN_LEVEL_KEYS},
            "runs": self.entries,
            **extra,
        }
        write_summary(self.folder, summary)
        return summary
