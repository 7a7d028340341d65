"""The package's layers: the contract sees ``sashil.drivers`` through its link, and the picture in
``docs/architecture.md`` is the one ``tools/layers.py`` draws from the code."""

from __future__ import annotations

from pathlib import Path

import grimp
from tool_module import load_tool

ROOT = Path(__file__).resolve().parents[1]


def test_the_import_graph_follows_the_link_to_drivers():
    graph = grimp.build_graph("sashil", cache_dir=None)
    assert {"sashil.drivers.interface", "sashil.drivers.sim", "sashil.drivers.emulator.device"} <= graph.modules
    assert "sashil.runtime.loop" in graph.find_modules_that_directly_import("sashil.drivers.interface")


def test_every_package_stands_in_a_layer():
    tool = load_tool("layers", "layers_tool")
    layers = tool.contract()
    named = {name.strip() for layer in layers["layers"] for name in layer.replace(":", "|").split("|")}
    packages = {
        f"sashil.{path.name}" for path in (ROOT / "src" / "sashil").iterdir() if (path / "__init__.py").exists()
    }
    modules = {f"sashil.{path.stem}" for path in (ROOT / "src" / "sashil").glob("*.py") if path.stem != "__init__"}
    assert packages | modules == named


def test_the_picture_in_the_architecture_page_is_the_codes():
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    shown = text.split("<!-- tools/layers.py -->\n```text\n", 1)[1].split("```", 1)[0]
    assert shown == load_tool("layers", "layers_tool").picture(), (
        "docs/architecture.md: run python tools/layers.py and paste its picture"
    )
    assert "NOT ALLOWED" not in shown
