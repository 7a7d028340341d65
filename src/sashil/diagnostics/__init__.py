"""``sashil doctor``'s checks: the machine, the port and the board, each a row of a table.

A :class:`Check` says ``ok``, ``warn`` or ``fail``, what was found, and the one command or setting
that fixes it. The machine and port checks read sysfs and procfs from roots a test can replace
(:mod:`.machine`, :mod:`.port`); the jitter measurement (:mod:`.jitter`) and the board checks
(:mod:`.board`) run on the real clock.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

OK, WARN, FAIL = "ok", "warn", "fail"
STATUSES = (OK, WARN, FAIL)


@dataclass
class Check:
    """One row of the doctor's table."""

    group: str  # "machine" | "port" | "board"
    name: str
    status: str  # OK | WARN | FAIL
    found: str
    fix: str = ""
    data: dict[str, Any] = field(default_factory=dict)  # numbers for --json (a histogram, RTT figures)

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "group": self.group,
            "name": self.name,
            "status": self.status,
            "found": self.found,
            "fix": self.fix,
        }
        if self.data:
            out["data"] = self.data
        return out


def exit_code(checks: list[Check]) -> int:
    """0 when no check failed, 1 otherwise."""
    return 1 if any(check.status == FAIL for check in checks) else 0


def table(checks: list[Check]) -> str:
    """The checks as a text table: status, group/name, what was found, and the fix beneath."""
    width = max((len(f"{c.group}/{c.name}") for c in checks), default=0)
    lines = []
    for c in checks:
        lines.append(f"{c.status.upper():<4}  {f'{c.group}/{c.name}':<{width}}  {c.found}")
        if c.fix and c.status != OK:
            lines.append(f"{'':<4}  {'':<{width}}  fix: {c.fix}")
    return "\n".join(lines)


__all__ = ["FAIL", "OK", "STATUSES", "WARN", "Check", "exit_code", "table"]
