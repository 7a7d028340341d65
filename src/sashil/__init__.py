"""sashil: hardware-in-the-loop control of the SAS rig with a rotary MR damper."""

from importlib.metadata import PackageNotFoundError, version

try:  # the one version is pyproject.toml's [project] version, read from the installed metadata
    __version__ = version("sashil")
except PackageNotFoundError:  # pragma: no cover - running from a tree that was never installed
    __version__ = "0+unknown"

from sashil.api import Run, load_run  # the Python API: sashil.load_run(folder)
from sashil.scripting import drop_test, run  # experiments from Python: the CLI's verbs, the same run folder

__all__ = ["Run", "__version__", "drop_test", "load_run", "run"]
