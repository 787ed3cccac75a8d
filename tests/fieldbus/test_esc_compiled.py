"""The compiled frame path (:mod:`firmware_model.esc.compiled`) against the readable chain of
:class:`~firmware_model.esc.esc.Esc` slaves: the same reply bytes, the same memories and
states, the same outputs handed to the boxes, on random sequences of frames (register,
SII, logical, broadcast, misaddressed, truncated, not EtherCAT), box inputs and clock
ticks, and the mailbox: SM0/SM1 configured as mailboxes, requests written, answers read,
repeat requests, the application taking requests and posting answers. And the sync
managers' 3-buffers under writers and readers in two threads."""

from __future__ import annotations

import copy
import struct
import threading

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_model.esc import compiled as cc
from firmware_model.esc import dc_compiled as dcc
from firmware_model.esc import registers as r
from hil.fieldbus.esc.chain import EscChain
from hil.fieldbus.esc.master import EscMaster
from hil.fieldbus.esc.slaves import describe_all
from protocols import ethercat as ec
from tests.fieldbus.test_esc import THREE

MAC_DST, MAC_SRC = b"\xff" * 6, b"\x01\x01\x01\x01\x01\x01"


class Both:
    """The reference chain and the compiled arrays fed the same; every step compared."""

    def __init__(self, cfg, dc=None) -> None:  # noqa: ANN001
        self.ref = EscChain(THREE, cfg, "echo", dc=dc)
        self.ref._hand_outputs = lambda: None  # the outputs are compared, not applied
        self.arr = cc.EscArrays(describe_all(THREE), dc)
        self.buf = np.zeros(2048, dtype=np.uint8)
        for i, esc in enumerate(self.ref.escs):  # the boxes' first inputs, as the chain's
            s = esc.desc.sms[esc.desc.in_sm]
            self.arr.set_inputs(i, bytes(esc.mem[s.start:s.start + esc.desc.in_bytes]))

    def handle(self, frame: bytes) -> bytes | None:
        want = self.ref.handle(frame)
        self.buf[:len(frame)] = np.frombuffer(frame, dtype=np.uint8)
        n = cc.handle_frame(self.buf, len(frame), *self.arr.frame_args())
        got = None if n < 0 else self.buf[:n].tobytes()
        assert got == want, frame.hex()
        if want is None:
            assert n == (cc.DROPPED if self.ref.stats.dropped_frames > self._dropped
                         else cc.NOT_ETHERCAT)
        self._dropped = self.ref.stats.dropped_frames
        self.check()
        return want

    _dropped = 0

    def set_inputs(self, i: int, data: bytes) -> None:
        self.ref.escs[i].set_inputs(data)
        self.arr.set_inputs(i, data)

    def outputs(self) -> None:
        for i, esc in enumerate(self.ref.escs):
            assert self.arr.pending_outputs(i) == esc.pending_outputs()

    def take_mailbox(self, i: int) -> None:
        assert self.arr.take_mailbox(i) == self.ref.escs[i].take_mailbox()

    def post_mailbox(self, i: int, data: bytes) -> None:
        assert self.arr.post_mailbox(i, data) == self.ref.escs[i].post_mailbox(data)

    def tick(self, dt: int) -> None:
        for esc in self.ref.escs:
            esc.tick(dt)
        cc.tick(self.arr.mem, self.arr.st, self.arr.obuf, self.arr.olen, self.arr.oidx, dt)
        self.check()

    def check(self) -> None:
        for i, esc in enumerate(self.ref.escs):
            # The compiled slave takes new inputs when the next datagram reaches it: compare
            # the memory outside a buffer a box may just have published into.
            s = esc.desc.sms[esc.desc.in_sm]
            mem = bytearray(esc.mem)
            got = bytearray(self.arr.mem[i].tobytes())
            if self.arr.iidx[i, cc.B_SHARED] & cc.FRESH:
                mem[s.start:s.start + esc.desc.in_bytes] = bytes(esc.desc.in_bytes)
                got[s.start:s.start + esc.desc.in_bytes] = bytes(esc.desc.in_bytes)
            assert got == mem, f"slave {i}: memories differ"
            assert self.arr.state(i) == (int(esc.state), esc.error, int(esc.code))
            assert self.arr.st[i, cc.S_TRIPS] == esc.watchdog_trips
            assert (self.arr.st[i, cc.S_TRIP_DELAY], self.arr.st[i, cc.S_TRIP_SEEN]) == (
                esc.last_trip_delay_ns, esc.last_trip_seen_ns)
            dc, row = esc.dc, self.arr.st[i]
            assert [int(row[c]) for c in _DC_COLUMNS] == [
                dc.corr_u, dc.l_upd, dc.slew, dc.freq, dc.l_cmp, dc.diff_f, dc.compares,
                dc.errors, dc.last_error, dc.sync_state, dc.sync_start, dc.sync_cycle,
                dc.next_sync0], f"slave {i}: DC state differs"


_DC_COLUMNS = (dcc.D_CORR_U, dcc.D_L_UPD, dcc.D_SLEW, dcc.D_FREQ, dcc.D_L_CMP, dcc.D_DIFF_F,
               dcc.D_COMPARES, dcc.D_ERRORS, dcc.D_LAST_ERROR, dcc.D_SYNC_STATE,
               dcc.D_SYNC_START, dcc.D_SYNC_CYCLE, dcc.D_NEXT_SYNC0)

# --- random traffic -------------------------------------------------------------------------------
_REGS = [r.TYPE, r.STATION_ADDRESS, r.STATION_ALIAS, r.DL_CONTROL, r.DL_STATUS, r.AL_CONTROL,
         r.AL_STATUS, r.AL_STATUS_CODE, r.RX_ERROR, r.WD_DIVIDER, r.WD_TIME_PD,
         r.WD_STATUS_PD, r.WD_COUNTER_PD, r.EEP_CONFIG, r.EEP_CONTROL, r.EEP_ADDRESS,
         r.EEP_DATA, r.FMMU0, r.FMMU0 + 16, r.SM0, r.SM0 + 8, r.DC_START, 0x1000, 0x1020,
         0x1100, 0x1140, 0x1FF8, 0xFFF0, 0x1080, 0x1200, r.SM0 + 5, r.SM0 + 13, r.SM0 + 16,
         r.DC_SYSTEM_TIME, r.DC_RECV_TIME_PU, r.DC_SYSTEM_OFFSET, r.DC_SYSTEM_DELAY,
         r.DC_SPEED_START, r.DC_ACTIVATION, r.DC_START_TIME, r.DC_SYNC0_CYCLE]

ado_st = st.one_of(st.sampled_from(_REGS), st.integers(0, 0xFFFF),
                   st.sampled_from(_REGS).flatmap(lambda a: st.integers(a - 4, a + 4)
                                                  .map(lambda x: x & 0xFFFF)))
adp_st = st.one_of(st.integers(0, 3), st.sampled_from([0xFFFF, 0xFFFE, 0x1001, 0x1002,
                                                       0x1003, 0x1004]),
                   st.integers(0, 0xFFFF))


@st.composite
def datagram_st(draw):  # noqa: ANN001, ANN201
    cmd = draw(st.integers(0, 14))
    n = draw(st.one_of(st.integers(0, 8), st.integers(0, 160)))
    data = draw(st.binary(min_size=n, max_size=n))
    if cmd in (ec.Command.LRD, ec.Command.LWR, ec.Command.LRW):
        lad = draw(st.one_of(st.integers(0, 400), st.integers(0, 0xFFFFFFFF)))
        return ec.Datagram.logical(cmd, lad, data, draw(st.integers(0, 255)),
                                   draw(st.integers(0, 0xFFFF)))
    if draw(st.integers(0, 3)) == 0:  # distributed clocks, as a master sets them up
        return _dc_datagram(draw)
    if cmd in (ec.Command.APWR, ec.Command.APRD) and draw(st.booleans()):
        return draw(mailbox_datagram_st(cmd))
    if cmd == ec.Command.FPWR and draw(st.booleans()):  # the AL and EEPROM commands
        ado = draw(st.sampled_from([r.AL_CONTROL, r.EEP_CONTROL]))
        data = struct.pack("<H", draw(st.sampled_from(
            [1, 2, 3, 4, 8, 0x11, 0x12, 0x14, 0x18, 5, 0x100, 0x200, 0x300, 0x0])))
        return ec.Datagram(cmd, draw(st.integers(0, 255)), draw(adp_st), ado, data)
    return ec.Datagram(cmd, draw(st.integers(0, 255)), draw(adp_st), draw(ado_st), data,
                       draw(st.integers(0, 0xFFFF)), draw(st.integers(0, 0xFFFF)),
                       draw(st.booleans()))


_SYS = 852_076_800_000_000_000  # a system time a master writes (ns since 2000)
_dc_value = {
    r.DC_RECV_TIME_P0: st.just(bytes(4)),
    r.DC_SYSTEM_TIME: st.one_of(st.integers(-10**6, 10**6).map(lambda v: _SYS + v),
                                st.integers(-2**63, 2**63 - 1)).map(lambda v: struct.pack("<q", v)),
    r.DC_SYSTEM_OFFSET: st.one_of(st.integers(-10**6, 10**6).map(lambda v: _SYS + v),
                                  st.integers(-2**63, 2**63 - 1)).map(
                                      lambda v: struct.pack("<q", v)),
    r.DC_SYSTEM_DELAY: st.integers(0, 20_000).map(lambda v: struct.pack("<I", v)),
    r.DC_SPEED_START: st.sampled_from([0x1000, 0x80, 0x7FFF, 0]).map(
        lambda v: struct.pack("<H", v)),
    r.DC_DIFF_FILTER: st.integers(0, 255).map(lambda v: bytes([v])),
    r.DC_CYCLIC_CONTROL: st.sampled_from([0, 1]).map(lambda v: bytes([v])),
    r.DC_ACTIVATION: st.sampled_from([0, 3, 1, 0x23, 7, 0xFF]).map(lambda v: bytes([v])),
    r.DC_START_TIME: st.one_of(
        st.integers(-10**6, 3 * 10**8).map(lambda v: _SYS + v),
        st.integers(-2**63, 2**63 - 1)).map(lambda v: struct.pack("<q", v)),
    r.DC_SYNC0_CYCLE: st.sampled_from([1_000_000, 0, 250_000, 0xFFFFFFFF]).map(
        lambda v: struct.pack("<I", v)),
}


def _dc_datagram(draw):  # noqa: ANN001, ANN202
    ado = draw(st.sampled_from(sorted(_dc_value)))
    data = draw(_dc_value[ado])
    cut = draw(st.sampled_from([len(data)] * 4 + [1, 4, 7]))
    data = data[:cut]
    cmd = draw(st.sampled_from([ec.Command.FPWR, ec.Command.BWR, ec.Command.FRMW,
                                ec.Command.ARMW, ec.Command.FPRD, ec.Command.BRD,
                                ec.Command.APRW]))
    adp = draw(st.sampled_from([0x1001, 0x1002, 0x1003, 0, (-1) & 0xFFFF, (-2) & 0xFFFF]))
    return ec.Datagram(cmd, draw(st.integers(0, 255)), adp, ado, data)


#: The mailbox sync managers as a master programs them (SM0 0x1000 / SM1 0x1080, 128 bytes).
_MBX_SMS = struct.pack("<HHBBBBHHBBBB", 0x1000, 128, 0x26, 0, 1, 0, 0x1080, 128, 0x22, 0, 1, 0)


@st.composite
def mailbox_datagram_st(draw, cmd):  # noqa: ANN001, ANN201
    """Position-addressed mailbox traffic: SM0/SM1 set up, a request written whole (or in
    part, or too long), SM1 read whole or in part, SM status read, repeat request toggled."""
    adp = (-draw(st.integers(0, 2))) & 0xFFFF
    if cmd == ec.Command.APRD:
        ado, n = draw(st.sampled_from([(0x1080, 128), (0x1080, 64), (0x10C0, 64),
                                       (r.SM0 + 5, 1), (r.SM0 + 13, 3), (0x1000, 128)]))
        return ec.Datagram(cmd, 1, adp, ado, bytes(n))
    kind = draw(st.sampled_from(["sms", "sms", "request", "request", "part", "long",
                                 "repeat", "al"]))
    if kind == "sms":
        return ec.Datagram(cmd, 1, adp, r.SM0, _MBX_SMS)
    if kind == "request":
        return ec.Datagram(cmd, 1, adp, 0x1000, draw(st.binary(min_size=128, max_size=128)))
    if kind == "part":
        off = draw(st.integers(0, 127))
        return ec.Datagram(cmd, 1, adp, 0x1000 + off,
                           draw(st.binary(min_size=1, max_size=128 - off)))
    if kind == "long":
        return ec.Datagram(cmd, 1, adp, 0x1000, bytes(140))
    if kind == "repeat":
        return ec.Datagram(cmd, 1, adp, r.SM0 + 13, bytes([0, draw(st.sampled_from([1, 3]))]))
    return ec.Datagram(cmd, 1, adp, r.AL_CONTROL, struct.pack("<H", draw(st.sampled_from(
        [0x11, 0x12, 0x1]))))


@st.composite
def frame_st(draw):  # noqa: ANN001, ANN201
    dgs = draw(st.lists(datagram_st(), min_size=1, max_size=4))
    frame = bytearray(ec.encode_frame(dgs, MAC_DST, MAC_SRC))
    how = draw(st.sampled_from(["ok"] * 6 + ["cut", "pad", "type", "flip", "short"]))
    if how == "cut":
        frame = frame[:draw(st.integers(0, len(frame)))]
    elif how == "pad":
        frame += draw(st.binary(max_size=20))
    elif how == "type":
        frame[12:14] = draw(st.sampled_from([b"\x08\x00", b"\x05\xdc", b"\x88\xa5"]))
    elif how == "flip":
        k = draw(st.integers(14, len(frame) - 1))
        frame[k] ^= 1 << draw(st.integers(0, 7))
    else:
        frame = frame[:draw(st.integers(0, 15))]
    return bytes(frame)


op_st = st.one_of(
    frame_st().map(lambda f: ("frame", f)),
    st.tuples(st.just("inputs"), st.integers(0, 2), st.randoms(use_true_random=False)),
    st.tuples(st.just("tick"), st.sampled_from([1_000, 1_000_000, 20_000_000, 120_000_000])),
    st.just(("outputs",)),
    st.tuples(st.just("take"), st.integers(0, 2)),
    st.tuples(st.just("post"), st.integers(0, 2), st.binary(max_size=140)))


def _run(both: Both, ops: list) -> None:
    for op in ops:
        if op[0] == "frame":
            both.handle(op[1])
        elif op[0] == "inputs":
            esc = both.ref.escs[op[1]]
            both.set_inputs(op[1], op[2].randbytes(esc.desc.in_bytes))
        elif op[0] == "tick":
            both.tick(op[1])
        elif op[0] == "take":
            both.take_mailbox(op[1])
        elif op[0] == "post":
            both.post_mailbox(op[1], op[2])
        else:
            both.outputs()


@given(ops=st.lists(op_st, min_size=1, max_size=25))
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_compiled_path_equals_the_chain_from_reset(cfg, ops):
    _run(Both(cfg), ops)


@pytest.fixture(scope="module")
def brought_up(cfg):  # noqa: ANN001, ANN201
    """A master's bring-up passed through both paths, to OP and to PREOP, each step compared:
    ``{to_op: (Both, EscMaster)}``. The bring-up is the same frames every time, so each
    example starts from a deep copy of it (~0.01 s) instead of repeating it (~0.15 s and
    the same checks, most of these tests' time). The copy holds no reference to the
    original (its arrays are its own): :func:`_from` checks the original is left as it was."""
    pairs = {}
    for to_op in (True, False):
        both = Both(cfg)
        master = EscMaster(both)
        master.bring_up(to_op=to_op)
        pairs[to_op] = (both, master)
    return pairs


def _from(brought_up: dict, to_op: bool, ops: list, cyclic: int = 0) -> None:  # noqa: ANN001
    """Random traffic (after ``cyclic`` LRW cycles) on a copy of the brought-up pair."""
    original = brought_up[to_op][0]
    before = (original.arr.mem.tobytes(), [bytes(e.mem) for e in original.ref.escs])
    both, master = copy.deepcopy(brought_up[to_op])
    for k in range(cyclic):
        master.image[:] = bytes((k + j) & 0xFF for j in range(len(master.image)))
        master.cycle()
        both.outputs()
    _run(both, ops)
    both.outputs()
    assert (original.arr.mem.tobytes(), [bytes(e.mem) for e in original.ref.escs]) == before


@given(ops=st.lists(op_st, min_size=1, max_size=25), cyclic=st.integers(0, 30))
@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_compiled_path_equals_the_chain_in_op(brought_up, ops, cyclic):
    """From OP (a master's whole bring-up passed through both: SII reads, sync managers,
    FMMUs, AL states), cyclic LRW frames with outputs, then random traffic."""
    _from(brought_up, True, ops, cyclic)


mailbox_op_st = st.one_of(
    st.lists(st.sampled_from([ec.Command.APWR, ec.Command.APRD, ec.Command.APRD])
             .flatmap(mailbox_datagram_st), min_size=1, max_size=3)
    .map(lambda dgs: ("frame", ec.encode_frame(dgs, MAC_DST, MAC_SRC))),
    st.tuples(st.just("take"), st.integers(0, 2)),
    st.tuples(st.just("post"), st.integers(0, 2), st.binary(max_size=140)),
    st.tuples(st.just("frame"), st.integers(0, 2).map(lambda k: ec.encode_frame(
        [ec.Datagram(ec.Command.APRD, 1, (-k) & 0xFFFF, 0x1080, bytes(128))],
        MAC_DST, MAC_SRC))),
    op_st)


@given(ops=st.lists(mailbox_op_st, min_size=1, max_size=30))
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_compiled_path_equals_the_chain_in_mailbox_traffic(brought_up, ops):
    """From PREOP with the mailboxes set up (a master's bring-up): requests, answers, partial
    and refused accesses, repeat requests, state changes, interleaved with random traffic."""
    _from(brought_up, False, ops)


def test_mailbox_answers_repeat_and_refusals_equal(cfg):
    """A long answer, then a shorter one (SM1's rest zeroed), a lost read repeated, a
    request written while the last is not taken (refused), equal in both paths."""
    both = Both(cfg)
    EscMaster(both).bring_up(to_op=False)

    def frame(*dgs: ec.Datagram) -> list[ec.Datagram]:
        return ec.decode_frame(both.handle(ec.encode_frame(list(dgs), MAC_DST, MAC_SRC)))

    read = ec.Datagram(ec.Command.APRD, 1, 0, 0x1080, bytes(128))
    write = ec.Datagram(ec.Command.APWR, 1, 0, 0x1000, bytes(range(128)))
    both.post_mailbox(0, b"\x11" * 100)
    assert frame(read)[0].wkc == 1
    assert frame(read)[0].wkc == 0                      # empty now: refused
    both.post_mailbox(0, b"\x22" * 10)
    assert frame(read)[0].data == b"\x22" * 10 + bytes(118)
    frame(ec.Datagram(ec.Command.APWR, 1, 0, r.SM0 + 13, bytes([0, 3])))  # repeat request
    d = frame(read, ec.Datagram(ec.Command.APRD, 1, 0, r.SM0 + 15, bytes(1)))
    assert d[0].wkc == 1 and d[0].data[:10] == b"\x22" * 10 and d[1].data[0] & 2
    assert [d.wkc for d in frame(write, write)] == [1, 0]  # full: the second refused
    both.take_mailbox(0)
    assert frame(write)[0].wkc == 1                     # taken: SM0 free again


# --- 3-buffer ------------------------------------------------------------------------------------
@given(ops=st.lists(st.booleans(), min_size=1, max_size=60))
@settings(max_examples=200, deadline=None)
def test_three_buffer_hand_over_in_any_order(ops):
    """Publishes (True) and takes (False) in any order, one at a time: the three slots stay
    distinct, a take gets the newest record published since the last take (-1 if none), and
    the slot the reader holds is never written until it takes again. Stepped one call at a
    time, so the order that a race reaches only now and then is reached every time."""
    n = 16
    bufs = np.zeros((3, cc.BUF), dtype=np.uint8)
    lens = np.zeros(3, dtype=np.int64)
    idx = np.array([0, 1, 2], dtype=np.int64)
    words = np.zeros(n // 4, dtype=np.uint32)
    published = 0          # records published so far (record k's words all equal k)
    fresh = False          # one was published since the last take
    held: bytes | None = None
    for is_publish in ops:
        if is_publish:
            published += 1
            words[:] = published
            cc.publish(bufs, lens, idx, words.view(np.uint8), n)
            fresh = True
        else:
            slot = cc.take(idx)
            if not fresh:
                assert slot == -1
            else:
                rec = bufs[slot, :lens[slot]].view(np.uint32)
                assert lens[slot] == n and (rec == published).all()
                held = bufs[slot].tobytes()
                fresh = False
        slots = (idx[cc.B_WRITER], idx[cc.B_SHARED] & 3, idx[cc.B_READER])
        assert sorted(slots) == [0, 1, 2]
        assert bool(idx[cc.B_SHARED] & cc.FRESH) == fresh
        if held is not None:
            assert bufs[idx[cc.B_READER]].tobytes() == held


def test_three_buffer_reader_never_sees_a_torn_record():
    """A writer publishes records whose words all equal a counter, as fast as it can; a
    reader in another thread takes them: every record it gets is whole and none older
    than one it had. The Python reader gets only a few of the records between the
    interpreter's switches, so this is the real threads' smoke check; the orders a race
    would reach are stepped through one by one in the test above."""
    n, records = 112, 20_000
    bufs = np.zeros((3, cc.BUF), dtype=np.uint8)
    lens = np.zeros(3, dtype=np.int64)
    idx = np.array([0, 1, 2], dtype=np.int64)
    seen = {"torn": 0, "backwards": 0, "taken": 0, "last": -1}

    def writer() -> None:
        words = np.zeros(n // 4, dtype=np.uint32)
        rec = words.view(np.uint8)
        for k in range(records):
            words[:] = k
            cc.publish(bufs, lens, idx, rec, n)

    def reader() -> None:
        last = -1
        while t.is_alive() or idx[cc.B_SHARED] & cc.FRESH:
            slot = cc.take(idx)
            if slot < 0:
                continue
            rec = bufs[slot, :lens[slot]].view(np.uint32)
            v = int(rec[0])
            seen["torn"] += int((rec != v).any())
            seen["backwards"] += int(v < last)
            seen["taken"] += 1
            last = v
        seen["last"] = last

    t = threading.Thread(target=writer)
    t.start()
    reader()
    t.join()
    assert seen["torn"] == 0 and seen["backwards"] == 0
    assert seen["last"] == records - 1   # the newest record is never lost
    assert seen["taken"] > 0


def test_master_reads_whole_input_records_while_a_box_publishes(cfg):
    """LRD frames of every slave's inputs in one thread (the compiled path, without the
    interpreter lock) while the boxes' records are published in another: every input
    record a frame carries is one the box published whole."""
    both = Both(cfg)
    master = EscMaster(both)
    master.bring_up()
    arr = both.arr
    sizes = [esc.desc.in_bytes for esc in both.ref.escs]
    stop = threading.Event()
    for i, n in enumerate(sizes):  # (the boxes' first records are not uniform)
        arr.set_inputs(i, bytes(n))

    def boxes() -> None:
        k = 0
        while not stop.is_set():
            k += 1
            for i, n in enumerate(sizes):
                arr.set_inputs(i, bytes([k & 0xFF]) * n)

    lrd = [ec.Datagram.logical(ec.Command.LRD, s.in_lad, bytes(s.in_len), 1)
           for s in master.slaves if s.in_len]
    frame = ec.encode_frame(lrd, MAC_DST, MAC_SRC)
    buf = np.zeros(2048, dtype=np.uint8)
    t = threading.Thread(target=boxes)
    t.start()
    torn = 0
    try:
        for _ in range(5000):
            buf[:len(frame)] = np.frombuffer(frame, dtype=np.uint8)
            n = cc.handle_frame(buf, len(frame), *arr.frame_args())
            for d in ec.decode_frame(buf[:n].tobytes()):
                assert d.wkc == 1
                torn += len(set(d.data)) != 1
    finally:
        stop.set()
        t.join()
    assert torn == 0


def test_watchdog_expires_on_the_slaves_increments_whatever_the_ticks(cfg):
    """The slaves' clock ticked in uneven steps of up to 3.3 ms (a frame thread woken late):
    the process-data watchdog still expires at the first increment of the divider at least
    its time after the last output write (the ESC's granularity: [t, t + one increment]),
    applied in the tick that passes that instant, not before; compiled and reference the
    same (:meth:`Both.check`)."""
    both = Both(cfg)
    master = EscMaster(both)
    master.bring_up()
    both.tick(1_234_567)           # off any grid
    master.cycle()                 # the last output write
    esc = both.ref.escs[0]
    last, wd, inc = esc.last_output_ns, esc.watchdog_ns(), esc.watchdog_increment_ns()
    assert wd and inc and esc.out_bytes
    steps = [3_300_013, 700_001, 2_900_017, 1_000_003]
    k = 0
    while not esc.watchdog_trips:
        before = esc.now_ns
        both.tick(steps[k % len(steps)])
        k += 1
    expiry = last + esc.last_trip_delay_ns
    assert wd <= esc.last_trip_delay_ns <= wd + inc and expiry % inc == 0
    assert before < expiry <= esc.now_ns == last + esc.last_trip_seen_ns
    assert esc.last_trip_seen_ns - esc.last_trip_delay_ns > inc  # a late tick, not counted


@pytest.mark.parametrize("cut", [0, 5, 13, 15])
def test_short_frames_are_not_ethercat_or_dropped(cfg, cut):
    both = Both(cfg)
    frame = ec.encode_frame([ec.Datagram(ec.Command.BRD, 1, 0, 0, bytes(2))], MAC_DST, MAC_SRC)
    assert both.handle(frame[:cut]) is None


def test_compiled_distributed_clocks_equal_the_chain_through_set_up_and_cycles(cfg):
    """A master's whole DC set-up (receive-time latch, offsets, delays, SYNC0 start) and
    drift compensation (FRMW on the reference's system time every 1 ms) through both: the
    same replies, registers, loop states and SYNC0 times at every step."""
    from firmware_model.esc.dc import dc_line
    from tests.fieldbus.dc_master import config_dc, dcsync0, frmw

    # 40 us per hop: the first corrections are larger than the loop may slew in a cycle
    both = Both(cfg, dc_line(3, (120.0, -300.0, 45.5), 40_000))
    master = EscMaster(both)
    master.bring_up(to_op=False)
    both.tick(3_000_000)
    config_dc(master, len(both.ref.escs))
    for k in range(400):
        both.tick(1_000_000 + 37 * (k % 5))   # frames not on an exact grid
        frmw(master)
        if k == 100:
            for i in range(len(both.ref.escs)):
                dcsync0(master, i, 1_000_000)
    assert all(e.dc.next_sync0 > 0 for e in both.ref.escs)
