"""One cycle of the driver board's current loop as records: the input words the RTL's ports
take and every output word it gives (``firmware_model/fpga/rtl/current_loop.v``)."""

from __future__ import annotations

import numpy as np

#: Input ports (all unsigned words as the ports carry them; enable is 1 bit).
INPUT_PORTS = ("enable", "ia_code", "ib_code", "theta_e", "iq_ref", "id_ref", "vq_ff",
               "current_limit", "kp", "ki")
LOOP_INPUT = np.dtype([(name, "<i8") for name in INPUT_PORTS])

#: Output ports: name -> signed? (the signed ones are read as two's complement).
OUTPUT_PORTS = {"sin_q15": True, "cos_q15": True, "i_alpha": True, "i_beta": True,
                "i_d": True, "i_q": True, "v_d": True, "v_q": True, "q_lim": False,
                "v_alpha": True, "v_beta": True, "count_a": False, "count_b": False,
                "count_c": False, "integ_d_next": True, "integ_q_next": True}
LOOP_OUTPUT = np.dtype([(name, "<i8") for name in OUTPUT_PORTS])

#: Port widths in bits (``tb_current_loop.v`` packs the ports in this order, LSB first).
INPUT_WIDTHS = {"enable": 1, "ia_code": 12, "ib_code": 12, "theta_e": 16, "iq_ref": 16,
                "id_ref": 16, "vq_ff": 16, "current_limit": 16, "kp": 16, "ki": 16}
OUTPUT_WIDTHS = {name: 16 for name in OUTPUT_PORTS} | {
    "q_lim": 15, "count_a": 11, "count_b": 11, "count_c": 11, "integ_d_next": 32,
    "integ_q_next": 32}


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
