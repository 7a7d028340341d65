"""tools/mutate_safety.py finds the comparisons of the safety code and builds every mutant."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[1] / "tools" / "mutate_safety.py"


def load_tool():
    spec = importlib.util.spec_from_file_location("mutate_safety", TOOL)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_every_target_has_mutants_and_each_compiles():
    tool = load_tool()
    for target in tool.TARGETS:
        found = tool.mutants(target)
        assert found, f"no comparison found in {target.path} (renamed?)"
        for mutant in found:
            assert "->" in mutant.text
            tool.mutated_code(mutant)  # compiles


def test_a_mutant_changes_exactly_one_operator():
    tool = load_tool()
    (target,) = [t for t in tool.TARGETS if t.function == "clamp_current"]
    (mutant,) = tool.mutants(target)
    assert mutant.text.endswith("current_a == current_a")
    namespace: dict = {}
    exec(tool.mutated_code(mutant), namespace)
    assert namespace["clamp_current"](0.5, 1.0) == 0.0  # every non-NaN current now reads as NaN -> 0 A
