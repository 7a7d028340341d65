"""The static types of a resolved config (``sashil.config.typed``) follow the schema, and mypy holds
code to them.

- The committed module equals what ``tools/gen_config_types.py`` writes from today's schema.
- Each section's keys and their types are the schema's (a hand-derived sample).
- mypy refuses a misspelt key, a wrong kind and a write into a resolved config, and accepts reads.
- ``resolve`` gives a read-only config at run time (the types' promise is kept there too).
"""

from __future__ import annotations

import shutil
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from sashil.config import typed
from sashil.config.schema import Section
from sashil.config.sections import SCHEMA
from sashil.engine.resolve import ConfigSource, resolve

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import gen_config_types  # noqa: E402


def test_the_committed_types_are_what_the_schema_gives() -> None:
    committed = (ROOT / "src" / "sashil" / "config" / "typed.py").read_text(encoding="utf-8")
    assert committed == gen_config_types.render(), "run python tools/gen_config_types.py"


def annotations(cls: Any) -> dict[str, str]:
    """A TypedDict's item types as written (the module's annotations are not evaluated)."""
    return {key: getattr(value, "__forward_arg__", value) for key, value in cls.__annotations__.items()}


def test_every_section_has_the_schema_keys() -> None:
    assert set(annotations(typed.RunConfig)) == set(SCHEMA)
    for name, spec in SCHEMA.items():
        assert isinstance(spec, Section)
        if spec.open_keys:
            assert annotations(typed.RunConfig)[name] == "ReadOnly[Mapping[str, Any]]"
            continue
        cls = getattr(typed, gen_config_types.class_name((name,)))
        assert set(annotations(cls)) == set(spec.fields), name
        assert annotations(typed.RunConfig)[name] == f"ReadOnly[{cls.__name__}]"


def test_item_types_follow_the_field_kinds() -> None:
    loop = annotations(typed.LoopSection)
    assert loop["rate_hz"] == "ReadOnly[float]"
    assert loop["rt"] == "ReadOnly[LoopRtSection]"
    assert annotations(typed.LoopRtSection)["cpu"] == "ReadOnly[int | None]"
    assert annotations(typed.DriverSection)["clock"] == "ReadOnly[Literal['virtual', 'real'] | None]"
    assert annotations(typed.DriverSection)["name"] == "ReadOnly[str]"  # backends are entry points
    assert annotations(typed.DropTestSection)["currents_a"] == "ReadOnly[tuple[float, ...]]"
    assert annotations(typed.RunConfig)["controller"] == "ReadOnly[Mapping[str, Any]]"  # a law's own keys


def test_a_resolved_config_refuses_a_write_at_run_time() -> None:
    config = resolve(ConfigSource(), "drop-test")
    with pytest.raises(TypeError, match="read-only"):
        config["loop"]["rate_hz"] = 500.0  # type: ignore[typeddict-readonly-mutated]


def test_mypy_holds_code_to_the_types(tmp_path: Path) -> None:
    api = pytest.importorskip("mypy.api")
    # the generated module on its own (it imports only typing), so mypy reads it alone
    shutil.copy(ROOT / "src" / "sashil" / "config" / "typed.py", tmp_path / "config_types.py")
    snippet = tmp_path / "uses_config.py"
    snippet.write_text(
        textwrap.dedent(
            """
            from config_types import RunConfig

            def reads(config: RunConfig) -> float:
                return config["loop"]["rate_hz"] * config["rig"]["current_max_a"]

            def misspelt(config: RunConfig) -> float:
                return config["loop"]["rate"]

            def wrong_kind(config: RunConfig) -> str:
                return config["loop"]["rate_hz"]

            def writes(config: RunConfig) -> None:
                config["loop"]["rate_hz"] = 500.0
            """
        ),
        encoding="utf-8",
    )
    no_config = tmp_path / "mypy.ini"
    no_config.write_text("[mypy]\n", encoding="utf-8")
    out, err, status = api.run(
        [
            str(snippet),
            str(tmp_path / "config_types.py"),
            "--config-file",
            str(no_config),
            "--cache-dir",
            str(tmp_path / "cache"),
            "--no-error-summary",
            "--hide-error-context",
        ]
    )
    errors = [line for line in out.splitlines() if ": error:" in line]
    lines = sorted(int(line.split(":")[1]) for line in errors)
    assert status == 1, err
    assert lines == [8, 11, 14], out  # the misspelt key, the float returned as str, the write; not the reads
    assert any('"rate"' in line for line in errors)
    assert any("ReadOnly" in line for line in errors)
