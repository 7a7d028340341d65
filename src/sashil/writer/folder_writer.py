"""The run folder's writer: a subscriber to a verb's documents that writes what ran and how it ended.

The engine hands every subscriber the same documents, in order (:mod:`sashil.writer.documents`):

* ``start``: a run begins. ``{"run": name or None, "config": the resolved config or None, "spec":
  the assembled run (a :class:`~sashil.config.parts.RunSpec`), "versions": the software's}``. ``run`` None is the folder
  itself; a name is one run of several (its sub-folder). The writer writes ``config.yaml`` from
  ``config`` (none when it is None: a run whose folder records no config of its own).
* ``progress``: what a run is doing (``{"run": name, "text": ...}``): for views; the writer keeps
  nothing of it.
* ``stop``: a run ended. ``{"run": name, "record": its RunRecord}``
  (:class:`~sashil.writer.documents.RunRecord`: the loop's summary keys, what ended the run or
  None, and the experiment's analysis: ``entry``, the run's row of the folder's summary; ``data``,
  the columns of its ``data.csv``; ``formats``, the keys its ``--format`` files are labelled with).
  The writer writes the data files and, for one run of several, its ``summary.json``.
* ``stop`` with ``run`` None: the verb ended (``{"run": None, "extra": the verb's own keys}``): the
  folder's ``summary.json``, with every run's entry, how the set ended (the first failing run
  ends it; what ran before it is kept) and a single run's loop keys at the top.
* ``stop`` with ``summary``: a run (``run`` a name) or the verb (``run`` None) whose summary the
  verb has composed itself (a session's, a comparison's, a simulation's): its ``summary.json`` is
  those keys after the common ones.

:func:`ending` is the one error rule of every summary (the status, the one line and the exit code
of what ended a run). ``config.yaml`` and ``summary.json`` are written here, each from one place
(:meth:`FolderWriter._write_config`, :meth:`FolderWriter._write_summary`), through
:mod:`sashil.writer.summary_writer` and its one schema.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sashil.errors import exit_code_of, status_of
from sashil.recording.outputs import Outputs
from sashil.writer.documents import RunRecord
from sashil.writer.run_folder import RunFolder
from sashil.writer.summary_writer import write_config, write_summary

__all__ = ["RUN_LEVEL_KEYS", "FolderWriter", "ending"]

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


class FolderWriter:
    """The writer of ``folder``, the run folder of one ``verb``: each run in a sub-folder of
    ``sub_root`` (default the folder itself) when there are ``several``, else the folder is the run.
    ``common``: the keys every summary of the folder carries (driver, controller, ...). ``outputs``:
    the ``--format`` files written beside each run's ``data.csv`` (None: none)."""

    def __init__(
        self,
        folder: RunFolder,
        verb: str,
        common: Mapping[str, Any],
        *,
        several: bool = True,
        sub_root: Path | None = None,
        outputs: Outputs | None = None,
    ):
        self.folder, self.verb, self.common, self.several = folder, verb, dict(common), several
        self.sub_root = sub_root if sub_root is not None else folder.path
        self.outputs = outputs
        self.entries: list[dict[str, Any]] = []
        self.error: BaseException | None = None
        self.summary: dict[str, Any] | None = None
        self._subs: dict[str, RunFolder] = {}

    def __call__(self, kind: str, fields: Mapping[str, Any]) -> None:
        """Take one document of the verb, its ``kind`` and ``fields`` (see the module docstring)."""
        name = fields.get("run")
        if kind == "start":
            if fields.get("config") is not None:
                self._write_config(self.folder_for(name), fields["config"], fields.get("note"))
        elif kind == "stop" and "summary" in fields:
            self._write_summary(self.folder_for(name), {**self.common, **fields["summary"]})
        elif kind == "stop" and name is None:
            self._close(fields.get("extra", {}))
        elif kind == "stop":
            self._run_ended(str(name), fields["record"])

    def folder_for(self, name: str | None) -> RunFolder:
        """Where run ``name`` writes: its sub-folder (created), or the folder itself for a single
        run (or ``name`` None)."""
        if not self.several or name is None:
            return self.folder
        if name not in self._subs:
            self._subs[name] = RunFolder.create(self.sub_root / name, self.verb)
        return self._subs[name]

    @property
    def failed(self) -> bool:
        return self.error is not None

    def _folder_key(self, name: str) -> str:
        if not self.several:
            return "."
        return str((self.sub_root / name).relative_to(self.folder.path))

    def _run_ended(self, name: str, record: RunRecord) -> None:
        """One run's files: its data and --format files, its entry in the folder's summary and, as
        one of several, its own summary (its entry's values of the common keys win: its controller).
        The first failing run is the folder's error."""
        target, error, data = self.folder_for(name), record.error, record.data
        if data is not None:
            target.write_data(data)
            if self.outputs is not None:
                status = ending(error)["exit_status"]
                self.outputs.write_formats(target.path, self.verb, data, exit_status=status, **record.formats)
        row = {
            "folder": self._folder_key(name),
            **record.entry,
            **{k: v for k, v in ending(error).items() if k != "exit_code"},
        }
        self.entries.append(row)
        if self.several:
            common = {key: row.get(key, value) for key, value in self.common.items()}
            run_level = {key: row.get(key) for key in RUN_LEVEL_KEYS}
            runs = [{**row, "folder": "."}]
            self._write_summary(target, {**common, "verb": self.verb, **ending(error), **run_level, "runs": runs})
        if error is not None and self.error is None:
            self.error = error

    def _close(self, extra: Mapping[str, Any]) -> None:
        """The folder's summary.json: the common keys, how the set ended (its first failure), the
        run-level keys of a single run at the top, every run's entry, and the verb's ``extra``."""
        single = self.entries[0] if len(self.entries) == 1 else {}
        summary = {
            **self.common,
            "verb": self.verb,
            **ending(self.error),
            **{key: single.get(key) for key in RUN_LEVEL_KEYS},
            "runs": self.entries,
            **extra,
        }
        self._write_summary(self.folder, summary)
        self.summary = summary

    @staticmethod
    def _write_config(folder: RunFolder, config: Mapping[str, Any], note: str | None) -> None:
        write_config(folder, config, note)

    @staticmethod
    def _write_summary(folder: RunFolder, summary: Mapping[str, Any]) -> None:
        write_summary(folder, summary)
