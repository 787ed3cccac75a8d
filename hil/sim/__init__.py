"""The engines: what advances simulated time. The integer-tick scheduler, one actuator's
stack (plant, driver board, LVDS link, MCU), the whole robot in one compiled engine, the hip
joint through the whole stack, the PC loops, the MCU law's C build the engines can run
instead of the Python model, and the warm-up that compiles the kernels once."""

from firmware_model import jit_cache  # noqa: F401  (before any kernel is defined)
