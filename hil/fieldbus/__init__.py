"""The fieldbus: an EtherCAT-style process image between the PC (master) and the chain of
joint driver boxes (slaves), over any transport of :mod:`hil.transports`.

* :mod:`~hil.fieldbus.topology`: the chain from a TOML file (Table 6.4 by default);
* :mod:`~hil.fieldbus.pdo`: the process data of each slot, declared once;
* :mod:`~hil.fieldbus.chain`: the slaves (logical windows, LRW, working counters);
* :mod:`~hil.fieldbus.master`: the master (frames, WKC check, image);
* :mod:`~hil.fieldbus.boxes`: what runs behind a slave (full stack or a behavioural echo);
* :mod:`~hil.fieldbus.system`: master + transport + chain in lockstep at 1 kHz;
* :mod:`~hil.fieldbus.esc.chain`: the boxes as EtherCAT slaves (one ESC model each) for a
  real master on raw Ethernet (docs/ethercat-slaves.md).
"""

from firmware_model import jit_cache  # noqa: F401  (before any kernel is defined)
