"""An engineer's image that breaks the firmware interface: one clear line naming the step,
the address and the symbol, exit 1 (a run that failed) or 2 (an image that cannot run);
nothing hangs."""

from __future__ import annotations

import re

import pytest

from hil.cli import main

from .conftest import host_elf

HEAD = '#include <stdint.h>\n#include "eha_hil.h"\nint main(void) { return 0; }\n'
STEP = HEAD + "void TIM2_IRQHandler(void) {}\nvoid eha_hil_step(void)\n{\n%s\n}\n"


def _run(capsys, elf, *extra: str) -> tuple[int, list[str]]:
    code = main(["run", "f5", "--mcu-image", str(elf), *extra])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("eha-hil")]
    return code, err


@pytest.mark.parametrize("body, pattern", [
    ("*(volatile uint32_t *)0x30000000u;",
     r"step 0 \(t = 0\.0000 s\): bus fault: read of 0x30000000 \(unmapped, 4 bytes\) at PC "
     r"0x080\w+ \(eha_hil_step\+0x\w+\)"),
    ("*(volatile uint32_t *)0x08000000u = 1;",
     r"step 0 .*: bus fault: write to read-only 0x08000000 \(flash.*\(eha_hil_step"),
    ("((volatile uint16_t *)EHA_UP(0))[0] = 1;",
     r"step 0 .*: bus fault: write to 0x60000040 \(DPRAM board 0 up word 0x00 \(status\), "
     r"2 bytes\), which the firmware interface does not allow, at PC 0x\w+ \(eha_hil_step"),
    ("*(volatile uint16_t *)(EHA_DPRAM_BASE + 0x24);",
     r"step 0 .*: bus fault: read of 0x60000024 \(DPRAM board 0 reserved word 0x02"),
    ("__builtin_trap();",
     r"step 0 .*: hard fault: undefined instruction .* at PC 0x\w+ \(eha_hil_step"),
    ("uint32_t a, b; __asm__ volatile(\"ldrd %0, %1, [%2]\" : \"=r\"(a), \"=r\"(b)"
     " : \"r\"(0x20000002u));",
     r"step 0 .*: usage fault: unaligned 4-byte access to 0x20000002 .* at PC 0x\w+ "
     r"\(eha_hil_step"),
    ("((void (*)(void))0x40000001u)();",
     r"step 0 .*: hard fault: instruction fetch from 0x40000000 \(TIM2..TIM5\), which is not "
     r"executable, branched to from 0x\w+ \(eha_hil_step"),
    ("for (;;) {}",
     r"step 0 .*: did not return within 10 periods \(336,000 estimated cycles, .*\); PC "
     r"0x\w+ \(eha_hil_step"),
    ("for (volatile int k = 0; k < 5000; k++) {}",
     r"step 0 .*: overrun: \d{2},\d{3} estimated cycles = \d+\.\d us > the 200 us period at "
     r"168 MHz"),
])
def test_a_broken_step_fails_the_run_with_one_line(capsys, make_image, body, pattern):
    code, err = _run(capsys, make_image(STEP % body))
    assert code == 1
    assert len(err) == 1, err
    assert re.search(pattern, err[0]), err[0]
    assert err[0].startswith("eha-hil run f5: mcu image ")  # the one form: eha-hil VERB: what


def test_a_fault_at_boot_names_the_boot(capsys, make_image):
    code, err = _run(capsys, make_image(
        "#include <stdint.h>\nint main(void) { return *(volatile int *)0x50000000u; }\n"
        "void TIM2_IRQHandler(void) {}\n"))
    assert code == 1 and len(err) == 1
    assert re.search(r"boot: bus fault: read of 0x50000000 .* at PC 0x\w+ \(main", err[0])


NO_ENTRY = """#include <stdint.h>
extern uint32_t _estack;
void Reset_Handler(void) { for (;;) __asm__ volatile("wfi"); }
__attribute__((section(".isr_vector"), used)) static void (*const vectors[45])(void) = {
    (void (*)(void))(&_estack), Reset_Handler,
};
"""


def test_an_image_without_a_5khz_entry_is_refused(capsys, make_image):
    elf = make_image(NO_ENTRY, startup=False)
    with pytest.raises(SystemExit) as exc:
        main(["run", "f5", "--mcu-image", str(elf)])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "no 5 kHz entry: no global function eha_hil_step, and vector 44 (TIM2) is " \
        "0x00000000" in err[0]


def test_an_elf_for_another_architecture_is_refused(capsys, tmp_path):
    elf = host_elf(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["run", "f5", "--mcu-image", str(elf)])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a 32-bit little-endian ARM image" in err[0]


def test_a_file_that_is_no_elf_is_refused(capsys, tmp_path):
    bad = tmp_path / "firmware.elf"
    bad.write_bytes(b"\x7fELF-but-not-really" * 4)
    with pytest.raises(SystemExit) as exc:
        main(["run", "f5", "--mcu-image", str(bad)])
    assert exc.value.code == 2
    assert "not an ELF file" in capsys.readouterr().err
