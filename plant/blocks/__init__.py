"""The plant's physics as blocks a motor engineer recognises, summed by
:func:`plant.kernel.derivatives`: :mod:`~plant.blocks.inverter` (average-value legs, dead
time), :mod:`~plant.blocks.motor_dq` (surface-magnet machine in the dq frame),
:mod:`~plant.blocks.pump` (trochoid ripple, pump friction), :mod:`~plant.blocks.hydraulics`
(leakage damper and series elasticity k_s(x)), :mod:`~plant.blocks.load` (piston, rod,
cart, end stops), :mod:`~plant.blocks.thermal` (oil temperature, viscosity, energy books).

Each block is compiled (numba, inlined into the kernel) and works on the flat arrays of
:mod:`plant.layout`. :mod:`plant.reference` is the readable linear model beside them.

:data:`TICK` are the compile options of the per-tick path (``kernel.derivatives``,
``rk4_tick``, ``outputs``, ``advance``, ``load.end_stops``): no reference counting. Each
block takes the state, parameter, input and derivative arrays, and every array passed into
an inlined block was an atomic increment and decrement of the array's reference count,
four RK4 stages a tick: with the blocks split out of one function the plant alone ran
1.3x slower per RK4 step (CPU time, paired runs; ``docs/architecture.md``). The per-tick
path allocates nothing, so it needs no runtime: compiled without it (numba's ``_nrt``
option), an allocation there is a compile error rather than a slowdown.
"""

#: numba options of the per-tick functions: cached, no runtime reference counting.
TICK = {"cache": True, "_nrt": False}
