"""The rig emulator: the interface board of the SAS rig, simulated, speaking the sashil protocols.

``device`` holds the board's logic (pure, simulated time), ``transports`` its links (serial or SLCAN
on a pty, python-can's virtual bus), ``runner`` the real-time loop that joins them (a process via
``sashil emulate``, or a thread in tests), ``truth`` the plant's true state per sample sent.
"""

from sashil.drivers.emulator.device import Faults, Operator, RigDevice
from sashil.drivers.emulator.runner import Emulator, EmulatorThread, build_device
from sashil.drivers.emulator.truth import TRUTH_COLUMNS, TruthLog, read_truth_csv

__all__ = [
    "TRUTH_COLUMNS",
    "Emulator",
    "EmulatorThread",
    "Faults",
    "Operator",
    "RigDevice",
    "TruthLog",
    "build_device",
    "read_truth_csv",
]
