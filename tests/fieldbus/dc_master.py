"""A distributed-clock set-up as SOEM's config_dc and dcsync0 do it, over the frames of
:class:`hil.fieldbus.esc.master.EscMaster`, for a line of slaves (each one's port 0 towards
the master, port 1 to the next): latch the receive times with a broadcast write to 0x0900,
read them, set each slave's system time offset from its processing-unit receive time and
its delay from the port times, then drift compensation with FRMW on the reference clock's
system time every cycle. Written from the algorithm's description, for tests."""

from __future__ import annotations

import struct

from firmware_model.esc import registers as r
from hil.fieldbus.esc.master import STATION_BASE, EscMaster
from protocols import ethercat as ec

MASTER_TIME = 852_076_800_000_000_000   # 2027-01-01 in ns since 2000-01-01
SYNC_DELAY = 100_000_000                # SOEM: the first SYNC0 100 ms after now


def config_dc(master: EscMaster, n: int) -> list[int]:
    """The delays [ns] it measures (and wrote to 0x0928), slave by slave."""
    d = master.one(ec.Command.BWR, 0, r.DC_RECV_TIME_P0, bytes(4))
    assert d.wkc == n
    port0, port1, delays = [], [], []
    for i in range(n):
        st = STATION_BASE + i
        port0.append(struct.unpack("<i", master.one(ec.Command.FPRD, st, r.DC_RECV_TIME_P0,
                                                    bytes(4)).data)[0])
        pu = struct.unpack("<q", master.one(ec.Command.FPRD, st, r.DC_RECV_TIME_PU,
                                            bytes(8)).data)[0]
        master.one(ec.Command.FPWR, st, r.DC_SYSTEM_OFFSET, struct.pack("<q", MASTER_TIME - pu))
        port1.append(struct.unpack("<i", master.one(ec.Command.FPRD, st, r.DC_RECV_TIME_P1,
                                                    bytes(4)).data)[0])
    delay = 0
    for i in range(n):
        if i:
            rt_parent = port1[i - 1] - port0[i - 1]
            rt_own = port1[i] - port0[i] if i < n - 1 else 0
            delay += (rt_parent - rt_own) // 2
            master.one(ec.Command.FPWR, STATION_BASE + i, r.DC_SYSTEM_DELAY,
                       struct.pack("<I", delay))
        delays.append(delay)
    return delays


def dcsync0(master: EscMaster, i: int, cycle_ns: int, shift_ns: int = 0) -> int:
    """SYNC0 of slave ``i`` every ``cycle_ns`` from the next whole cycle 100 ms ahead;
    the start time written."""
    st = STATION_BASE + i
    master.one(ec.Command.FPWR, st, r.DC_ACTIVATION, b"\x00")
    master.one(ec.Command.FPWR, st, r.DC_CYCLIC_CONTROL, b"\x00")
    t1 = struct.unpack("<q", master.one(ec.Command.FPRD, st, r.DC_SYSTEM_TIME,
                                        bytes(8)).data)[0]
    start = ((t1 + SYNC_DELAY) // cycle_ns) * cycle_ns + cycle_ns + shift_ns
    master.one(ec.Command.FPWR, st, r.DC_START_TIME, struct.pack("<q", start))
    master.one(ec.Command.FPWR, st, r.DC_SYNC0_CYCLE, struct.pack("<I", cycle_ns))
    master.one(ec.Command.FPWR, st, r.DC_ACTIVATION, b"\x03")
    return start


def frmw(master: EscMaster, value: int = 0) -> ec.Datagram:
    """The drift compensation datagram: the reference (slave 0) reads its system time,
    every other slave compares it with its own."""
    return master.one(ec.Command.FRMW, STATION_BASE, r.DC_SYSTEM_TIME, struct.pack("<q", value))
