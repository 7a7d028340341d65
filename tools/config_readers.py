"""Count the files that read a config's keys outside the config layer.

A file counts when it has either of these:

* a subscript, ``.get`` or ``read_key`` on a name like ``config``, ``cfg``, ``conf``,
  ``*_config``, ``config_*``, ``doc`` or ``document``;
* a section's name (a key of the schema's ``SCHEMA`` table in ``src/sashil/config/sections.py``)
  used as a key on ``values``, ``section``, ``controller``, ``model``, ``rig`` or ``options``.

Only reads count: a config's keys are strings, so an integer index (``doc[0]``, a docstring's
first paragraph) reads a sequence, not a config, and a subscript stored to or deleted
(``doc["intervals_95"] = ...``, a document being written, with the subscripts it is written
through: ``doc["calibration"]["intervals"] = ...``) reads nothing.

The count runs over ``src/sashil`` and ``drivers/``, leaving out ``src/sashil/config/``. Files in
the loop's own layers (runtime/, control/, safety.py and the backends) are listed apart, since
none of them may read a config's keys.

Usage: ``python tools/config_readers.py [--list] [--check] [--quick]``. With ``--check`` it exits 1
when a loop-side file reads keys; ``--quick`` is the same count (it takes well under a second).
"""

from __future__ import annotations

import argparse
import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG_NAME = re.compile(r"^(config|cfg|conf|doc|document|\w+_config|config_\w+)$")
SECTION_HOLDERS = {"values", "section", "controller", "model", "rig", "options"}
LOOP_SIDE = ("src/sashil/runtime/", "src/sashil/control/", "src/sashil/safety.py", "drivers/")


def section_names() -> set[str]:
    """The config's section names: the string keys of the ``SCHEMA`` table in the config layer's
    ``sections.py`` (read from its source, so the count imports nothing of sashil)."""
    tree = ast.parse((ROOT / "src" / "sashil" / "config" / "sections.py").read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "SCHEMA" for t in node.targets):
            if isinstance(node.value, ast.Dict):
                return {k.value for k in node.value.keys if isinstance(k, ast.Constant) and isinstance(k.value, str)}
    raise SystemExit("config_readers: no SCHEMA table in src/sashil/config/sections.py")


def _written(tree: ast.AST) -> set[int]:
    """The subscripts of ``tree`` stored to or deleted, and those they are written through (the
    ``doc["a"]`` of ``doc["a"]["b"] = value``), by ``id``."""
    written: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and not isinstance(node.ctx, ast.Load):
            inner: ast.expr = node
            while isinstance(inner, ast.Subscript):
                written.add(id(inner))
                inner = inner.value
    return written


def _reads_no_key(node: ast.AST, written: set[int]) -> bool:
    """Whether ``node`` is a subscript that reads no key: by an integer constant (a sequence's
    item) or written (:func:`_written`)."""
    if not isinstance(node, ast.Subscript):
        return False
    by_index = isinstance(node.slice, ast.Constant) and type(node.slice.value) is int
    return by_index or id(node) in written


def _name_of(node: ast.expr) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return None


def _first_key(call_or_subscript: ast.AST) -> str | None:
    if isinstance(call_or_subscript, ast.Subscript):
        key = call_or_subscript.slice
    elif isinstance(call_or_subscript, ast.Call) and call_or_subscript.args:
        key = call_or_subscript.args[0]
    else:
        return None
    return key.value if isinstance(key, ast.Constant) and isinstance(key.value, str) else None


def reasons(tree: ast.AST, sections: set[str]) -> list[str]:
    """Each place in ``tree`` that reads a config's keys, as ``line: what``."""
    found: list[str] = []
    written = _written(tree)
    for node in ast.walk(tree):
        if not isinstance(node, (ast.Subscript, ast.Call)):
            continue
        holder: str | None = None
        if isinstance(node, ast.Subscript):
            holder = _name_of(node.value)
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            if node.func.attr == "get":
                holder = _name_of(node.func.value)
        elif isinstance(node, ast.Call) and _name_of(node.func) == "read_key" and node.args:
            holder = _name_of(node.args[0])
            if holder is not None and CONFIG_NAME.match(holder):
                found.append(f"{node.lineno}: read_key({holder}, …)")
            continue
        if holder is None or _reads_no_key(node, written):
            continue
        if CONFIG_NAME.match(holder):
            found.append(f"{node.lineno}: {holder}[…]")
        elif holder in SECTION_HOLDERS and _first_key(node) in sections:
            found.append(f"{node.lineno}: {holder}[{_first_key(node)!r}]")
    return found


def readers() -> dict[str, list[str]]:
    """Every counted file, relative to the checkout, with its reading places."""
    sections = section_names()
    files = sorted((ROOT / "src" / "sashil").rglob("*.py")) + sorted((ROOT / "drivers").rglob("*.py"))
    counted: dict[str, list[str]] = {}
    for path in files:
        relative = path.relative_to(ROOT).as_posix()
        if relative.startswith("src/sashil/config/"):
            continue
        places = reasons(ast.parse(path.read_text(encoding="utf-8")), sections)
        if places:
            counted[relative] = places
    return counted


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="print each reading place")
    parser.add_argument("--check", action="store_true", help="exit 1 when a loop-side file reads keys")
    parser.add_argument("--quick", action="store_true", help="the same count (kept for the tools' quick test)")
    args = parser.parse_args(argv)
    counted = readers()
    loop_side = [name for name in counted if name.startswith(LOOP_SIDE)]
    for name, places in counted.items():
        mark = "  (loop side)" if name in loop_side else ""
        print(f"{name}: {len(places)}{mark}")
        if args.list:
            for place in places:
                print(f"    {place}")
    print(f"files that read a config's keys: {len(counted)} (target <= 12)")
    print(f"of them on the loop side: {len(loop_side)} (target 0)")
    return 1 if args.check and loop_side else 0


if __name__ == "__main__":
    sys.exit(main())
