"""The documents a verb's runs emit, handed to its subscribers in order: the engine emits each run's
start and stop (:func:`sashil.engine.run`), a verb its folder's start and end.

A subscriber is a callable ``(kind, document)``: the run folder's writer
(:class:`~sashil.writer.folder_writer.FolderWriter`) among them. The kinds and their keys are the
writer's module's: ``start`` (the resolved config, the assembled run, the versions), ``progress``
and ``stop`` (the run's :class:`RunRecord`: how its loop ended and the experiment's analysis of it;
``run`` None: the verb's end).
"""

from __future__ import annotations

import platform
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sashil._version import __version__

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

__all__ = ["Documents", "RunRecord", "Subscriber", "versions"]

#: a reader of a verb's documents: ``(kind, document)``
Subscriber = Callable[[str, Mapping[str, Any]], None]


def versions() -> dict[str, str]:
    """The software a run ran on, for its start document."""
    return {"sashil": __version__, "python": platform.python_version()}


@dataclass(kw_only=True)
class RunRecord:
    """What one run leaves, as its ``stop`` document carries it to every subscriber: how its loop
    ended (``summary``: the loop's summary.json keys; {} when the verb ran no loop of the engine's),
    what ended the run as the experiment judges it (``error``; None: it ended normally), and the
    experiment's analysis: ``entry`` (the run's row of the folder's summary), ``data`` (the columns
    of its ``data.csv``; None: none) and ``formats`` (the keys its ``--format`` files are labelled
    with). An experiment's own record (a drop's) is a ``RunRecord`` with its figures beside these,
    so the record the verb reads is the document the writer reads."""

    summary: dict[str, Any] = field(default_factory=dict)
    error: BaseException | None = None
    entry: dict[str, Any] = field(default_factory=dict)
    data: Mapping[str, Any] | None = None
    formats: dict[str, Any] = field(default_factory=dict)


class Documents:
    """One verb's stream of documents to ``subscribers``, each handed every document in order."""

    def __init__(self, subscribers: Sequence[Subscriber] = ()):
        self.subscribers = tuple(subscribers)

    def emit(self, kind: str, fields: Mapping[str, Any]) -> None:
        """Hand every subscriber the document of ``kind`` with ``fields``."""
        for subscriber in self.subscribers:
            subscriber(kind, fields)

    def start(
        self, run: str | None, config: Mapping[str, Any] | None, spec: RunSpec | None = None, note: str | None = None
    ) -> None:
        """A run begins (``run`` None: the verb's folder itself): its resolved ``config`` (None: none
        recorded for it; ``note``: what its config.yaml says of it first), its assembled ``spec``
        (read-only; ``spec.to_json()`` its plain values) and the versions."""
        fields = {"run": run, "config": config, "note": note, "spec": spec, "versions": versions()}
        self.emit("start", fields)

    def progress(self, run: str | None, text: str) -> None:
        self.emit("progress", {"run": run, "text": text})

    def stop(self, run: str, record: RunRecord) -> None:
        """Run ``run`` ended, as its ``record`` tells it."""
        self.emit("stop", {"run": run, "record": record})

    def summary(self, run: str | None, summary: Mapping[str, Any]) -> None:
        """Run ``run`` (None: the verb) ended with the summary the verb composed itself."""
        self.emit("stop", {"run": run, "summary": summary})

    def end(self, **extra: Any) -> None:
        """The verb ended: its own summary keys."""
        self.emit("stop", {"run": None, "extra": extra})
