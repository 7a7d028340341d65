"""Every module of sashil imports when it is the first sashil module a program imports.

An import circle can hide while the usual entry points (the CLI, ``sashil.lab``) happen to import
its modules in a working order, then break a tool or a script that starts elsewhere (a model, a
driver). One fresh interpreter imports each module in turn with every ``sashil`` module forgotten
before it, so each is imported first once.
"""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import importlib, pkgutil, sys
import sashil
names = [m.name for m in pkgutil.walk_packages(sashil.__path__, "sashil.") if not m.name.endswith("__main__")]
for name in names:
    for key in [k for k in sys.modules if k == "sashil" or k.startswith("sashil.")]:
        del sys.modules[key]
    try:
        importlib.import_module(name)
    except Exception as err:
        print(f"{name}: {type(err).__name__}: {err}")
print(f"{len(names)} modules")
"""


def test_every_module_imports_first() -> None:
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert lines[-1].endswith(" modules") and int(lines[-1].split()[0]) > 100, done.stdout
    assert lines[:-1] == [], "\n".join(lines[:-1])
