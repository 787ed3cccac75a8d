"""The EtherCAT slave controller (ESC) of a joint driver box, as a pure model.

* :mod:`~firmware_model.esc.registers`: register addresses, AL states and status codes;
* :mod:`~firmware_model.esc.sii`: the SII EEPROM image built from a slave description;
* :mod:`~firmware_model.esc.esc`: one ESC (register space, datagram processing with the
  working-counter rules, AL state machine, FMMUs, sync managers, process-data watchdog).

No sockets, no files: the chain (:mod:`hil.fieldbus.esc.chain`) passes frames through.
"""
