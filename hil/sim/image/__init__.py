"""A Cortex-M4F firmware image in the loop (``--set mcu.impl=image``, ``--mcu-image``):
the ELF runs on Unicorn (QEMU's CPU core, in process) behind the memory map of
``firmware_model/mcu/image/template/eha_hil.h``, with per-step instruction counts and
estimated cycles (docs/mcu.md, "Firmware images in the loop")."""
