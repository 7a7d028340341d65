"""Every script in ``tools/`` runs end to end in its quick mode, so a benchmark that crashes fails here.

Each script takes ``--quick``: the same code path on a tiny problem (seconds), printing its figures
(meaningless at that size). A script whose quick mode another test already runs and checks
(:data:`RUN_ELSEWHERE`) is not run a second time here. A script that needs a tool this machine lacks (qemu-system-arm, a C
compiler, make and ziglang, Chromium and Playwright) says so in one line and exits 0. A new script without ``--quick`` fails
the first test.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted((ROOT / "tools").glob("*.py"))

#: the scripts that run on the wall clock against an emulated rig over ptys, a socket (the RT-DAC's) or
#: QEMU's serial socket, drive Chromium against the panel, or run whole verbs on the real clock and fit
#: (readme_figures: the timing figure's runs, a calibration and an identification; tutorial_figures:
#: a run and the emulated board's doctor)
E2E = {
    "bench_calibrate.py", "bench_control_link.py", "bench_formats.py", "bench_link.py", "bench_preview_link.py",
    "bench_rtdac.py", "panel_figures.py", "qemu_smoke.py", "readme_figures.py", "tutorial_figures.py",
}  # fmt: skip

#: scripts whose quick mode a test elsewhere runs whole and checks the figures of (script: that test)
RUN_ELSEWHERE = {"bench_drop_damping.py": ("test_drop_damping.py", "test_bench_quick_meets_the_goal")}


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda path: path.name)
def test_every_tool_has_a_quick_mode(script: Path) -> None:
    assert "--quick" in script.read_text(encoding="utf-8"), f"tools/{script.name} has no --quick mode"


@pytest.mark.parametrize("script", sorted(RUN_ELSEWHERE))
def test_a_tool_left_out_here_runs_in_quick_mode_elsewhere(script: str) -> None:
    module, test = RUN_ELSEWHERE[script]
    source = (ROOT / "tests" / module).read_text(encoding="utf-8")
    assert f"def {test}(" in source, f"tests/{module} has no {test}"
    body = source.split(f"def {test}(", 1)[1].split("\ndef ", 1)[0]
    assert script in body and '"--quick"' in body, f"tests/{module}::{test} does not run tools/{script} --quick"


@pytest.mark.parametrize(
    "script", [path for path in SCRIPTS if path.name not in RUN_ELSEWHERE.keys() | E2E], ids=lambda path: path.name
)
def test_tool_runs_in_quick_mode(script: Path, warm_sashil) -> None:
    # a fork of the tests' warm interpreter runs the script as ``python tools/SCRIPT --quick`` would
    # (tests/warm_sashil.py): the imports and kernels every tool loads are paid once per worker
    _runs_in_quick_mode(script, {}, warm_sashil.python)


@pytest.mark.e2e
@pytest.mark.parametrize("script", [path for path in SCRIPTS if path.name in E2E], ids=lambda path: path.name)
def test_link_tool_runs_in_quick_mode(script: Path, warm_sashil) -> None:
    # a fresh interpreter, killed with what it started if it overruns (below); the sashil commands it
    # starts fork the tests' warm interpreter (SASHIL_COMMAND, tests/warm_sashil.py)
    _runs_in_quick_mode(script, {"SASHIL_COMMAND": " ".join(warm_sashil.command)}, [sys.executable])


def _runs_in_quick_mode(script: Path, env: dict[str, str], python: list[str]) -> None:
    # in a session of its own: a tool that overruns is killed with what it started (an emulator at
    # real-time priority, a worker pool), which would otherwise spin on for the rest of the suite. A
    # warm fork (the client's child) is first told SIGTERM, which the client passes on to it.
    with subprocess.Popen(
        [*python, f"tools/{script.name}", "--quick"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env={**os.environ, **env},
    ) as tool:
        try:
            stdout, stderr = tool.communicate(timeout=120)
        except BaseException:
            if python != [sys.executable]:
                tool.terminate()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    tool.wait(timeout=10)
            with contextlib.suppress(ProcessLookupError):  # a warm client that ended with its fork
                os.killpg(tool.pid, signal.SIGKILL)
            tool.communicate()
            raise
    assert tool.returncode == 0, (
        f"tools/{script.name} --quick: exit {tool.returncode}\n{stdout[-3000:]}\n{stderr[-3000:]}"
    )
    assert stdout.strip(), f"tools/{script.name} --quick printed nothing"
