"""Flash and RAM use of Cortex-M4 ELF files, without binutils for ARM (no ``arm-none-eabi-size`` here).

The reader is ``drivers/firmware/elf.py`` (one copy: ELF32 section headers and symbol table read with
``struct``); ``make -C drivers/firmware cortex-m4`` runs that file directly, since the Makefile ships
with the package and ``tools/`` does not. This is the same line for any ELF, from the repository:

    python tools/elf_size.py drivers/firmware/build/cortex-m4/sashil-board.elf
    -> flash 4206 B (0.4 % of 1024 KiB), RAM 5104 B (3.9 % of 128 KiB, the 4 KiB stack included)

    python tools/elf_size.py --quick    # build the firmware into a temporary folder and read that ELF

``--quick`` needs make and the ziglang package (the cross build); without them it says so and exits 0.

Flash: the allocated sections with contents (.isr_vector, .text, .rodata, .ARM.exidx, .data's
initial values); RAM: the allocated sections in SRAM (.data, .bss, .stack). Exit 1 on a file that is
not an ELF32 little-endian file.
"""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from types import ModuleType

ELF_PY = Path(__file__).resolve().parent.parent / "drivers" / "firmware" / "elf.py"


def load_elf_module() -> ModuleType:
    """drivers/firmware/elf.py as a module (by path: the sashil package need not be installed)."""
    spec = importlib.util.spec_from_file_location("sashil_firmware_elf", ELF_PY)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {ELF_PY}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the class is made
    spec.loader.exec_module(module)
    return module


def quick() -> int:
    """``make cortex-m4`` into a temporary folder, then the usage line of the ELF it wrote."""
    if importlib.util.find_spec("ziglang") is None or shutil.which("make") is None:
        print("elf_size: --quick skipped, needs make and the ziglang package (pip install ziglang)")
        return 0
    with tempfile.TemporaryDirectory(prefix="elf_size-") as tmp:
        subprocess.run(
            ["make", "-s", "-C", str(ELF_PY.parent), "cortex-m4", f"PYTHON={sys.executable}", f"BUILD={tmp}"],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        return main([str(Path(tmp) / "cortex-m4" / "sashil-board.elf")])


def main(argv: list[str]) -> int:
    if argv == ["--quick"]:
        return quick()
    if not argv:
        print("usage: python tools/elf_size.py FILE.elf [FILE.elf ...] | --quick", file=sys.stderr)
        return 2
    elf = load_elf_module()
    status = 0
    for name in argv:
        try:
            print(f"{name}: {elf.usage_line(elf.read_elf(name))}")
        except (OSError, ValueError) as err:
            print(f"elf_size: {err}", file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("elf_size", lambda: main(sys.argv[1:])))
