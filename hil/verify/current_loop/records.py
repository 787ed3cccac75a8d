"""The current loop's ports packed into the testbench buses of ``tb_current_loop.v`` (one
write and one read per cycle through the simulator interface), and back."""

from __future__ import annotations

import numpy as np

from firmware_model.fpga.current_loop import (
    INPUT_PORTS,
    INPUT_WIDTHS,
    LOOP_OUTPUT,
    OUTPUT_PORTS,
    OUTPUT_WIDTHS,
)


def pack_inputs(inputs: np.ndarray) -> list[int]:
    """Each input record as one integer, the ports' bits side by side (LSB first)."""
    words = [0] * len(inputs)
    shift = 0
    for name in INPUT_PORTS:
        width = INPUT_WIDTHS[name]
        col = (inputs[name].astype(np.int64) & ((1 << width) - 1)).tolist()
        words = [w | (v << shift) for w, v in zip(words, col, strict=True)]
        shift += width
    return words


def unpack_outputs(words: list[int]) -> np.ndarray:
    """The inverse for the output bus: one :data:`LOOP_OUTPUT` record per integer."""
    out = np.zeros(len(words), dtype=LOOP_OUTPUT)
    shift = 0
    for name, signed in OUTPUT_PORTS.items():
        width = OUTPUT_WIDTHS[name]
        mask, top = (1 << width) - 1, 1 << (width - 1)
        col = [(w >> shift) & mask for w in words]
        if signed:
            col = [v - (top << 1) if v & top else v for v in col]
        out[name] = col
        shift += width
    return out
