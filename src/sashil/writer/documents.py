"""The documents a verb's runs emit, handed to its subscribers in order: the engine emits each run's
start and stop (:func:`sashil.engine.run`), a verb its folder's start and end.

A subscriber is a callable ``(kind, document)``: the run folder's writer
(:class:`~sashil.writer.folder_writer.FolderWriter`) among them. The kinds and their keys are the
writer's module's: ``start`` (the resolved config, the assembled run, the versions), ``progress``
and ``stop`` (the outcome, to which the experiment adds its analysis; ``run`` None: the verb's end).
"""

from __future__ import annotations

import platform
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from sashil._version import __version__

if TYPE_CHECKING:
    from sashil.config.parts import RunSpec

__all__ = ["Documents", "Subscriber", "versions"]

#: a reader of a verb's documents: ``(kind, document)``
Subscriber = Callable[[str, Mapping[str, Any]], None]


def versions() -> dict[str, str]:
    """The software a run ran on, for its start document."""
    return {"sashil": __version__, "python": platform.python_version()}


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

    def stop(self, run: str, outcome: Mapping[str, Any], error: BaseException | None, **analysis: Any) -> None:
        """Run ``run`` ended: the loop's summary keys (``outcome``), what ended it, and the
        experiment's ``analysis`` (``entry``, ``data``, ``formats``)."""
        self.emit("stop", {"run": run, "outcome": outcome, "error": error, **analysis})

    def summary(self, run: str | None, summary: Mapping[str, Any]) -> None:
        """Run ``run`` (None: the verb) ended with the summary the verb composed itself."""
        self.emit("stop", {"run": run, "summary": summary})

    def end(self, **extra: Any) -> None:
        """The verb ended: its own summary keys."""
        self.emit("stop", {"run": None, "extra": extra})
