"""The MCU tunables (:mod:`firmware_model.mcu.tunables`) of the robot engine's actuators:
a value written over CoE goes into that actuator's C program state between two engine
steps, computed as the Python program computes it.

Per tuned actuator a Python :class:`~firmware_model.mcu.mcu.Mcu` built from the firmware
calibration takes every write (:func:`tunables.apply`, so a limit written after another sees
it, as on the model), and its float32 constants are copied into the head of the actuator's
``mcu_state`` (:data:`~firmware_model.mcu.c_abi.STATE_HEAD`: the configuration and the gains
in use). The program's other state (filters, integrators, observer) is kept: only the
coefficients change, as on the model. A write before the first step therefore gives the
engine that calibration value from the start, bit for bit.
"""

from __future__ import annotations

import numpy as np

from firmware_model.calibration import calibration
from firmware_model.fpga.driver_board import LinkMemory
from firmware_model.mcu import tunables
from firmware_model.mcu.c_abi import STATE_HEAD, model_config
from firmware_model.mcu.mcu import Mcu
from plant.config import Config

#: The gains in use the program keeps beside its configuration (a write sets them, as the
#: model's ``tunables.apply`` sets the controller's).
_GAINS_IN_USE = {"kp_force": "kp", "position_kp_n_per_m": "k_pos"}


class EngineTunables:
    """The tunables of ``n`` programs whose states lie ``state_size`` bytes apart in
    ``states``; :meth:`tune` takes a write, :meth:`apply` (the engine's thread, no compute
    running) puts the writes taken since into the states."""

    def __init__(self, cfg: Config, states: np.ndarray, state_size: int, n: int) -> None:
        if state_size < STATE_HEAD.itemsize:
            raise RuntimeError(f"the MCU law's state is {state_size} bytes, smaller than "
                               f"its head ({STATE_HEAD.itemsize}): the C build and "
                               "firmware_model/mcu/c_abi.py disagree")
        self.cal = calibration(cfg)
        self.n = n
        self._heads = [states[j * state_size:j * state_size + STATE_HEAD.itemsize]
                       .view(STATE_HEAD) for j in range(n)]
        self._models: dict[int, Mcu] = {}
        self._pending: list[tuple[int, str, float]] = []

    def tune(self, j: int, key: str, value: float) -> None:
        """Tunable ``key`` of actuator ``j`` (chain order) becomes ``value`` at its program's
        next step (the range is the caller's to check: the object dictionary does)."""
        tunables.BY_KEY[key]  # (a KeyError now, not at the step)
        if not 0 <= j < self.n:
            raise IndexError(f"actuator {j}: the engine has {self.n}")
        self._pending.append((j, key, float(value)))

    def apply(self) -> None:
        """The writes taken since the last call, into the program states."""
        for j, key, value in self._pending:
            model = self._models.get(j)
            if model is None:
                model = self._models[j] = Mcu(self.cal, [LinkMemory(self.cal)])
            tunables.apply(model, 0, key, value)
            head = self._heads[j]
            head["cfg"] = model_config(model)
            if key in _GAINS_IN_USE:
                name = _GAINS_IN_USE[key]
                head[name] = head["cfg"][name]
        self._pending.clear()
