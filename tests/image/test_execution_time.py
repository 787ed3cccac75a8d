"""The execution-time model on code whose count is known by construction: a hand-written
step whose instructions, taken branches, flash literals and external-bus accesses are
counted here from the Cortex-M4 TRM's timings, not from hil/sim/image/cost.py. (The literals
are addresses no MOV immediate can hold, so the assembler keeps them in flash. The IT block
matters: Unicorn calls no code hook inside one, so its instructions are charged with the IT
and the return after it must not look like a taken branch.)"""

from __future__ import annotations

import numpy as np

from firmware_model.mcu.c_abi import INPUT, OUTPUT, config_record
from hil.sim.image.law import ImageLaw
from plant.config import load_config

KNOWN = r"""
    .syntax unified
    .thumb
    .text
    .global main
    .type main, %function
main:
    movs r0, #0
    bx lr
    .global TIM2_IRQHandler
    .type TIM2_IRQHandler, %function
TIM2_IRQHandler:
    bx lr
    .global eha_hil_step
    .type eha_hil_step, %function
eha_hil_step:
    movs r0, #4
1:  subs r0, #1
    bne 1b
    vadd.f32 s0, s0, s1
    vdiv.f32 s0, s0, s1
    ldr r1, =0x20000010
    ldr r2, [r1]
    ldr r3, =0x60000002
    ldrh r2, [r3, #0x3e]
    strh r2, [r3, #-2]
    ldr r2, [r3, #-2]
    cmp r0, #0
    ite eq
    moveq r1, #1
    movne r1, #2
    bx lr
    .ltorg
    .size eha_hil_step, .-eha_hil_step
"""

# Cycles, Cortex-M4 TRM table 3-1 and FPv4-SP table 7-1, 168 MHz with 5 flash wait
# states; a taken branch refills the pipeline (2) from flash (5); an FSMC transfer takes
# 6 HCLK instead of 2 (16 bit) or two of them (32 bit).
BRANCH = 2 + 5
EXPECTED_INSTRUCTIONS = 1 + 4 + 4 + 1 + 1 + 1 + 1 + 1 + 1 + 1 + 1 + 4 + 1
EXPECTED_CYCLES = (BRANCH            # the call into the entry
                   + 1               # movs
                   + 4 * 1           # subs, four times
                   + 4 * 1 + 3 * BRANCH  # bne: four times, taken three times
                   + 1 + 14          # vadd, vdiv
                   + 2 + 5 + 2       # literal load from flash, load from SRAM
                   + 2 + 5           # literal load
                   + 2 + 4           # ldrh from the DPRAM over the FSMC
                   + 2 + 4           # strh to the DPRAM
                   + 2 + 10          # ldr (32 bit) from the DPRAM: two transfers
                   + 1 + 1 + 1 + 1   # cmp, ite, and both conditional moves (one skipped:
                   #                   charged in full, the model's upper bound)
                   + 1)              # bx lr (the harness stops at the return address)


def test_a_known_step_costs_what_the_trm_says(make_image):
    elf = make_image(KNOWN, suffix=".S")
    law = ImageLaw(elf, config_record(load_config(None, ())))
    rec, out = np.zeros((), INPUT), np.zeros((), OUTPUT)
    for k in range(3):  # the same cost every step: nothing depends on the first call
        law.step(rec, out, f"step {k}")
    assert law.profile.instructions == [EXPECTED_INSTRUCTIONS] * 3
    assert law.profile.cycles == [EXPECTED_CYCLES] * 3


def test_the_law_s_profile_is_within_the_period_and_varies_with_the_path(law_image):
    """The law's image over a few hundred steps of the F5 stack: every step counted, well
    inside 200 us, and not one constant (the paths differ: enable, limits, strain)."""
    from hil.verify.mcu.steps import random_inputs

    law = ImageLaw(law_image, config_record(load_config(None, ())))
    law.run(random_inputs(300, 3))
    s = law.profile.summary()
    assert s["steps"] == 300
    assert 300 < s["instructions_mean"] < s["instructions_max"] < 5000
    assert s["period_share_max"] < 0.5
    assert len(set(law.profile.cycles)) > 10
