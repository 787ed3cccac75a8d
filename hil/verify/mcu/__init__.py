"""The Python MCU model against the MCU law's C, built for the host and for the Cortex-M4F
under QEMU (``eha-hil verify mcu``)."""
