"""The harness: wiring, scheduler, scenarios, fieldbus, transports, logs, the CLI."""

from firmware_model import jit_cache  # noqa: F401  (before any kernel is defined)
