"""Every benchmark of the harness (``eha-hil bench ...``): the engines (plant, board, stack,
robot, hip joint), the codecs, the bus and its EtherCAT slave chain, the frame log, what
logging costs, and the sweep's process pool. Figures are ratios and rates with CPU time
beside wall time; no test asserts a timing."""

from firmware_model import jit_cache  # noqa: F401  (before any kernel is defined)
