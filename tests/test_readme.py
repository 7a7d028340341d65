"""The README quick start is exactly two commands, and CI runs the second one."""

from __future__ import annotations

from pathlib import Path

from doc_blocks import fenced_blocks, section

ROOT = Path(__file__).resolve().parents[1]


def _quick_start_commands() -> list[str]:
    blocks = fenced_blocks(section((ROOT / "README.md").read_text(), "## Quick start"))
    assert len(blocks) == 1, "one fenced block under ## Quick start"
    return [line for line in blocks[0].body.splitlines() if line.strip()]


def test_quick_start_has_two_commands_setup_and_drop_test_then_tests():
    first, second = _quick_start_commands()
    assert "pip install" in first and "sashil drop-test" in first
    assert "pip install" in second and "pytest" in second


def test_ci_runs_the_readme_test_command():
    _, second = _quick_start_commands()
    assert second in (ROOT / ".ci" / "run").read_text()


def test_a_failed_test_in_the_readme_command_fails_ci():
    """``set -e`` lets a failed command inside an && list pass: the line must stop CI itself."""
    import subprocess

    _, second = _quick_start_commands()
    (line,) = [line for line in (ROOT / ".ci" / "run").read_text().splitlines() if second in line]
    failing = line.replace(second, "true && false && true")  # the parallel tier fails, the alone tier is skipped
    done = subprocess.run(
        ["bash", "-c", f"set -euo pipefail\n{failing}\necho CI-went-on"], capture_output=True, text=True
    )
    assert done.returncode != 0 and "CI-went-on" not in done.stdout


def test_the_readme_python_examples_run(tmp_path, monkeypatch):
    import subprocess
    import sys

    blocks = [block for block in fenced_blocks((ROOT / "README.md").read_text()) if block.info == "python"]
    assert blocks, "the README shows sashil from Python"
    for block in blocks:
        done = subprocess.run([sys.executable, "-c", block.body], cwd=tmp_path, capture_output=True, text=True)
        assert done.returncode == 0, f"README.md line {block.line}:\n{done.stderr[-2000:]}"
        assert "ok [0.5]" in done.stdout
