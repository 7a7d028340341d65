"""The laws a page may choose: the registry ``sashil laws`` reads, plus a laws folder named at launch.

A page names a law by its name only; the server maps the name to the class spec it found here. So
a page never hands the server a path to Python code: file laws come only from the folder given
on the command line (``sashil panel --laws DIR``), each ``DIR/*.py`` searched for
:class:`~sashil.control.law_api.Law` subclasses, each described as ``sashil laws`` describes it.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sashil.errors import ConfigError


@dataclass(frozen=True)
class LawChoice:
    """A law a page may pick: its name, the spec ``controller.law`` takes, and its description."""

    name: str
    spec: str
    about: dict[str, Any]


def _law_classes(path: Path) -> list[str]:
    """The top-level class names of ``path`` that derive from a name ending ``Law`` (read without
    importing the file; the registry imports and checks each one named)."""
    try:
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    except (OSError, SyntaxError, UnicodeDecodeError) as err:
        raise ConfigError(f"--laws {path}: cannot read the file ({err})") from None
    names = []
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            bases = [ast.unparse(base) for base in node.bases]
            if any(base == "Law" or base.endswith(".Law") for base in bases):
                names.append(node.name)
    return names


def laws_catalog(laws_dir: str | Path | None = None) -> list[LawChoice]:
    """Every law the registry knows (built-in and installed), then those of ``laws_dir``; a file
    law whose name a registered law already has is refused by the registry (one line), unless it
    is that law's own file (an installed package's folder), which is offered once."""
    from sashil.control.law_registry import describe, find_law, known_laws

    entries = known_laws()
    if laws_dir is not None:
        folder = Path(laws_dir)
        if not folder.is_dir():
            raise ConfigError(f"--laws {folder}: not a folder")
        for path in sorted(folder.glob("*.py")):
            entries += [find_law(f"{path.resolve()}:{name}") for name in _law_classes(path)]
    choices: dict[str, LawChoice] = {}
    for entry in entries:
        if entry.cls.name in choices:  # the installed package's own file (find_law refuses another class)
            continue
        about = describe(entry)
        params = entry.cls.params()
        for described in about["parameters"]:  # the page draws a slider for a float
            described["kind"] = params[described["name"]].field.kind
        choices[about["name"]] = LawChoice(about["name"], entry.spec, about)
    return list(choices.values())
