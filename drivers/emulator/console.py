"""The host's console as the emulated operator reads it: the hold prompts a person would read.

``sashil calibrate`` says before every attempt of a step, first or repeated, which angle to press
the arm to (:func:`sashil.drivers.operator_prompt.hold_prompt`), and it says so before it
connects. Where the host's console (its stderr) goes to a file, :class:`HostConsole` reads the
lines added since its last look and keeps the angle of the last hold prompt among them: the
emulated operator holds the arm where the host asked, whatever the board saw of the link. The board
learns nothing new (no message on the wire): this is the operator's eyes, test equipment beside
the board, as a person at the bench is.
"""

from __future__ import annotations

import os
from pathlib import Path

from sashil.drivers.operator_prompt import prompted_hold_deg


class HostConsole:
    """Reads ``path`` (the host's console, written as it runs) from where it left off.

    Only whole lines count (a line being written is read at the next look). A file that shrank
    was started again (a new host run writing it afresh): it is read from its start. A file not
    there yet holds no prompt."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._offset = 0
        self._partial = b""
        self.hold_deg: float | None = None  # the angle of the last hold prompt read

    def latest_hold_deg(self) -> float | None:
        """The angle [deg] of the last hold prompt the console has said so far, or None."""
        try:
            with open(self.path, "rb") as handle:
                size = os.fstat(handle.fileno()).st_size
                if size < self._offset:
                    self._offset, self._partial, self.hold_deg = 0, b"", None
                handle.seek(self._offset)
                added = handle.read(size - self._offset)
        except FileNotFoundError:
            return self.hold_deg
        self._offset += len(added)
        text = self._partial + added
        whole, _, self._partial = text.rpartition(b"\n")
        angle = prompted_hold_deg(whole.decode("utf-8", errors="replace"))
        if angle is not None:
            self.hold_deg = angle
        return self.hold_deg
