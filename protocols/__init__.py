"""Pure, bit-exact codecs for every link of the Hydra EHA electronics.

Values <-> bits/bytes only: no timing, no I/O, no models. Device side (what a sensor or
slave sends) and master side (what the FPGA, MCU or PC decodes) both live here.
"""
