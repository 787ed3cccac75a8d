"""The boxes as EtherCAT slave controllers (one ESC model each) for a real master on raw
Ethernet: the chain, what each slave says about itself (SII, ESI), serving it on an
interface, a minimal in-process master, SOEM in a network namespace (docs/ethercat-slaves.md)."""
