"""Models of the rig and its damper (pure math, no I/O)."""
