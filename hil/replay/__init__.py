"""Logged runs and bit-exact replay of the MCU firmware model against them.

:func:`~hil.replay.record.run_logged` runs a fieldbus scenario and logs, per box, every
input the MCU model takes (fieldbus outputs each cycle, the upstream LVDS memory and its
CRC-error count each 5 kHz step) and every output it gives (the downstream LVDS registers
after each step, the fieldbus inputs each cycle). :func:`~hil.replay.replay.replay_mcu` feeds
the logged inputs to the current MCU model and reports the first output that differs.
"""

from firmware_model import jit_cache  # noqa: F401  (before any kernel is defined)
