"""Every script in ``tools/`` runs end to end in its quick mode, so a benchmark that crashes fails here.

Each script takes ``--quick``: the same code path on a tiny problem (seconds), printing its figures
(meaningless at that size). A script that needs a tool this machine lacks (qemu-system-arm, a C
compiler, make and ziglang) says so in one line and exits 0. A new script without ``--quick`` fails
the first test.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted((ROOT / "tools").glob("*.py"))

#: the scripts that run on the wall clock against an emulated rig over ptys (or QEMU's serial socket)
E2E = {"bench_calibrate.py", "bench_control_link.py", "bench_formats.py", "bench_link.py", "qemu_smoke.py"}


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda path: path.name)
def test_every_tool_has_a_quick_mode(script: Path) -> None:
    assert "--quick" in script.read_text(encoding="utf-8"), f"tools/{script.name} has no --quick mode"


@pytest.mark.parametrize(
    "script",
    [pytest.param(path, id=path.name, marks=[pytest.mark.e2e] if path.name in E2E else []) for path in SCRIPTS],
)
def test_tool_runs_in_quick_mode(script: Path) -> None:
    done = subprocess.run(
        [sys.executable, f"tools/{script.name}", "--quick"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, (
        f"tools/{script.name} --quick: exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    )
    assert done.stdout.strip(), f"tools/{script.name} --quick printed nothing"
