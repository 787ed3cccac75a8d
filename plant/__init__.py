"""The physics of the actuator, its sensors as physical parts, the configuration."""

from firmware_model import jit_cache  # noqa: F401  (before any kernel is defined)
