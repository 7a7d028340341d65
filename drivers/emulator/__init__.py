"""The rig emulator: the interface board of the SAS rig, simulated, speaking the sashil protocols.

``device`` holds the board's logic in Python (pure, simulated time) and ``c_board`` the same board
running the firmware's C code (``sashil emulate --board c``), ``transports`` their links (serial or
SLCAN on a pty, python-can's virtual bus) carrying decoded messages or the raw wire (``wire``),
``runner`` the real-time loop that joins them (a process via ``sashil emulate``, or a thread in
tests), ``truth`` the plant's true state per sample sent, ``console`` the host's hold prompts as
the emulated operator reads them.
"""

from sashil.drivers.emulator.console import HostConsole
from sashil.drivers.emulator.device import Faults, Operator, RigDevice
from sashil.drivers.emulator.runner import Emulator, EmulatorThread, build_device
from sashil.drivers.emulator.truth import TRUTH_COLUMNS, TruthLog, read_truth_csv

__all__ = [
    "TRUTH_COLUMNS",
    "Emulator",
    "EmulatorThread",
    "Faults",
    "HostConsole",
    "Operator",
    "RigDevice",
    "TruthLog",
    "build_device",
    "read_truth_csv",
]
