"""Mutation testing of the safety code: flip each comparison, one at a time, and run the tests.

Python targets: every comparison in ``src/sashil/safety.py`` (the host's supervisor), in
``clamp_current`` of ``drivers/interface.py`` (the one current clamp), in the device watchdog of
``drivers/emulator/device.py`` (the comparisons that read ``watchdog*`` or ``_last_cmd_ns``), and in
what the rtdac backend lets reach a board with no watchdog of its own: the coil's and the road's
outputs (``output`` and ``_lag`` of ``drivers/rtdac_outputs.py``: the current loop's authority, the
road's limits and its one-way clamp) and the bring-up caps of a guessed wiring (``BringUp.of`` of
``drivers/rtdac_bringup.py``).

C targets, the board that runs on the bench (``drivers/firmware/sashil_board.c``): the current clamp
(``set_drive``), the watchdog (in ``sashil_board_tick`` and ``sashil_board_next_event_us``), and the
fault paths: Configure's refusals (a rate above the link's), a Command before Configure, a CAN frame
of the wrong length, a HAL without a transmitter (``configure``, ``sashil_board_set_max_rate``,
``handle``, ``sashil_board_receive_can``, ``emit``).

Each comparison operator gives two mutants: its negation (``<`` -> ``>=``, ``==`` -> ``!=``,
``is`` -> ``is not``, ``in`` -> ``not in``) and, for an ordering, its boundary twin (``<`` -> ``<=``,
``>=`` -> ``>``); in C a logical not (``!x``) is also dropped. A Python mutant is *killed* when the
unit tests of the safety path fail against it; a C mutant when the C board's tests fail against it
(``tests/test_firmware_board.py``, the sanitizer fuzz), or, for one those miss, the end-to-end tests
of the emulator on the C board over ptys (``tests/test_emulator_link.py``). No mutant is written
into the work tree: a child process puts an import hook in front of the Python module that compiles
the mutated syntax tree, or builds the C board from a mutated copy of its sources in a temporary
folder (``sashil.drivers.firmware.HERE`` pointed there, its own library cache). A C mutant the
compiler rejects is listed apart and not counted.

    .venv/bin/python tools/mutate_safety.py            # all mutants, a table and the kill rate
    .venv/bin/python tools/mutate_safety.py --list     # the mutants only
    .venv/bin/python tools/mutate_safety.py --quiet    # the kill rate and the survivors (CI)
    .venv/bin/python tools/mutate_safety.py --quick    # two mutants: the supervisor's and the C clamp's

``--quick`` runs a fixed sample of two mutants, the first of the supervisor (``safety.py``) and the
first of the C board's current clamp, each against the one test file of its code (:data:`QUICK_TESTS`,
:data:`QUICK_C_TESTS`), with the same checks of the tests without a mutant first: seconds.

``--jobs N`` tests N mutants at once, each in a child process of its own (default: one per CPU this
process may use); a C survivor's end-to-end check runs alone.

Exit status 0 when every mutant is killed, 1 otherwise.
"""

from __future__ import annotations

import argparse
import ast
import copy
import importlib.abc
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: the tests of the safety path (unit tier: the virtual clock, no pty, no child process)
TESTS = [
    "tests/test_safety.py",
    "tests/test_emulator_device.py",
    "tests/test_loop.py",
    "tests/test_sim_driver.py",
    "tests/test_rtdac_outputs.py",
]

#: the C board's tests (unit tier), and the end-to-end ones on the C board for what those miss
C_TESTS = ["tests/test_firmware_board.py", "tests/test_firmware_fuzz.py"]
C_E2E_TESTS = ["tests/test_emulator_link.py", "-k", "not python"]
#: --quick: the test file of each of its two mutants' code (the supervisor's, the C board's)
QUICK_TESTS = TESTS[:1]
QUICK_C_TESTS = C_TESTS[:1]

NEGATE = {
    ast.Lt: ast.GtE,
    ast.GtE: ast.Lt,
    ast.Gt: ast.LtE,
    ast.LtE: ast.Gt,
    ast.Eq: ast.NotEq,
    ast.NotEq: ast.Eq,
    ast.Is: ast.IsNot,
    ast.IsNot: ast.Is,
    ast.In: ast.NotIn,
    ast.NotIn: ast.In,
}
BOUNDARY = {ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt}


@dataclass(frozen=True)
class Target:
    module: str
    path: str
    function: str | None = None  # only comparisons inside this function
    mentions: tuple[str, ...] = ()  # only comparisons whose source mentions one of these


TARGETS = (
    Target("sashil.safety", "src/sashil/safety.py"),
    Target("sashil.drivers.interface", "drivers/interface.py", function="clamp_current"),
    Target("sashil.drivers.emulator.device", "drivers/emulator/device.py", mentions=("watchdog", "_last_cmd_ns")),
    Target("sashil.drivers.rtdac_outputs", "drivers/rtdac_outputs.py", function="output"),
    Target("sashil.drivers.rtdac_outputs", "drivers/rtdac_outputs.py", function="_lag"),
    Target("sashil.drivers.rtdac_bringup", "drivers/rtdac_bringup.py", function="of"),
)


@dataclass(frozen=True)
class Mutant:
    target: Target
    index: int  # the n-th Compare node of the module (ast.walk order)
    op: int  # which operator of that node
    new: str  # the new operator's class name
    line: int
    text: str  # the comparison as written, and as mutated

    @property
    def label(self) -> str:
        return f"{self.target.path}:{self.line}"


def _compares(tree: ast.Module) -> list[ast.Compare]:
    return [node for node in ast.walk(tree) if isinstance(node, ast.Compare)]


def _inside(tree: ast.Module, name: str) -> set[int]:
    """ids of the Compare nodes inside function ``name``."""
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name == name:
            out |= {id(n) for n in ast.walk(node) if isinstance(n, ast.Compare)}
    return out


def mutants(target: Target) -> list[Mutant]:
    source = (ROOT / target.path).read_text()
    tree = ast.parse(source)
    allowed = _inside(tree, target.function) if target.function else None
    out = []
    for index, node in enumerate(_compares(tree)):
        segment = ast.get_source_segment(source, node) or ""
        if allowed is not None and id(node) not in allowed:
            continue
        if target.mentions and not any(word in segment for word in target.mentions):
            continue
        for op_index, op in enumerate(node.ops):
            for table in (NEGATE, BOUNDARY):
                new = table.get(type(op))
                if new is None:
                    continue
                mutated = copy.deepcopy(node)
                mutated.ops[op_index] = new()
                text = f"{segment}  ->  {ast.unparse(mutated)}"
                out.append(Mutant(target, index, op_index, new.__name__, node.lineno, text))
    return sorted(out, key=lambda m: m.line)


def mutated_code(mutant: Mutant):
    """The target module's code object with the one operator replaced."""
    path = ROOT / mutant.target.path
    tree = ast.parse(path.read_text())
    node = _compares(tree)[mutant.index]
    node.ops[mutant.op] = getattr(ast, mutant.new)()
    return compile(tree, str(path), "exec")


class _Loader(importlib.abc.Loader):
    def __init__(self, code):
        self.code = code

    def create_module(self, spec):
        return None

    def exec_module(self, module):
        exec(self.code, module.__dict__)


class _Finder(importlib.abc.MetaPathFinder):
    def __init__(self, module: str, path: Path, code):
        self.module, self.path, self.code = module, path, code

    def find_spec(self, fullname, path=None, target=None):
        if fullname != self.module:
            return None
        return importlib.util.spec_from_file_location(fullname, self.path, loader=_Loader(self.code))


def _child(spec: str) -> int:
    """Run the tests with the mutant ``spec`` (JSON) in place of its module."""
    import pytest

    data = json.loads(spec)
    if "c" in data:
        return _c_child(data["c"])
    found = data["mutant"]
    if found is not None:
        target = next(t for t in TARGETS if t.module == found["module"])
        mutant = Mutant(target, found["index"], found["op"], found["new"], 0, "")
        sys.meta_path.insert(0, _Finder(target.module, ROOT / target.path, mutated_code(mutant)))
    os.chdir(ROOT)
    # -n 0: the mutant is in this process's importer, so the tests run here, not in xdist workers
    return int(pytest.main(["-x", "-q", "-n", "0", "-p", "no:cacheprovider", "-m", "not e2e", *data["tests"]]))


def run(mutant: Mutant | None, timeout_s: float, tests: list[str] = TESTS) -> tuple[bool, str]:
    """(``tests`` passed, the first failing test or why the run ended)."""
    found = (
        None
        if mutant is None
        else {"module": mutant.target.module, "index": mutant.index, "op": mutant.op, "new": mutant.new}
    )
    argv = [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps({"mutant": found, "tests": tests})]
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout_s, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return False, f"timeout after {timeout_s:g} s"
    failed = [line.split(" ")[1] for line in done.stdout.splitlines() if line.startswith(("FAILED ", "ERROR "))]
    return done.returncode == 0, failed[0] if failed else f"exit {done.returncode}"


@dataclass(frozen=True)
class CTarget:
    path: str
    function: str
    mentions: tuple[str, ...] = ()  # only operators on a line that mentions one of these


C_TARGETS = (
    CTarget("drivers/firmware/sashil_board.c", "set_drive"),
    CTarget(
        "drivers/firmware/sashil_board.c",
        "sashil_board_tick",
        mentions=("watchdog", "last_cmd", "road_urad", "commanded"),
    ),
    CTarget("drivers/firmware/sashil_board.c", "sashil_board_next_event_us", mentions=("watchdog", "commanded")),
    CTarget("drivers/firmware/sashil_board.c", "configure"),
    CTarget("drivers/firmware/sashil_board.c", "sashil_board_set_max_rate"),
    CTarget("drivers/firmware/sashil_board.c", "handle", mentions=("configured",)),
    CTarget("drivers/firmware/sashil_board.c", "sashil_board_receive_can", mentions=("len",)),
    CTarget("drivers/firmware/sashil_board.c", "emit", mentions=("NULL",)),
)

#: mutants that behave exactly as the original (no test can kill them): (function, the line's code
#: before the mutation, the operator, its replacement) and why; listed apart and not counted
C_EQUIVALENT = {
    ("set_drive", "if (counts > b->current_max_counts) {", ">", ">="): "a current at the limit is clamped to itself",
    (
        "sashil_board_set_max_rate",
        "b->max_rate_hz = max_rate_hz >= 1u && max_rate_hz <= SASHIL_MAX_RATE_HZ ? max_rate_hz : SASHIL_MAX_RATE_HZ;",
        "<=",
        "<",
    ): "a limit of 20000 is replaced by 20000",
}

C_NEGATE = {"<": ">=", ">=": "<", ">": "<=", "<=": ">", "==": "!=", "!=": "=="}
C_BOUNDARY = {"<": "<=", "<=": "<", ">": ">=", ">=": ">"}
# a comparison, not a shift (<<, >>), an arrow (->) or an assignment; a logical not, not !=
_C_COMPARE = re.compile(r"(?<![-<>=!])(==|!=|<=|>=|<|>)(?![<>=])")
_C_NOT = re.compile(r"!(?!=)")
_C_COMMENT = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)


@dataclass(frozen=True)
class CMutant:
    target: CTarget
    offset: int  # in the file
    old: str
    new: str
    line: int
    text: str

    @property
    def label(self) -> str:
        return f"{self.target.path}:{self.line}"


def _c_body(source: str, function: str) -> tuple[int, int]:
    """[start, end) of the body of the C function defined as ``... function(...)\n{ ... \n}``."""
    found = re.search(rf"^[A-Za-z][^;\n]*\b{function}\([^;{{]*?\)\s*\n\{{", source, re.M)
    if found is None:
        raise LookupError(f"no function {function}")
    end = source.index("\n}", found.end())
    return found.end(), end


def c_mutants(target: CTarget) -> list[CMutant]:
    source = (ROOT / target.path).read_text()
    masked = _C_COMMENT.sub(lambda m: re.sub(r"[^\n]", " ", m.group()), source)  # same offsets
    start, end = _c_body(masked, target.function)
    out = []
    for pattern, tables in ((_C_COMPARE, (C_NEGATE, C_BOUNDARY)), (_C_NOT, ({"!": ""},))):
        for match in pattern.finditer(masked, start, end):
            line_start = masked.rfind("\n", 0, match.start()) + 1
            line_end = masked.index("\n", match.start())
            line = masked[line_start:line_end]
            if target.mentions and not any(word in line for word in target.mentions):
                continue
            for table in tables:
                new = table.get(match.group())
                if new is None:
                    continue
                col = match.start() - line_start
                mutated = line[:col] + new + line[col + len(match.group()) :]
                text = f"{line.strip()}  ->  {mutated.strip()}"
                number = masked.count("\n", 0, match.start()) + 1
                out.append(CMutant(target, match.start(), match.group(), new, number, text))
    return sorted(out, key=lambda m: (m.line, m.offset, m.new))


def _equivalent(mutant: CMutant) -> str | None:
    """Why ``mutant`` is an equivalent mutant, or None."""
    before = mutant.text.split("  ->  ")[0]
    return C_EQUIVALENT.get((mutant.target.function, before, mutant.old, mutant.new))


def mutated_c_source(mutant: CMutant) -> str:
    source = (ROOT / mutant.target.path).read_text()
    assert source[mutant.offset : mutant.offset + len(mutant.old)] == mutant.old
    return source[: mutant.offset] + mutant.new + source[mutant.offset + len(mutant.old) :]


def _c_child(data: dict) -> int:
    """Run the C tests on a board built from a copy of the firmware with the mutant ``data`` in it.
    Exit 3 when the mutated sources do not build."""
    import pytest

    from sashil.drivers import firmware
    from sashil.errors import DriverError

    os.environ["SASHIL_CACHE"] = data["cache"]  # the mutants' libraries, apart from the user's cache
    with tempfile.TemporaryDirectory(prefix="mutant-") as tmp:
        for name in (*firmware.SOURCES, *firmware.HEADERS):
            shutil.copy(firmware.HERE / name, Path(tmp) / name)
        if data.get("offset") is not None:
            target = CTarget(data["path"], "")
            mutant = CMutant(target, data["offset"], data["old"], data["new"], 0, "")
            (Path(tmp) / Path(data["path"]).name).write_text(mutated_c_source(mutant))
        firmware.HERE = Path(tmp)
        try:
            firmware.library_path()
        except DriverError:
            return 3
        os.chdir(ROOT)
        # -n 0: firmware.HERE points at the mutant in this process only, so the tests run here
        return int(pytest.main(["-x", "-q", "-n", "0", "-p", "no:cacheprovider", *data["tests"]]))


def run_c(mutant: CMutant | None, tests: list[str], cache: str, timeout_s: float) -> tuple[bool | None, str]:
    """(tests passed, or None when the mutant does not build; the first failing test or why it ended)."""
    spec: dict = {"cache": cache, "tests": tests}
    if mutant is not None:
        spec.update(path=mutant.target.path, offset=mutant.offset, old=mutant.old, new=mutant.new)
    argv = [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps({"c": spec})]
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout_s, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return False, f"timeout after {timeout_s:g} s"
    if done.returncode == 3:
        return None, "does not build"
    failed = [line.split(" ")[1] for line in done.stdout.splitlines() if line.startswith(("FAILED ", "ERROR "))]
    return done.returncode == 0, failed[0] if failed else f"exit {done.returncode}"


def _verdict(n: int, total: int, label: str, text: str, verdict: str, quiet: bool) -> None:
    if not quiet:
        print(f"[{n:2}/{total}] {label:40} {text:60} {verdict}", flush=True)


def _run_python(
    found: list[Mutant], timeout_s: float, quiet: bool, tests: list[str] = TESTS, jobs: int = 1
) -> list[Mutant] | None:
    """The survivors among ``found`` against ``tests`` (``jobs`` mutants at a time), or None when
    they fail without a mutant."""
    ok, why = run(None, timeout_s, tests)
    if not ok:
        print(f"the Python tests fail without a mutant ({why}): fix them first", file=sys.stderr)
        return None
    survivors = []
    with ThreadPoolExecutor(jobs) as pool:  # each mutant's tests run in a child process of their own
        results = pool.map(lambda m: run(m, timeout_s, tests), found)
    for n, (m, (passed, why)) in enumerate(zip(found, results, strict=True), 1):
        _verdict(n, len(found), m.label, m.text, "SURVIVED" if passed else f"killed by {why}", quiet)
        if passed:
            survivors.append(m)
    return survivors


def _run_c(
    found: list[CMutant], timeout_s: float, quiet: bool, tests: list[str] = C_TESTS, jobs: int = 1
) -> tuple[list[CMutant], list[CMutant]] | None:
    """(survivors, mutants not counted: equivalent or not building) among ``found`` against ``tests``
    (``jobs`` mutants at a time; then C_E2E_TESTS for a survivor, one at a time), or None when the
    tests fail without a mutant."""
    with tempfile.TemporaryDirectory(prefix="mutate-cache-") as cache:
        ok, why = run_c(None, tests, cache, timeout_s)
        if not ok:
            print(f"the C tests fail without a mutant ({why}): fix them first", file=sys.stderr)
            return None
        e2e_checked, survivors, stillborn = False, [], []
        runnable = [k for k, m in enumerate(found) if _equivalent(m) is None]
        with ThreadPoolExecutor(jobs) as pool:
            first = dict(
                zip(runnable, pool.map(lambda k: run_c(found[k], tests, cache, timeout_s), runnable), strict=True)
            )
        for n, m in enumerate(found, 1):
            if _equivalent(m) is not None:  # nothing to run: no test could tell it apart
                stillborn.append(m)
                _verdict(n, len(found), m.label, m.text, f"equivalent: {_equivalent(m)} (not counted)", quiet)
                continue
            passed, why = first[n - 1]
            if passed and not e2e_checked:  # the end-to-end tests must pass without a mutant first
                ok, e2e_why = run_c(None, C_E2E_TESTS, cache, timeout_s)
                if not ok:
                    print(f"the C board's e2e tests fail without a mutant ({e2e_why})", file=sys.stderr)
                    return None
                e2e_checked = True
            if passed:
                passed, why = run_c(m, C_E2E_TESTS, cache, timeout_s)
            if passed is None:
                stillborn.append(m)
            elif passed:
                survivors.append(m)
            verdict = {None: "does not build (not counted)", True: "SURVIVED"}.get(passed, f"killed by {why}")
            _verdict(n, len(found), m.label, m.text, verdict, quiet)
        return survivors, stillborn


def _rate(what: str, total: int, survivors: int, seconds: float, tests: str) -> str:
    killed = total - survivors
    return (
        f"{what}: kill rate {killed}/{total} = {100 * killed / max(total, 1):.0f} % ({seconds:.0f} s; tests: {tests})"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--list", action="store_true", help="list the mutants, run nothing")
    parser.add_argument("-q", "--quiet", action="store_true", help="only the kill rates and the survivors")
    parser.add_argument("--timeout", type=float, default=120.0, metavar="S", help="per mutant (default 120)")
    parser.add_argument(
        "--jobs",
        type=int,
        default=len(os.sched_getaffinity(0)),
        metavar="N",
        help="mutants tested at once, each in a process of its own (default: the CPUs this process may use)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="two mutants only: the first of the supervisor, the first of the C clamp (seconds)",
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        return _child(args.child)
    if args.quick:
        found, c_found = [mutants(TARGETS[0])[0]], [c_mutants(C_TARGETS[0])[0]]
    else:
        found = [m for target in TARGETS for m in mutants(target)]
        c_found = [m for target in C_TARGETS for m in c_mutants(target)]
    if args.list:
        for m in [*found, *c_found]:
            print(f"{m.label:40} {m.text}")
        print(f"{len(found)} Python mutants, {len(c_found)} C mutants")
        return 0
    started = time.monotonic()
    tests, c_tests = (QUICK_TESTS, QUICK_C_TESTS) if args.quick else (TESTS, C_TESTS)
    survivors = _run_python(found, args.timeout, args.quiet, tests, args.jobs)
    if survivors is None:
        return 2
    python_s = time.monotonic() - started
    c_result = _run_c(c_found, args.timeout, args.quiet, c_tests, args.jobs)
    if c_result is None:
        return 2
    c_survivors, stillborn = c_result
    counted = len(c_found) - len(stillborn)
    print(_rate("Python", len(found), len(survivors), python_s, " ".join(tests)))
    c_named = f"{' '.join(c_tests)}, then {' '.join(C_E2E_TESTS)}"
    print(_rate("C", counted, len(c_survivors), time.monotonic() - started - python_s, c_named))
    total, left = len(found) + counted, len(survivors) + len(c_survivors)
    print(f"kill rate {total - left}/{total} = {100 * (total - left) / max(total, 1):.0f} %")
    for m in [*survivors, *c_survivors]:
        print(f"survivor: {m.label} {m.text}")
    for m in stillborn:
        print(f"{_equivalent(m) or 'does not build'} (not counted): {m.label} {m.text}")
    return 0 if not left else 1


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("mutate_safety", main, children=("--child",)))
