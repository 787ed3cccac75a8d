"""The driver board's current loop as one block with ports, for the RTL of
``firmware_model/fpga/rtl/current_loop.v``: the port records (the words its inputs take,
every output word it gives) and the board model's loop on them
(:func:`firmware_model.fpga.tick.control_tick`, current mode: the same
:mod:`firmware_model.fpga.foc` calls in the same order, with the board's constants; a test
compares the two tick by tick)."""

from __future__ import annotations

import numpy as np
from numba import njit

from firmware_model.calibration import FirmwareCalibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.fixed import clamp, mul_shift, sat_s, wrap_s
from firmware_model.fpga.foc import clarke, inv_park, park, pi_step, q_limit, sin_cos, svpwm
from firmware_model.fpga.params import board_params

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

_IN = {name: k for k, name in enumerate(INPUT_PORTS)}
(E, IA, IB, TH, IQR, IDR, VQFF, ILIM, KP, KI) = (_IN[n] for n in INPUT_PORTS)
_OUT = {name: k for k, name in enumerate(OUTPUT_PORTS)}
O_ID, O_IQ, O_VD, O_VQ = _OUT["i_d"], _OUT["i_q"], _OUT["v_d"], _OUT["v_q"]
O_COUNT_A, O_INTEG_D, O_INTEG_Q = _OUT["count_a"], _OUT["integ_d_next"], _OUT["integ_q_next"]


@njit(cache=True)
def loop_outputs(c, enable, ia_code, ib_code, theta_e, iq_ref_w, id_ref_w, vq_ff_w,
                 current_limit, kp, ki, integ_d, integ_q):
    """One cycle of the loop: the output ports (:data:`OUTPUT_PORTS` order) for the input
    words and the integrators the last edge stored; ``c`` the board's constants."""
    top = c[B.C_PWM_TOP]
    v_lim = c[B.C_V_LIMIT]
    i_a = (ia_code - c[B.C_ADC_MID]) << c[B.C_ADC_SHIFT]
    i_b = (ib_code - c[B.C_ADC_MID]) << c[B.C_ADC_SHIFT]
    i_alpha, i_beta = clarke(i_a, i_b)
    s, co = sin_cos(theta_e)
    i_d, i_q = park(i_alpha, i_beta, s, co)
    v_d = v_q = q_lim = v_alpha = v_beta = 0
    d_a = d_b = d_c = top >> 1
    if enable != 0:
        i_lim = min(mul_shift(current_limit, c[B.C_MA_TO_I], 15), 32767)
        iq_ref = clamp(mul_shift(wrap_s(iq_ref_w, 16), c[B.C_MA_TO_I], 15), -i_lim, i_lim)
        id_ref = clamp(mul_shift(wrap_s(id_ref_w, 16), c[B.C_MA_TO_I], 15), -i_lim, i_lim)
        ff = sat_s(mul_shift(wrap_s(vq_ff_w, 16), c[B.C_MV_TO_V], 15), 16)
        v_d, integ_d = pi_step(id_ref - i_d, integ_d, kp, c[B.C_KP_SHIFT], ki,
                               c[B.C_KI_SHIFT], 0, v_lim)
        q_lim = q_limit(v_d, v_lim)
        v_q, integ_q = pi_step(iq_ref - i_q, integ_q, kp, c[B.C_KP_SHIFT], ki,
                               c[B.C_KI_SHIFT], ff, q_lim)
        v_alpha, v_beta = inv_park(v_d, v_q, s, co)
        d_a, d_b, d_c = svpwm(v_alpha, v_beta, top)
    else:
        integ_d = 0
        integ_q = 0
    return (s, co, i_alpha, i_beta, i_d, i_q, v_d, v_q, q_lim, v_alpha, v_beta, d_a, d_b,
            d_c, integ_d, integ_q)


@njit(cache=True)
def _run(x: np.ndarray, c: np.ndarray, out: np.ndarray) -> None:
    integ_d = 0
    integ_q = 0
    for k in range(x.shape[0]):
        row = loop_outputs(c, x[k, E], x[k, IA], x[k, IB], x[k, TH], x[k, IQR], x[k, IDR],
                           x[k, VQFF], x[k, ILIM], x[k, KP], x[k, KI], integ_d, integ_q)
        for j in range(len(row)):
            out[k, j] = row[j]
        integ_d = row[O_INTEG_D]
        integ_q = row[O_INTEG_Q]


def run_model(cal: FirmwareCalibration, inputs: np.ndarray) -> np.ndarray:
    """One output record per input record, the integrators starting at zero."""
    x = np.stack([inputs[name] for name in INPUT_PORTS], axis=1).astype(np.int64)
    flat = np.zeros((len(inputs), len(OUTPUT_PORTS)), dtype=np.int64)
    _run(x, board_params(cal), flat)
    out = np.zeros(len(inputs), dtype=LOOP_OUTPUT)
    for j, name in enumerate(OUTPUT_PORTS):
        out[name] = flat[:, j]
    return out
