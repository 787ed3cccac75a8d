"""The MCU law's records (``mcu_input`` in, ``mcu_output`` out) through a firmware image:
what the harness writes into the process data and the DPRAM before a cycle and reads back
after it. Used by the stack (hil/sim/image/stack.py) and by ``verify mcu --against image``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from firmware_model.mcu.c_abi import OUTPUT
from hil.sim.image import build, cost
from hil.sim.image import memory_map as M
from hil.sim.image.elf import Image, load
from hil.sim.image.emulator import ImageCore
from hil.sim.image.errors import ImageFault
from hil.sim.image.profile import Profile

#: ``eha_rx`` of eha_hil.h.
RX = np.dtype([("tick", "<i4"), ("flags", "<u4"), ("mode", "<u4"), ("value", "<f4"),
               ("kp_position", "<f4"), ("kp_force", "<f4"), ("angle_offset", "<u4"),
               ("reserved", "<u4")])
_DOWN = OUTPUT.fields["down"][1] + OUTPUT.fields["down"][0].itemsize
#: ``eha_tx``: ``mcu_output`` from ``status`` on.
TX = np.dtype({"names": list(OUTPUT.names[1:]),
               "formats": [OUTPUT.fields[n][0] for n in OUTPUT.names[1:]],
               "offsets": [OUTPUT.fields[n][1] - _DOWN for n in OUTPUT.names[1:]],
               "itemsize": OUTPUT.itemsize - _DOWN})
_RX_FIELDS = ("tick", "flags", "mode", "value", "kp_position", "kp_force", "angle_offset")
_UP, _DOWN_W = slice(0x20, 0x40), slice(0x00, 0x10)
assert RX.itemsize == M.RX_BYTES and TX.itemsize <= M.TX_BYTES


def image_path(path: str | Path | None) -> Path:
    """``path``, or the project's image built from firmware_model/mcu/c (cached)."""
    return Path(path) if path else build.law_image()


class ImageLaw:
    """An image booted with the calibration record ``config`` (``mcu_config``)."""

    def __init__(self, path: str | Path | None, config: np.ndarray,
                 label: str | None = None) -> None:
        self.image: Image = load(image_path(path))
        self.core = ImageCore(self.image, np.asarray(config).tobytes())
        self.profile = Profile(label or self.image.path.name)
        self._rx = self.core.rx.view(RX)[0:1]
        self._tx = self.core.tx[:TX.itemsize].view(TX)[0:1]
        self._dpram = self.core.dpram
        self._dpram[_DOWN_W] = np.asarray(config)["down_init"]  # the FPGA's boot values
        self._tx_names = TX.names

    def step(self, rec: np.ndarray, out: np.ndarray, label: str) -> int:
        """One cycle: ``rec`` in, ``out`` filled; the step's estimated cycles. ImageFault
        if the image breaks the interface or overruns its period."""
        rx = self._rx
        for name in _RX_FIELDS:
            rx[name] = rec[name]
        self._dpram[_UP] = rec["up"]
        self.core.link_counters[0] = rec["up_crc_errors"]
        instructions, cycles = self.core.step(label)
        self.profile.add(instructions, cycles, label)
        out["down"] = self._dpram[_DOWN_W]
        tx = self._tx
        for name in self._tx_names:
            out[name] = tx[name][0]
        if cycles > cost.PERIOD_CYCLES:
            raise ImageFault(f"{label}: overrun: {cycles:,} estimated cycles = "
                             f"{cycles / cost.CLOCK_HZ * 1e6:.1f} us > the "
                             f"{cost.PERIOD_S * 1e6:.0f} us period at "
                             f"{cost.CLOCK_HZ / 1e6:.0f} MHz ({instructions:,} instructions)")
        return cycles

    def run(self, inputs: np.ndarray) -> np.ndarray:
        """Every record of ``inputs`` in turn; the outputs."""
        out = np.zeros(len(inputs), dtype=OUTPUT)
        for k in range(len(inputs)):
            self.step(inputs[k], out[k], f"step {k}")
        return out
