"""Flash and RAM use of the firmware's ELF (``make -C drivers/firmware cortex-m4`` prints them).

A small reader of ELF32 little-endian files (the section headers and the symbol table; the System V
ABI's ELF format, with ARM's e_machine 40), so that no binutils for ARM are needed: flash is every
allocated section with contents (the vector table, code, constants, and the initial values of
.data, which are stored in flash), RAM every allocated section that lies in SRAM (.data, .bss, the
stack). Run as a script: ``python elf.py FILE.elf`` prints one line.
"""

from __future__ import annotations

import struct
import sys
from dataclasses import dataclass
from pathlib import Path

SHF_ALLOC = 0x2
SHT_NOBITS = 8
SHT_SYMTAB = 2
EM_ARM = 40
FLASH = (0x0800_0000, 1024 * 1024)
SRAM = (0x2000_0000, 128 * 1024)


@dataclass(frozen=True)
class Section:
    name: str
    kind: int
    flags: int
    address: int
    offset: int
    size: int


@dataclass(frozen=True)
class Elf:
    machine: int
    entry: int
    sections: tuple[Section, ...]
    symbols: dict[str, int]
    data: bytes

    def word_at(self, address: int) -> int:
        """The 32-bit little-endian word stored at ``address`` (in a section with contents)."""
        for s in self.sections:
            if s.kind != SHT_NOBITS and s.flags & SHF_ALLOC and s.address <= address < s.address + s.size:
                at = s.offset + address - s.address
                return int(struct.unpack_from("<I", self.data, at)[0])
        raise ValueError(f"no contents at 0x{address:08x}")

    def flash_bytes(self) -> int:
        return sum(s.size for s in self.sections if s.flags & SHF_ALLOC and s.kind != SHT_NOBITS)

    def ram_bytes(self) -> int:
        start, size = SRAM
        return sum(s.size for s in self.sections if s.flags & SHF_ALLOC and start <= s.address < start + size)


def read_elf(path: str | Path) -> Elf:
    """Parse an ELF32 little-endian file; ValueError naming the file if it is not one."""
    data = Path(path).read_bytes()
    if data[:4] != b"\x7fELF" or data[4] != 1 or data[5] != 1:
        raise ValueError(f"{path}: not an ELF32 little-endian file")
    (machine, _version, entry, _phoff, shoff, _flags, _ehsize, _phentsize, _phnum, shentsize, shnum, shstrndx) = (
        struct.unpack_from("<HIIIIIHHHHHH", data, 18)
    )
    raw = [struct.unpack_from("<IIIIIIIIII", data, shoff + i * shentsize) for i in range(shnum)]
    names = raw[shstrndx]

    def name_at(table_offset: int, index: int) -> str:
        end = data.index(b"\0", table_offset + index)
        return data[table_offset + index : end].decode("ascii", "replace")

    sections = tuple(Section(name_at(names[4], r[0]), r[1], r[2], r[3], r[4], r[5]) for r in raw)
    symbols: dict[str, int] = {}
    for r in raw:
        if r[1] == SHT_SYMTAB:
            strtab = raw[r[6]]
            for k in range(r[5] // 16):
                st_name, st_value = struct.unpack_from("<II", data, r[4] + 16 * k)
                if st_name:
                    symbols[name_at(strtab[4], st_name)] = st_value
    return Elf(machine, entry, sections, symbols, data)


def usage_line(elf: Elf) -> str:
    flash, ram = elf.flash_bytes(), elf.ram_bytes()
    return (
        f"flash {flash} B ({100 * flash / FLASH[1]:.1f} % of {FLASH[1] // 1024} KiB), "
        f"RAM {ram} B ({100 * ram / SRAM[1]:.1f} % of {SRAM[1] // 1024} KiB, the 4 KiB stack included)"
    )


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python elf.py FILE.elf")
    try:
        print(f"{sys.argv[1]}: {usage_line(read_elf(sys.argv[1]))}")
    except (OSError, ValueError) as err:
        sys.exit(f"elf.py: {err}")
