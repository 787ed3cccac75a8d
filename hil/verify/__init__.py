"""Bit-exactness of the firmware models against builds we did not write in Python: the MCU
law as C (host compiler, Cortex-M4 image under QEMU) and the current loop as RTL (Icarus
Verilog under cocotb)."""
