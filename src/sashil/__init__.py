"""sashil: hardware-in-the-loop control of the SAS rig with a rotary MR damper."""

__version__ = "0.1.0"
