"""Reading a firmware ELF for the harness: the checks an engineer's image must pass before
it runs (32-bit little-endian ARM executable, loadable segments inside flash and SRAM, a
vector table, a 5 kHz entry), each failure one line naming the file and what is wrong."""

from __future__ import annotations

import struct
from bisect import bisect_right
from dataclasses import dataclass, field
from pathlib import Path

from elftools.common.exceptions import ELFError
from elftools.elf.elffile import ELFFile

from hil.sim.image import memory_map as M
from hil.sim.image.errors import ImageError

EM_ARM = 40


@dataclass
class Image:
    path: Path
    segments: list[tuple[int, bytes]]          # (physical address, bytes) to load
    initial_sp: int
    reset: int
    entry: int                                 # the 5 kHz entry (Thumb bit set)
    entry_name: str
    functions: list[tuple[int, int, str]] = field(default_factory=list)  # (start, size, name)
    _starts: list[int] = field(default_factory=list)

    def symbol(self, address: int) -> str | None:
        """``name+0xoff`` of the function holding ``address``, if the ELF names one."""
        a = address & ~1
        k = bisect_right(self._starts, a) - 1
        if k >= 0:
            start, size, name = self.functions[k]
            if start <= a < start + max(size, 2):
                return f"{name}+0x{a - start:X}" if a != start else name
        return None

    def where(self, address: int) -> str:
        sym = self.symbol(address)
        return f"0x{address:08X}" + (f" ({sym})" if sym else "")

    def function_code(self) -> list[tuple[int, bytes]]:
        """(start, bytes) of every function in flash, for the cost table."""
        out = []
        for start, size, _ in self.functions:
            if size and M.FLASH_BASE <= start < M.FLASH_BASE + M.FLASH_SIZE:
                out.append((start, self.read(start, size)))
        return out

    def read(self, address: int, size: int) -> bytes:
        for base, data in self.segments:
            if base <= address and address + size <= base + len(data):
                return data[address - base:address - base + size]
        return b""


def _inside(base: int, size: int) -> bool:
    for name, rbase, rsize, _ in M.REGIONS:
        if name in ("flash", "SRAM", "CCM RAM") and rbase <= base and base + size <= rbase + rsize:
            return True
    return False


def load(path: str | Path) -> Image:
    """Read and check ``path``; ImageError (one line) if it cannot run here."""
    path = Path(path)
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise ImageError(f"{path}: {exc.strerror}") from None
    with f:
        try:
            elf = ELFFile(f)
            machine = elf["e_machine"]
            if elf.elfclass != 32 or not elf.little_endian or machine not in ("EM_ARM", EM_ARM):
                raise ImageError(f"{path}: an ELF for {machine} "
                                 f"({elf.elfclass}-bit), not a 32-bit little-endian ARM image")
            if elf["e_type"] != "ET_EXEC":
                raise ImageError(f"{path}: {elf['e_type']}, not a linked "
                                 "executable (link it with eha_hil.ld)")
            segments = []
            for seg in elf.iter_segments():
                if seg["p_type"] != "PT_LOAD" or not seg["p_filesz"]:
                    continue
                base, data = seg["p_paddr"], seg.data()
                if not _inside(base, len(data)):
                    raise ImageError(f"{path}: a segment at 0x{base:08X} "
                                     f"({len(data)} bytes) lies outside flash and SRAM")
                if base < M.CAL_BASE + M.PAGE * 32 and base + len(data) > M.CAL_BASE:
                    raise ImageError(f"{path}: a segment at 0x{base:08X} overlaps "
                                     f"the calibration block at 0x{M.CAL_BASE:08X}")
                segments.append((base, data))
            functions = []
            symtab = elf.get_section_by_name(".symtab")
            names: dict[str, int] = {}
            if symtab is not None:
                for s in symtab.iter_symbols():
                    if s["st_info"]["type"] == "STT_FUNC" and s.name:
                        functions.append((s["st_value"] & ~1, s["st_size"], s.name))
                        if s["st_info"]["bind"] == "STB_GLOBAL":
                            names[s.name] = s["st_value"]
        except ELFError as exc:
            raise ImageError(f"{path}: not an ELF file ({exc})") from None
    functions.sort()
    img = Image(path, segments, 0, 0, 0, "", functions, [f[0] for f in functions])
    vectors = img.read(M.FLASH_BASE, 4 * (M.TIM2_VECTOR + 1))
    if len(vectors) < 8:
        raise ImageError(f"{path}: no vector table at 0x{M.FLASH_BASE:08X} "
                         "(put .isr_vector first in flash, as eha_hil.ld does)")
    img.initial_sp, img.reset = struct.unpack_from("<2I", vectors)
    if not (M.SRAM_BASE < img.initial_sp <= M.SRAM_BASE + M.SRAM_SIZE
            or M.CCM_BASE < img.initial_sp <= M.CCM_BASE + M.CCM_SIZE):
        raise ImageError(f"{path}: initial stack pointer 0x{img.initial_sp:08X} "
                         "(vector 0) is not in SRAM or CCM RAM")
    if not img.reset & 1 or not _inside(img.reset & ~1, 2):
        raise ImageError(f"{path}: reset vector 0x{img.reset:08X} is not a Thumb "
                         "address in flash or SRAM")
    if M.STEP_SYMBOL in names:
        img.entry, img.entry_name = names[M.STEP_SYMBOL] | 1, M.STEP_SYMBOL
    else:
        tim2 = struct.unpack_from("<I", vectors, 4 * M.TIM2_VECTOR)[0] \
            if len(vectors) >= 4 * (M.TIM2_VECTOR + 1) else 0
        if not tim2 & 1 or not _inside(tim2 & ~1, 2):
            raise ImageError(f"{path}: no 5 kHz entry: no global function "
                             f"{M.STEP_SYMBOL}, and vector {M.TIM2_VECTOR} (TIM2) is "
                             f"0x{tim2:08X}, not a Thumb address in flash")
        img.entry, img.entry_name = tim2, img.symbol(tim2) or f"vector {M.TIM2_VECTOR} (TIM2)"
    return img
