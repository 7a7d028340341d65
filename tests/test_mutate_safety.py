"""tools/mutate_safety.py finds the comparisons of the safety code and builds every mutant."""

from __future__ import annotations

from tool_module import load_tool


def test_every_target_has_mutants_and_each_compiles():
    tool = load_tool("mutate_safety")
    for target in tool.TARGETS:
        found = tool.mutants(target)
        assert found, f"no comparison found in {target.path} (renamed?)"
        for mutant in found:
            assert "->" in mutant.text
            tool.mutated_code(mutant)  # compiles


def test_a_mutant_changes_exactly_one_operator():
    tool = load_tool("mutate_safety")
    (target,) = [t for t in tool.TARGETS if t.function == "clamp_current"]
    (mutant,) = tool.mutants(target)
    assert mutant.text.endswith("current_a == current_a")
    namespace: dict = {}
    exec(tool.mutated_code(mutant), namespace)
    assert namespace["clamp_current"](0.5, 1.0) == 0.0  # every non-NaN current now reads as NaN -> 0 A


def test_every_c_target_has_mutants_each_one_operator_away_and_the_equivalents_exist():
    tool = load_tool("mutate_safety")
    every = []
    for target in tool.C_TARGETS:
        found = tool.c_mutants(target)
        assert found, f"no comparison found in {target.function} of {target.path} (renamed?)"
        every += found
    source = (tool.ROOT / "drivers/firmware/sashil_board.c").read_text()
    for mutant in every:
        mutated = tool.mutated_c_source(mutant)
        assert mutated != source and len(mutated) == len(source) + len(mutant.new) - len(mutant.old)
        assert mutated[: mutant.offset] == source[: mutant.offset]
    equivalents = [m for m in every if tool._equivalent(m) is not None]
    assert len(equivalents) == len(tool.C_EQUIVALENT)  # each one still names a real mutant


def test_the_c_watchdogs_comparison_and_its_logical_not_are_mutated():
    tool = load_tool("mutate_safety")
    (tick,) = [t for t in tool.C_TARGETS if t.function == "sashil_board_tick"]
    texts = [m.text for m in tool.c_mutants(tick)]
    assert any("now_us - b->last_cmd_us > (uint64_t)b->watchdog_ms" in t.split("  ->  ")[1] for t in texts)
    assert any("b->commanded && b->watchdog_tripped &&" in t.split("  ->  ")[1] for t in texts)
    assert not any("next_sample" in t for t in texts)  # the pacing is not safety code
