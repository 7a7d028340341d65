"""sashil: hardware-in-the-loop control of the SAS rig with a rotary MR damper."""

__version__ = "0.1.0"

from sashil.api import Run, load_run  # the Python API: sashil.load_run(folder)

__all__ = ["Run", "__version__", "load_run"]
