"""The one copy of sashil's version: pyproject.toml reads it at build time (``dynamic``), the
package and ``sashil --version`` at run time, without scanning the installed distributions."""

__version__ = "0.1.0"
