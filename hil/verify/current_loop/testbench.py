"""The cocotb testbench of the current loop's RTL: replays the input records given in
``EHA_RTL_VECTORS`` (a .npy of :data:`LOOP_INPUT`) one clock cycle each and writes what every
output port held, before the clock edge, to ``EHA_RTL_OUTPUTS``. The RTL sits in
``tb_current_loop.v``, which connects it by port name: any RTL with the same ports fits. Run
by :mod:`hil.verify.current_loop.rtl`, not by pytest."""

from __future__ import annotations

import os

import cocotb
import numpy as np
from cocotb.triggers import Timer

from hil.verify.current_loop.records import pack_inputs, unpack_outputs


@cocotb.test()
async def replay(dut) -> None:
    vectors = np.load(os.environ["EHA_RTL_VECTORS"])
    words = pack_inputs(vectors)
    clk, in_bus, out_bus = dut.clk, dut.in_bus, dut.out_bus
    clk.value = 0
    dut.rst.value = 1
    in_bus.value = 0
    await Timer(1, "ns")
    clk.value = 1
    await Timer(1, "ns")
    dut.rst.value = 0
    read = []
    half = Timer(1, "ns")
    for w in words:
        clk.value = 0
        in_bus.value = w
        await half
        read.append(out_bus.value.to_unsigned())  # the cycle's outputs, before the edge
        clk.value = 1
        await half
    np.save(os.environ["EHA_RTL_OUTPUTS"], unpack_outputs(read))
