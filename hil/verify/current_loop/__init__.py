"""The board model's current loop against its RTL under Icarus Verilog and cocotb
(``eha-hil verify current-loop``); ``testbench.py`` is the cocotb testbench the simulator runs."""
