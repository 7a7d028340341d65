"""The README quick start is exactly two commands, and CI runs the second one."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _quick_start_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    section = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```[a-z]*\n(.*?)```", section, flags=re.S)
    assert len(blocks) == 1, "one fenced block under ## Quick start"
    return [line for line in blocks[0].splitlines() if line.strip()]


def test_quick_start_has_two_commands_setup_and_drop_test_then_tests():
    first, second = _quick_start_commands()
    assert "pip install" in first and "sashil drop-test" in first
    assert "pip install" in second and "pytest" in second


def test_ci_runs_the_readme_test_command():
    _, second = _quick_start_commands()
    assert second in (ROOT / ".ci" / "run").read_text()
