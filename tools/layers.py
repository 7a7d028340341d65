"""The package's layers as the code has them: the layers contract of ``pyproject.toml`` (the one
``lint-imports`` checks) drawn with the imports the code makes between its packages, read by the
same graph (grimp, which follows ``src/sashil/drivers`` to ``drivers/``).

    python tools/layers.py            # the picture, as docs/architecture.md shows it
    python tools/layers.py --quick    # the same (it takes a second)

Each package is a line, its layers top to bottom, with each package it imports from and how many
of its modules' imports go there (``↑`` marks an import upwards: each is one the contract's
``ignore_imports`` names, listed at the end). ``tests/test_layers.py`` keeps the picture in ``docs/architecture.md`` equal to
this output.
"""

from __future__ import annotations

import argparse
import os
import sys
import textwrap
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def contract() -> dict:
    """The layers contract's options, as import-linter reads them from ``pyproject.toml``."""
    from importlinter.api import read_configuration

    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        options = read_configuration()["contracts_options"]
    finally:
        os.chdir(cwd)
    (layers,) = [c for c in options if c.get("type") == "layers"]
    return layers


def package_of(module: str, packages: list[str]) -> str | None:
    """The contract's package (or module) that ``module`` is, or lies in."""
    for package in packages:
        if module == package or module.startswith(package + "."):
            return package
    return None


def picture() -> str:
    """The layers, top to bottom, each with the packages its modules import from and how often."""
    import grimp

    layers = contract()
    rows = [[name.strip() for name in layer.replace(":", "|").split("|")] for layer in layers["layers"]]
    packages = [name for row in rows for name in row]
    level = {name: index for index, row in enumerate(rows) for name in row}
    allowed = {tuple(part.strip() for part in line.split("->")) for line in layers.get("ignore_imports", [])}
    graph = grimp.build_graph("sashil", cache_dir=None)
    counts: Counter[tuple[str, str]] = Counter()
    upward: list[tuple[str, str]] = []
    for importer in sorted(graph.modules):
        source = package_of(importer, packages)
        for imported in sorted(graph.find_modules_directly_imported_by(importer)):
            target = package_of(imported, packages)
            if source is None or target is None or source == target:
                continue
            counts[(source, target)] += 1
            if level[target] <= level[source]:
                upward.append((importer, imported))
    short = {name: name.removeprefix("sashil.") for name in packages}
    width = max(len(name) for name in short.values()) + 2
    lines = []
    for row in rows:
        if len(row) > 1:
            lines.append(" | ".join(short[name] for name in row) + "   (independent: none imports another)")
        for name in row:
            targets = sorted((t for s, t in counts if s == name), key=lambda t: (level[t], t))
            arrows = " · ".join(
                f"{'↑' if level[target] <= level[name] else ''}{short[target]}\u00a0{counts[(name, target)]}"
                for target in targets
            )
            head = f"{'  ' if len(row) > 1 else ''}{short[name]}"
            text = f"{head:<{width}} ↓ {arrows}" if arrows else head
            wrapped = textwrap.wrap(text, 100, subsequent_indent=" " * (width + 3), break_on_hyphens=False)
            lines += [line.replace("\u00a0", " ") for line in wrapped] or [head]
    if upward:
        lines.append("")
        lines.append("upward imports (each one the contract's ignore_imports names):")
        for importer, imported in upward:
            named = (importer, imported) in allowed
            lines.append(f"    {importer} -> {imported}{'' if named else '  (NOT ALLOWED)'}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="the same picture (it is quick)")
    parser.parse_args(argv)
    sys.stdout.write(picture())
    return 0


if __name__ == "__main__":
    sys.exit(main())
