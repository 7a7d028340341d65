"""The package's functions over a length, longest first: a function that long does several things,
and each deserves a name of its own.

A function's length is its lines from the ``def`` (decorators left out) to its last line, docstring
and comments included, as Python's own parser gives them; methods and nested functions count on
their own (a nested function's lines count in its parent's too). The package is ``src/sashil`` and
``drivers/`` (``sashil.drivers``); tests and tools are not counted.

    python tools/long_functions.py                # every function over 80 lines, and how many
    python tools/long_functions.py --lines 60     # another length
    python tools/long_functions.py --check        # exit 1 when more than CEILING are over 80 lines
    python tools/long_functions.py --quick        # --check, printing the count alone (CI)

:data:`CEILING` is the most functions over :data:`LINES` lines the package may hold
(``tests/test_long_functions.py`` holds it there): lower it when a long function is split, never
raise it to let one in.
"""

from __future__ import annotations

import argparse
import ast
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: the folders of the package's source (sashil.drivers lives in drivers/, linked into src/sashil)
SOURCES = (ROOT / "src" / "sashil", ROOT / "drivers")
#: a function longer than this many lines is long
LINES = 80
#: the most long functions the package may hold
CEILING = 5


@dataclass(frozen=True)
class Function:
    path: str  # relative to the repository
    name: str  # qualified within its module: Class.method, outer.inner
    line: int
    lines: int


def _files() -> list[Path]:
    """The package's Python files, each once (``src/sashil/drivers`` is the link to ``drivers/``)."""
    link = ROOT / "src" / "sashil" / "drivers"
    return [path for folder in SOURCES for path in sorted(folder.rglob("*.py")) if link not in path.parents]


def functions(path: Path) -> list[Function]:
    """Every function and method of the file at ``path``, with its length."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    shown = str(path.relative_to(ROOT)) if ROOT in path.parents else str(path)
    found: list[Function] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = f"{prefix}{child.name}"
                end = child.end_lineno or child.lineno
                found.append(Function(shown, name, child.lineno, end - child.lineno + 1))
                visit(child, f"{name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(tree, "")
    return found


def long_functions(lines: int = LINES) -> list[Function]:
    """The package's functions over ``lines`` lines, longest first."""
    every = [function for path in _files() for function in functions(path)]
    return sorted((f for f in every if f.lines > lines), key=lambda f: (-f.lines, f.path, f.line))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lines", type=int, default=LINES, help=f"the length that is long (default {LINES})")
    parser.add_argument("--check", action="store_true", help=f"exit 1 when more than {CEILING} are long")
    parser.add_argument("--quick", action="store_true", help="--check, printing the count alone")
    args = parser.parse_args(argv)
    found = long_functions(args.lines)
    if not args.quick:
        for function in found:
            print(f"{function.lines:5d}  {function.path}:{function.line}  {function.name}")
    print(f"{len(found)} functions over {args.lines} lines (ceiling {CEILING} over {LINES})")
    if (args.check or args.quick) and args.lines == LINES and len(found) > CEILING:
        print(f"more than {CEILING}: split the new one into named helpers", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
