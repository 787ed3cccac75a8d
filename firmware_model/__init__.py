"""What runs on the boards: the driver board's FPGA, the LVDS link's endpoints, the MCU."""

from firmware_model import jit_cache  # noqa: F401  (before any kernel is defined)
