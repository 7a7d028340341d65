"""The RT-DAC/USB2's register map files, read and checked: one YAML file per FPGA logic, saying at
which words of the board's frame each block sits (the header, digital I/O, PWM, encoder counters,
A/D and D/A). :mod:`sashil.drivers.rtdac_map` builds its register maps of these values and chooses
one from the board's header.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from sashil.errors import ConfigError

__all__ = ["read_map_file"]

#: each block of a map file and its keys
BLOCKS: dict[str, tuple[str, ...]] = {
    "header": ("logic_version", "application", "synthesis_date", "module_counts"),
    "digital_io": ("pin_mode", "direction", "output", "input"),
    "pwm": ("count", "base", "stride"),
    "encoder": ("count", "reset", "index_active", "index_invert", "counter_base", "stride"),
    "ad": ("count", "gain_base", "value_base"),
    "da": ("count", "base"),
}


def _word(value: Any, where: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ConfigError(f"{where}: expected an integer from {low} to {high}, got {value!r}")
    return value


def read_map_file(path: Path, frame_words: int) -> dict[str, Any]:
    """The values of one map file, by the register map's field names, each word address checked to
    lie in a frame of ``frame_words`` words: a wrong key is one line naming the file and the key."""
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f"{path}: cannot read the register map ({err})") from None
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: expected a mapping of the register map's blocks")
    where = str(path)
    known = {"logic_version", "applications", "evidence", *BLOCKS}
    for key in doc:
        if key not in known:
            raise ConfigError(f"{where}: {key}: unknown key (known: {', '.join(sorted(known))})")
    values: dict[str, Any] = {
        "logic_version": _word(doc.get("logic_version"), f"{where}: logic_version", 0, 0xFFFF),
        "source": path.name,
        "evidence": str(doc.get("evidence", "")),
    }
    apps = doc.get("applications")
    if apps is not None and not (isinstance(apps, list) and all(isinstance(a, str) for a in apps)):
        raise ConfigError(f"{where}: applications: expected a list of names or null, got {apps!r}")
    values["applications"] = None if apps is None else tuple(a.strip() for a in apps)
    for block, keys in BLOCKS.items():
        section = doc.get(block)
        if not isinstance(section, dict):
            raise ConfigError(f"{where}: {block}: expected a mapping with {', '.join(keys)}")
        for key in keys:
            if key not in section:
                raise ConfigError(f"{where}: {block}.{key}: missing")
        if block == "header":
            continue  # the header's words are fixed by the frame (rtdac_codec.decode_header)
        prefix = {"digital_io": ""}.get(block, block + "_")
        for key in keys:
            name = {"counter_base": "base"}.get(key, key) if block == "encoder" else key
            low = 1 if key in ("count", "stride") else 0
            values[prefix + name] = _word(section[key], f"{where}: {block}.{key}", low, frame_words - 1)
    return values
