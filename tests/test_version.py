"""One version: ``sashil/_version.py``'s, which pyproject.toml reads at build time, the package
metadata carries, and ``sashil`` and ``sashil --version`` report."""

from __future__ import annotations

import re
from importlib.metadata import version
from pathlib import Path

import pytest

import sashil
from sashil.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_the_version_is_pyprojects(capsys):
    assert 'dynamic = ["version"]' in (ROOT / "pyproject.toml").read_text()
    declared = re.search(r'^__version__ = "([^"]+)"', (ROOT / "src/sashil/_version.py").read_text(), re.M).group(1)
    assert sashil.__version__ == version("sashil") == declared
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"sashil {declared}"


def test_the_version_is_written_nowhere_else():
    declared = sashil.__version__
    for path in [*ROOT.glob("src/**/*.py"), *ROOT.glob("drivers/**/*.py")]:
        if path.name == "_version.py":
            continue
        assert f'"{declared}"' not in path.read_text(), path


def test_the_package_ships_its_type_hints():
    assert (Path(sashil.__file__).parent / "py.typed").is_file()
