"""Mutation testing of the safety code: flip each comparison, one at a time, and run the tests.

Targets: every comparison in ``src/sashil/safety.py`` (the host's supervisor), in
``clamp_current`` of ``drivers/interface.py`` (the one current clamp) and in the device watchdog of
``drivers/emulator/device.py`` (the comparisons that read ``watchdog*`` or ``_last_cmd_ns``).

Each comparison operator gives two mutants: its negation (``<`` -> ``>=``, ``==`` -> ``!=``,
``is`` -> ``is not``, ``in`` -> ``not in``) and, for an ordering, its boundary twin (``<`` -> ``<=``,
``>=`` -> ``>``). A mutant is *killed* when the unit tests of the safety path fail against it. The
mutant is never written to disk: a child process puts an import hook in front of the module that
compiles the mutated syntax tree, so the work tree stays as it is whatever happens.

    .venv/bin/python tools/mutate_safety.py            # all mutants, a table and the kill rate
    .venv/bin/python tools/mutate_safety.py --list     # the mutants only
    .venv/bin/python tools/mutate_safety.py --quiet    # the kill rate and the survivors (CI)
    .venv/bin/python tools/mutate_safety.py --quick    # two mutants only (the supervisor's and the watchdog's first)

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
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: the tests of the safety path (unit tier: the virtual clock, no pty, no child process)
TESTS = ["tests/test_safety.py", "tests/test_emulator_device.py", "tests/test_loop.py", "tests/test_sim_driver.py"]

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
    if data is not None:
        target = next(t for t in TARGETS if t.module == data["module"])
        mutant = Mutant(target, data["index"], data["op"], data["new"], 0, "")
        sys.meta_path.insert(0, _Finder(target.module, ROOT / target.path, mutated_code(mutant)))
    os.chdir(ROOT)
    return int(pytest.main(["-x", "-q", "-p", "no:cacheprovider", "-m", "not e2e", *TESTS]))


def run(mutant: Mutant | None, timeout_s: float) -> tuple[bool, str]:
    """(tests passed, the first failing test or why the run ended)."""
    spec = (
        None
        if mutant is None
        else {"module": mutant.target.module, "index": mutant.index, "op": mutant.op, "new": mutant.new}
    )
    argv = [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(spec)]
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout_s, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return False, f"timeout after {timeout_s:g} s"
    failed = [line.split(" ")[1] for line in done.stdout.splitlines() if line.startswith(("FAILED ", "ERROR "))]
    return done.returncode == 0, failed[0] if failed else f"exit {done.returncode}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--list", action="store_true", help="list the mutants, run nothing")
    parser.add_argument("-q", "--quiet", action="store_true", help="only the kill rate and the survivors")
    parser.add_argument("--timeout", type=float, default=120.0, metavar="S", help="per mutant (default 120)")
    parser.add_argument(
        "--quick", action="store_true", help="two mutants only: the first of the first and of the last target"
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        return _child(args.child)
    if args.quick:
        found = [mutants(TARGETS[0])[0], mutants(TARGETS[-1])[0]]
    else:
        found = [m for target in TARGETS for m in mutants(target)]
    if args.list:
        for m in found:
            print(f"{m.label:36} {m.text}")
        print(f"{len(found)} mutants")
        return 0
    ok, why = run(None, args.timeout)
    if not ok:
        print(f"the tests fail without a mutant ({why}): fix them first", file=sys.stderr)
        return 2
    started, survivors = time.monotonic(), []
    for n, m in enumerate(found, 1):
        passed, why = run(m, args.timeout)
        verdict = "SURVIVED" if passed else f"killed by {why}"
        if not args.quiet:
            print(f"[{n:2}/{len(found)}] {m.label:36} {m.text:60} {verdict}", flush=True)
        if passed:
            survivors.append(m)
    killed = len(found) - len(survivors)
    print(
        f"kill rate {killed}/{len(found)} = {100 * killed / max(len(found), 1):.0f} % "
        f"({time.monotonic() - started:.0f} s; tests: {' '.join(TESTS)})"
    )
    for m in survivors:
        print(f"survivor: {m.label} {m.text}")
    return 0 if not survivors else 1


if __name__ == "__main__":
    sys.exit(main())
