"""Config loading: YAML (a safe loader that refuses duplicate keys), validated against :mod:`sashil.config.sections`."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from sashil.config.frozen import thaw
from sashil.config.schema import defaults, validate
from sashil.config.sections import SCHEMA
from sashil.errors import ConfigError
from sashil.models.registry import check_model

Config = dict[str, Any]

__all__ = ["Config", "apply_params", "dump_config", "load_params", "read_config"]


class _UniqueKeyLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a mapping with the same key twice (YAML says keys are
    unique; PyYAML silently keeps the last, so a doubled ``rate_hz:`` would change a run unseen)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {key!r} given twice (each key once)", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def _read_yaml(path: Path) -> Any:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except UnicodeDecodeError as err:
        at = text_line_of(err.object, err.start)
        raise ConfigError(
            f"{path}: line {at}: byte 0x{err.object[err.start]:02x} is not UTF-8 (save the file as UTF-8)"
        ) from None
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror})") from None
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        line = f" line {mark.line + 1}" if mark is not None else ""
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise ConfigError(f"{path}:{line}: not valid YAML ({problem})") from None


def text_line_of(data: bytes, offset: int) -> int:
    """The 1-based line number of byte ``offset`` in ``data``."""
    return data.count(b"\n", 0, offset) + 1


def read_config(path: str | Path | None = None) -> Config:
    """Read a config file, validated against the schema; ``None`` gives the default config. The law
    in it and its parameters are checked where the config is resolved
    (:func:`sashil.engine.resolve.load_config`), by the laws' own declarations.

    A config may name a parameter file with ``include_params: FILE`` (relative to the config),
    which replaces its ``model`` section, as ``--params`` does on the command line.
    """
    if path is None:
        return defaults(SCHEMA)
    path = Path(path)
    doc = _read_yaml(path)
    include = None
    if isinstance(doc, dict) and "include_params" in doc:
        doc = dict(doc)
        include = doc.pop("include_params")
        if not isinstance(include, str):
            raise ConfigError(f"{path}: include_params: expected a file name, got {include!r}")
    config = validate(doc, SCHEMA, str(path))
    if include is not None:
        config = apply_params(config, (path.parent / include))
    return config


def load_params(path: str | Path) -> dict[str, Any]:
    """Load a parameter file (the shape ``sashil identify`` writes) as a ``model`` section."""
    path = Path(path)
    doc = _read_yaml(path)
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: expected a mapping with 'model' and 'params', got {type(doc).__name__}")
    if "params" not in doc:
        raise ConfigError(f"{path}: params: missing (expected a mapping of model parameters)")
    name = doc.get("model", "bouc-wen")
    section = {"name": name, "params": doc["params"]}

    return check_model(section, str(path), "", complete=True)


def apply_params(config: Config, params_path: str | Path) -> Config:
    """A copy of ``config`` whose model section comes from a parameter file."""
    out = copy.deepcopy(config)
    out["model"] = load_params(params_path)
    return out


def dump_config(config: Mapping[str, Any]) -> str:
    """The resolved config as YAML text (what a run folder's ``config.yaml`` holds)."""
    return yaml.safe_dump(thaw(config), sort_keys=False, default_flow_style=False)
