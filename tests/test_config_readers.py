"""The config readers' count: the files outside the config layer that read a config's keys, and the rule's reading."""

from __future__ import annotations

import ast
from pathlib import Path

from tool_module import load_tool

ROOT = Path(__file__).resolve().parents[1]


def test_at_most_twelve_files_read_a_configs_keys_and_none_on_the_loop_side():
    tool = load_tool("config_readers", "config_readers_tool")
    counted = tool.readers()
    loop_side = [name for name in counted if name.startswith(tool.LOOP_SIDE)]
    assert loop_side == []
    assert len(counted) <= 12, sorted(counted)


def test_the_rule_counts_reads_of_a_config_and_of_a_sections_name():
    tool = load_tool("config_readers", "config_readers_tool")
    sections = tool.section_names()
    assert {"model", "rig", "mismatch", "rtdac", "controller", "calibrate"} <= sections  # rtdac: not in sim.yaml
    source = """
config["loop"]["rate_hz"]
run_config.get("rig")
read_key(cfg, "driver.name")
values["rtdac"]
options["calibrate"]
"""
    found = tool.reasons(ast.parse(source), sections)
    assert sorted(found) == [
        "2: config[…]",
        "3: run_config[…]",
        "4: read_key(cfg, …)",
        "5: values['rtdac']",
        "6: options['calibrate']",
    ]
    assert tool.reasons(ast.parse('values["port"]; section["kalman_accel_psd"]'), sections) == []


def test_a_sequence_index_and_a_document_being_written_read_no_key():
    tool = load_tool("config_readers", "config_readers_tool")
    source = """
doc = ["a paragraph"]
first = doc[0]
doc = {}
doc["calibration"] = {}
doc["calibration"]["intervals"] = 1
del doc["calibration"]
"""
    assert tool.reasons(ast.parse(source), tool.section_names()) == []
    assert len(tool.reasons(ast.parse("x = doc['calibration']"), tool.section_names())) == 1
