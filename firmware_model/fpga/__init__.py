"""The motor driver board's MachXO2 FPGA: fixed-point FOC, PI current loop, sensor masters,
LVDS endpoint and protections, at the 20 kHz PWM rate (thesis 5.3, 6.3.1).

Every signal is an integer of declared width; ``docs/fpga.md`` has the Q-format table.
"""
