"""The plant's physics as blocks a motor engineer recognises, summed by
:func:`plant.kernel.derivatives`: :mod:`~plant.blocks.inverter` (average-value legs, dead
time), :mod:`~plant.blocks.motor_dq` (surface-magnet machine in the dq frame),
:mod:`~plant.blocks.pump` (trochoid ripple, pump friction), :mod:`~plant.blocks.hydraulics`
(leakage damper and series elasticity k_s(x)), :mod:`~plant.blocks.load` (piston, rod,
cart, end stops), :mod:`~plant.blocks.thermal` (oil temperature, viscosity, energy books).

Each block is compiled (numba, inlined into the kernel) and works on the flat arrays of
:mod:`plant.layout`. :mod:`plant.reference` is the readable linear model beside them.
"""
