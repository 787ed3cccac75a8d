"""The execution-time model: instructions and estimated cycles of Cortex-M4F code at
168 MHz, per instruction class, from the Cortex-M4 Technical Reference Manual's
instruction timings (Table 3-1) and the FPv4-SP timings (Table 7-1), plus flash wait
states. Documented in docs/mcu.md ("Execution time"); the numbers are here once.

Per instruction (cycles): data processing, moves, compares, shifts, IT, MUL 1; MLA/MLS 2;
SDIV/UDIV 12 (the TRM's 2..12, worst case); LDR*/STR* 2, LDRD/STRD 3; LDM/STM/PUSH/POP
1 + N registers; VADD/VSUB/VMUL/VNEG/VABS/VCMP/VCVT/VMOV/VMRS 1; VMLA/VMLS/VNMLA/VFMA 3;
VDIV/VSQRT 14; VLDR/VSTR 2; VPUSH/VPOP/VLDM/VSTM 1 + N single registers. A PC-relative
literal load reads flash: + FLASH_WAIT_STATES.

Per taken branch (a block that does not start where the last one ended): pipeline refill
BRANCH_REFILL + FLASH_WAIT_STATES (the target line fetched from flash; the ART
accelerator's 1 KiB instruction cache is smaller than the law, so it is not counted on).
Per external-bus (FSMC) access to the DPRAM or the process data: FSMC_HALF extra cycles
for a byte or half-word, FSMC_WORD for a word (two 16-bit transfers)."""

from __future__ import annotations

from dataclasses import dataclass

import capstone

CLOCK_HZ = 168_000_000
PERIOD_S = 200e-6
PERIOD_CYCLES = round(CLOCK_HZ * PERIOD_S)   # 33600
FLASH_WAIT_STATES = 5      # FLASH_ACR.LATENCY at 168 MHz, 2.7..3.6 V (RM0090 table 10)
BRANCH_REFILL = 2          # the TRM's P = 1..3
BRANCH_PENALTY = BRANCH_REFILL + FLASH_WAIT_STATES
#: FSMC asynchronous SRAM mode 1 with ADDSET = 1, DATAST = 3 HCLK (a dual-port block RAM
#: in the FPGA answers within 20 ns): 6 HCLK per 16-bit transfer, against 2 for an
#: internal load or store.
FSMC_HALF = 4
FSMC_WORD = 10

_FIXED = {"mla": 2, "mls": 2, "sdiv": 12, "udiv": 12, "ldrd": 3, "strd": 3,
          "vmla": 3, "vmls": 3, "vnmla": 3, "vnmls": 3, "vfma": 3, "vfms": 3, "vfnma": 3,
          "vfnms": 3, "vdiv": 14, "vsqrt": 14, "vldr": 2, "vstr": 2}
_LOADSTORE = ("ldr", "ldrb", "ldrh", "ldrsb", "ldrsh", "ldrex", "ldrexb", "ldrexh", "str",
              "strb", "strh", "strex", "strexb", "strexh", "ldrt", "strt", "ldrbt", "strbt",
              "ldrht", "strht", "ldrsbt", "ldrsht")
_MULTI = ("ldm", "ldmdb", "stm", "stmdb", "push", "pop")
_VMULTI = ("vpush", "vpop", "vldmia", "vldmdb", "vstmia", "vstmdb", "vldm", "vstm")


@dataclass(frozen=True)
class Cost:
    instructions: int
    cycles: int


def _disassembler() -> capstone.Cs:
    md = capstone.Cs(capstone.CS_ARCH_ARM, capstone.CS_MODE_THUMB | capstone.CS_MODE_MCLASS)
    md.detail = True
    return md


_MD = _disassembler()


def instruction_cycles(insn: capstone.CsInsn) -> int:
    """Cycles of one instruction, not counting a taken branch's refill (per block)."""
    name = insn.insn_name()
    if name in _FIXED:
        cycles = _FIXED[name]
    elif name in _LOADSTORE:
        cycles = 2
    elif name in _MULTI:
        regs = [op for op in insn.operands if op.type == capstone.arm.ARM_OP_REG]
        cycles = 1 + len(regs)
    elif name in _VMULTI:
        regs = [insn.reg_name(op.reg) for op in insn.operands
                if op.type == capstone.arm.ARM_OP_REG]
        cycles = 1 + sum(2 if r.startswith("d") else 1 for r in regs)
    elif name == "vmov" and sum(op.type == capstone.arm.ARM_OP_REG
                                for op in insn.operands) >= 3:
        cycles = 2  # two core registers to or from two singles / a double
    else:
        cycles = 1
    if name in ("ldr", "vldr", "ldrd") and any(
            op.type == capstone.arm.ARM_OP_MEM and op.mem.base == capstone.arm.ARM_REG_PC
            for op in insn.operands):
        cycles += FLASH_WAIT_STATES  # a literal from flash
    return cycles


def block_cost(code: bytes, address: int) -> Cost:
    """Instructions and cycles of the straight-line code ``code`` at ``address``."""
    n = c = 0
    for insn in _MD.disasm(code, address):
        n += 1
        c += instruction_cycles(insn)
    return Cost(n, c)
