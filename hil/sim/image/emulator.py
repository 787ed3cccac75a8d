"""One firmware image on Unicorn's Cortex-M4: the memory map of the firmware interface,
the boot from the reset vector, and one call of the 5 kHz entry per MCU cycle, with its
instruction count and estimated cycles (hil/sim/image/cost.py) and every way an image can
break the interface turned into one :class:`ImageFault` line (step, address, PC, symbol).

Per cycle the harness writes the process data in (RX) and the link's upstream words into
the DPRAM, calls the entry with LR = a return address of its own on the stack main left
(as the NVIC would, without stacking a frame main would need again: thread mode never
resumes after boot), and reads the downstream words and process data out. The DPRAM and
process-data pages are numpy arrays Unicorn maps directly, so no copies go through calls."""

from __future__ import annotations

import ctypes
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import unicorn
from unicorn import Uc, UcError
from unicorn import arm_const as A
from unicorn import unicorn_const as U

from firmware_model.mcu import dpram
from hil.sim.image import build, cost
from hil.sim.image import memory_map as M
from hil.sim.image.elf import Image
from hil.sim.image.errors import ImageFault

FAULT_READ, FAULT_WRITE, FAULT_BUDGET, FAULT_PENDING, FAULT_UNALIGNED = 1, 2, 3, 4, 5
#: A step is stopped (the image "never returns") past this many periods of cycles.
RUNAWAY_PERIODS = 10
BOOT_INSTRUCTIONS = 5_000_000
PENDING_CAP = 1 << 16
WFI = b"\x30\xbf"
_PERMS = {"r": U.UC_PROT_READ, "w": U.UC_PROT_WRITE, "x": U.UC_PROT_EXEC}


class _Prof(ctypes.Structure):
    """``eha_prof`` of hooks.c, field for field."""

    _fields_ = [
        ("emu_stop", ctypes.c_void_p), ("reg_read", ctypes.c_void_p),
        ("code_base", ctypes.c_uint32), ("code_halfwords", ctypes.c_uint32),
        ("cost", ctypes.c_void_p), ("count", ctypes.c_void_p), ("span", ctypes.c_void_p),
        ("strict_reg", ctypes.c_void_p),
        ("strict_off", ctypes.c_void_p),
        ("branch_penalty", ctypes.c_uint32), ("budget_cycles", ctypes.c_uint64),
        ("fsmc_extra_half", ctypes.c_uint32), ("fsmc_extra_word", ctypes.c_uint32),
        ("pending", ctypes.c_void_p), ("pending_cap", ctypes.c_uint32),
        ("instructions", ctypes.c_uint64), ("cycles", ctypes.c_uint64),
        ("taken", ctypes.c_uint32), ("fsmc_accesses", ctypes.c_uint32),
        ("n_pending", ctypes.c_uint32), ("next_pc", ctypes.c_uint32),
        ("last_pc", ctypes.c_uint32),
        ("fault", ctypes.c_uint32), ("fault_addr", ctypes.c_uint32),
        ("fault_size", ctypes.c_uint32), ("fault_pc", ctypes.c_uint32),
    ]


class _Window(ctypes.Structure):
    """``eha_window`` of hooks.c: one MMIO page of the external bus."""

    _fields_ = [("memory", ctypes.c_void_p), ("rules", ctypes.c_void_p),
                ("base", ctypes.c_uint32), ("bytes", ctypes.c_uint32),
                ("prof", ctypes.c_void_p)]


#: Instructions whose data address must be word aligned on the Cortex-M4 (else an
#: UNALIGNED UsageFault); PUSH/POP and VPUSH/VPOP use SP, which is always aligned.
_STRICT = frozenset({"ldrd", "strd", "ldm", "ldmdb", "stm", "stmdb", "vldr", "vstr",
                     "vldmia", "vldmdb", "vstmia", "vstmdb", "ldrex", "strex"})
_UC_REG = {"sb": "r9", "sl": "r10", "fp": "r11", "ip": "r12"}


def _uc_register(name: str) -> int:
    return getattr(A, f"UC_ARM_REG_{_UC_REG.get(name, name).upper()}")


def _alignment_rule(insn) -> tuple[int, int]:  # noqa: ANN001 - capstone.CsInsn
    """(Unicorn register id of the base, offset) of an instruction that needs aligned
    data; (0, 0) for the others and for PC-relative literals (aligned by construction)."""
    if insn.insn_name() not in _STRICT:
        return 0, 0
    arm = cost.capstone.arm
    for op in insn.operands:
        if op.type == arm.ARM_OP_MEM:
            if op.mem.base in (0, arm.ARM_REG_PC):
                return 0, 0
            post = insn.writeback and len([o for o in insn.operands if o.type == arm.ARM_OP_IMM])
            return _uc_register(insn.reg_name(op.mem.base)), 0 if post else op.mem.disp
    base = insn.operands[0]  # LDM/STM: the base register comes first
    if base.type == arm.ARM_OP_REG and insn.reg_name(base.reg) != "sp":
        return _uc_register(insn.reg_name(base.reg)), 0
    return 0, 0


@dataclass
class CostTable:
    """Per halfword of flash, for the instruction starting there: its cycles, the
    instructions and bytes it stands for (1 and its size; an IT instruction: itself and its
    block, inside which Unicorn calls the code hook only now and then; an instruction inside
    a block: 0 instructions), and its alignment rule (span 0: no instruction starts there);
    from a linear disassembly of every function the ELF names."""

    cost: np.ndarray
    count: np.ndarray
    span: np.ndarray
    strict_reg: np.ndarray
    strict_off: np.ndarray

    @classmethod
    def of(cls, image: Image) -> CostTable:
        n = M.FLASH_SIZE // 2
        table = cls(np.zeros(n, dtype=np.uint16), np.zeros(n, dtype=np.uint8),
                    np.zeros(n, dtype=np.uint8), np.zeros(n, dtype=np.int16),
                    np.zeros(n, dtype=np.int16))
        for start, code in image.function_code():
            insns = list(cost._MD.disasm(code, start))
            members = 0  # instructions of the current IT block still to come
            for k, insn in enumerate(insns):
                h = (insn.address - M.FLASH_BASE) >> 1
                if members:
                    members -= 1
                    table.span[h] = insn.size  # an instruction, charged with its IT
                    continue
                members = _it_length(insn)
                block = insns[k:k + 1 + members]
                table.cost[h] = sum(cost.instruction_cycles(i) for i in block)
                table.count[h] = len(block)
                table.span[h] = block[-1].address + block[-1].size - insn.address
                table.strict_reg[h], table.strict_off[h] = _alignment_rule(insn)
        return table


def _it_length(insn) -> int:  # noqa: ANN001 - capstone.CsInsn
    """How many instructions an IT instruction makes conditional (``itte``: 3); 0 for any
    other instruction."""
    name = insn.mnemonic.split(".")[0]
    if insn.insn_name() != "it" or not name.startswith("it"):
        return 0
    return len(name) - 1  # "it" + one letter per further instruction


def _uclib() -> ctypes.CDLL:
    lib = Path(unicorn.__file__).parent / "lib" / "libunicorn.so.2"
    return ctypes.CDLL(str(lib))


class ImageCore:
    """The image ``image`` with calibration record ``cal`` (bytes) in the flash block."""

    def __init__(self, image: Image, cal: bytes, boards: int = 1) -> None:
        self.image = image
        self.step_index = 0
        uc = self.uc = Uc(U.UC_ARCH_ARM, U.UC_MODE_THUMB | U.UC_MODE_MCLASS)
        uc.ctl_set_cpu_model(A.UC_CPU_ARM_CORTEX_M4)
        # The FSMC pages: numpy memory behind the MMIO callbacks of hooks.c.
        self._dpram_page = np.zeros(M.PAGE, dtype=np.uint8)
        self._pd_page = np.zeros(M.PAGE, dtype=np.uint8)
        for _name, base, size, perms in M.REGIONS:
            p = 0
            for ch in perms:
                p |= _PERMS[ch]
            if base not in (M.DPRAM_BASE, M.RX_BASE):  # the FSMC pages are MMIO (hooks.c)
                uc.mem_map(base, size, p)
        for base, data in image.segments:
            uc.mem_write(base, data)
        uc.mem_write(M.CAL_BASE, struct.pack("<4I", M.CAL_MAGIC, M.CAL_VERSION, len(cal),
                                             boards) + cal)
        uc.mem_write(M.RETURN_ADDRESS, b"\x00\xbf" * 8)  # never executed: the stop address
        # Views the harness reads and writes every cycle.
        self.dpram = self._dpram_page[:2 * dpram.DPRAM_WORDS].view("<u2")
        off = M.LINK_COUNTERS - M.DPRAM_BASE
        self.link_counters = self._dpram_page[off:off + M.LINK_COUNTERS_BYTES].view("<u4")
        self.rx = self._pd_page[:M.RX_BYTES]
        self.tx = self._pd_page[M.TX_BASE - M.RX_BASE:M.TX_BASE - M.RX_BASE + M.TX_BYTES]
        self._install_hooks()
        self._invalid: tuple[int, int, int] | None = None
        uc.hook_add(U.UC_HOOK_MEM_INVALID, self._on_invalid)
        self.boot_sp = self._boot()

    # --- set-up --------------------------------------------------------------------------------
    def _install_hooks(self) -> None:
        self.costs = CostTable.of(self.image)
        self._rules = (M.dpram_rules(), M.pd_rules())
        self._pending = np.zeros(2 * PENDING_CAP, dtype=np.uint32)
        lib = ctypes.CDLL(str(build.hooks_library()))
        uclib = _uclib()

        def fn(name: str) -> int | None:
            return ctypes.cast(getattr(uclib, name), ctypes.c_void_p).value

        p = self.prof = _Prof()
        p.emu_stop, p.reg_read = fn("uc_emu_stop"), fn("uc_reg_read")
        p.code_base, p.code_halfwords = M.FLASH_BASE, M.FLASH_SIZE // 2
        c = self.costs
        p.cost, p.strict_reg = c.cost.ctypes.data, c.strict_reg.ctypes.data
        p.count, p.span = c.count.ctypes.data, c.span.ctypes.data
        p.strict_off = c.strict_off.ctypes.data
        p.branch_penalty = cost.BRANCH_PENALTY
        p.budget_cycles = 2**63
        p.fsmc_extra_half, p.fsmc_extra_word = cost.FSMC_HALF, cost.FSMC_WORD
        p.pending, p.pending_cap = self._pending.ctypes.data, PENDING_CAP
        w = self._windows = (_Window * 2)()
        for k, (page, rules, base) in enumerate(((self._dpram_page, self._rules[0],
                                                  M.DPRAM_BASE),
                                                 (self._pd_page, self._rules[1], M.RX_BASE))):
            w[k].memory, w[k].rules = page.ctypes.data, rules.ctypes.data
            w[k].base, w[k].bytes = base, M.PAGE
        lib.eha_install.restype = ctypes.c_int
        err = lib.eha_install(ctypes.c_void_p(self.uc._uch.value),
                              ctypes.c_void_p(fn("uc_hook_add")),
                              ctypes.c_void_p(fn("uc_mmio_map")), ctypes.byref(p),
                              U.UC_HOOK_CODE, w, 2)
        if err:
            raise RuntimeError(f"unicorn refused the image hooks (error {err})")
        self._lib = lib  # keep the hooks' code loaded as long as the engine

    def _on_invalid(self, uc: Uc, access: int, address: int, size: int, value: int,
                    user: object) -> bool:
        self._invalid = (access, address, size)
        return False

    def _clear(self) -> None:
        p = self.prof
        p.instructions = p.cycles = 0
        p.taken = p.fsmc_accesses = p.n_pending = p.next_pc = p.last_pc = 0
        p.fault = p.fault_addr = p.fault_size = p.fault_pc = 0
        self._invalid = None

    def _boot(self) -> int:
        """Run from the reset vector until the image waits for interrupts; its SP."""
        uc = self.uc
        uc.reg_write(A.UC_ARM_REG_SP, self.image.initial_sp)
        uc.reg_write(A.UC_ARM_REG_LR, M.RETURN_ADDRESS | 1)
        self._clear()
        self._run(self.image.reset, BOOT_INSTRUCTIONS, "boot")
        pc = uc.reg_read(A.UC_ARM_REG_PC)
        if pc != M.RETURN_ADDRESS and bytes(uc.mem_read(pc - 2, 2)) != WFI:
            raise ImageFault(f"boot: the reset handler neither reached WFI nor returned within "
                             f"{BOOT_INSTRUCTIONS:,} instructions; PC {self.image.where(pc)}")
        return uc.reg_read(A.UC_ARM_REG_SP) & ~7

    # --- running -------------------------------------------------------------------------------
    def _run(self, start: int, count: int, what: str) -> None:
        try:
            self.uc.emu_start(start, M.RETURN_ADDRESS, count=count)
        except UcError as exc:
            raise ImageFault(self._describe_error(exc, what)) from None
        p = self.prof
        if p.fault:
            raise ImageFault(self._describe_fault(what))

    def _describe_error(self, exc: UcError, what: str) -> str:
        pc = self.prof.last_pc or self.uc.reg_read(A.UC_ARM_REG_PC)
        where = self.image.where(pc)
        inv = self._invalid
        e = exc.errno
        if inv is not None and e in (U.UC_ERR_READ_UNMAPPED, U.UC_ERR_WRITE_UNMAPPED,
                                     U.UC_ERR_FETCH_UNMAPPED, U.UC_ERR_WRITE_PROT,
                                     U.UC_ERR_READ_PROT, U.UC_ERR_FETCH_PROT):
            access, address, size = inv
            kind = {U.UC_MEM_READ_UNMAPPED: "read of", U.UC_MEM_WRITE_UNMAPPED: "write to",
                    U.UC_MEM_FETCH_UNMAPPED: "instruction fetch from",
                    U.UC_MEM_WRITE_PROT: "write to read-only", U.UC_MEM_READ_PROT:
                    "read of unreadable", U.UC_MEM_FETCH_PROT:
                    "instruction fetch from non-executable"}.get(access, "access to")
            if e == U.UC_ERR_FETCH_UNMAPPED or e == U.UC_ERR_FETCH_PROT:
                return (f"{what}: bus fault: {kind} 0x{address:08X} "
                        f"({M.describe(address)}), branched to from {where}")
            return (f"{what}: bus fault: {kind} 0x{address:08X} ({M.describe(address)}, "
                    f"{size} bytes) at PC {where}")
        if e == U.UC_ERR_INSN_INVALID:
            return (f"{what}: hard fault: undefined instruction or invalid state (e.g. an "
                    f"ARM-mode branch target) at PC {where}")
        if e == U.UC_ERR_EXCEPTION:
            target = self.uc.reg_read(A.UC_ARM_REG_PC)
            if not self._executable(target):
                return (f"{what}: hard fault: instruction fetch from 0x{target:08X} "
                        f"({M.describe(target)}), which is not executable, branched to from "
                        f"{where}")
            return f"{what}: hard fault: unhandled CPU exception (SVC, BKPT, ...) at PC {where}"
        return f"{what}: the emulator stopped: {exc} at PC {where}"

    @staticmethod
    def _executable(address: int) -> bool:
        return any(base <= address < base + size and "x" in perms
                   for _, base, size, perms in M.REGIONS)

    def _describe_fault(self, what: str) -> str:
        p = self.prof
        at = self.image.where(p.fault_pc)
        if p.fault in (FAULT_READ, FAULT_WRITE):
            verb = "read of" if p.fault == FAULT_READ else "write to"
            return (f"{what}: bus fault: {verb} 0x{p.fault_addr:08X} "
                    f"({M.describe(p.fault_addr)}, {p.fault_size} bytes), which the firmware "
                    f"interface does not allow, at PC {at}")
        if p.fault == FAULT_UNALIGNED:
            return (f"{what}: usage fault: unaligned {p.fault_size}-byte access to "
                    f"0x{p.fault_addr:08X} by an instruction that needs alignment, at PC {at}")
        if p.fault == FAULT_BUDGET:
            return (f"{what}: did not return within {RUNAWAY_PERIODS} periods "
                    f"({p.budget_cycles:,} estimated cycles, {p.instructions:,} "
                    f"instructions); PC {at}")
        return f"{what}: more than {PENDING_CAP} blocks outside the cost table; PC {at}"

    def step(self, label: str) -> tuple[int, int]:
        """One call of the 5 kHz entry (the harness has written RX and the DPRAM); its
        (instructions, estimated cycles)."""
        uc = self.uc
        self._clear()
        p = self.prof
        p.budget_cycles = RUNAWAY_PERIODS * cost.PERIOD_CYCLES
        uc.reg_write(A.UC_ARM_REG_SP, self.boot_sp)
        uc.reg_write(A.UC_ARM_REG_LR, M.RETURN_ADDRESS | 1)
        self._run(self.image.entry, RUNAWAY_PERIODS * cost.PERIOD_CYCLES, label)
        instructions, cycles = p.instructions, p.cycles
        if p.n_pending:
            instructions, cycles = self._price_pending(instructions, cycles)
        return instructions, cycles + cost.BRANCH_PENALTY  # the call into the entry

    def _price_pending(self, instructions: int, cycles: int) -> tuple[int, int]:
        pend = self._pending[:2 * self.prof.n_pending].reshape(-1, 2)
        blocks, counts = np.unique(pend, axis=0, return_counts=True)
        for (addr, size), n in zip(blocks.tolist(), counts.tolist(), strict=True):
            c = cost.block_cost(bytes(self.uc.mem_read(addr, size)), addr)
            cycles += n * (c.cycles - 1)  # the hook counted the instruction, at 1 cycle
        return instructions, cycles
