"""The package holds no more long functions than ``tools/long_functions.py`` allows (its CEILING)."""

from __future__ import annotations

from pathlib import Path

from tool_module import load_tool

ROOT = Path(__file__).resolve().parents[1]


def test_no_more_long_functions_than_the_ceiling():
    tool = load_tool("long_functions")
    found = tool.long_functions()
    listing = "\n".join(f"{f.lines} {f.path}:{f.line} {f.name}" for f in found)
    assert len(found) <= tool.CEILING, f"more than {tool.CEILING} functions over {tool.LINES} lines:\n{listing}"


def test_the_count_sees_drivers_once_and_measures_a_function_whole(tmp_path):
    tool = load_tool("long_functions")
    files = tool._files()
    assert any(path.parent.name == "drivers" for path in files)
    assert len({path.resolve() for path in files}) == len(files)
    source = tmp_path / "sample.py"
    source.write_text(
        "class A:\n    @staticmethod\n    def f():\n        def g():\n            pass\n\n        return 1\n"
    )
    found = {f.name: f.lines for f in tool.functions(source)}
    assert found == {"A.f": 5, "A.f.g": 2}  # from the def (its decorator left out) to its last line
