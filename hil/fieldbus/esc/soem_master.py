"""SOEM (through pysoem) as the master of the ESC chain, run as its own process inside a
network namespace (``python -m hil.fieldbus.esc.soem_master IF MODE ...``) by the pysoem test
and ``eha-hil bench ethercat --wire``; prints one JSON object. pysoem is a test extra.

MODE ``cycles N``: config_init, config_map, SAFEOP, OP, N process-data cycles at 1 kHz
(outputs all zero), then stops sending, waits WAIT s and reads every slave's AL state.
MODE ``force BOX SLOT NEWTONS N``: as far as OP, then N cycles commanding a force on that
actuator (mode 1, enable), and reports that actuator's f_pressure input over the cycles.
MODE ``bringups K IMAGE_BYTES``: K bring-ups to OP, each from a fresh master, counted.
MODE ``rtt N``: as far as OP, every actuator enabled with a force command, N cycles at
1 kHz; the wall time of each cycle's send + receive (the frames' round trip) as a 1 us
histogram (``rtt_hist``, :mod:`hil.fieldbus.reply_times`: memory bounded however long the
run) with its exact maximum, and the WKC errors; a progress line on stderr every
PROGRESS_S seconds.
MODE ``dc N CHECK``: as far as OP with distributed clocks (config_dc after config_map,
SYNC0 every 1 ms on every slave), N process-data cycles at 1 kHz (SOEM adds its FRMW on
the reference clock's system time to each); every CHECK cycles, between two of SOEM's
cycles, one frame of this process's own (raw socket) reads every slave's system time
(0x0910) and filtered difference (0x092C): their spread and largest magnitude, each
slave's, when and how long. Also when its cycles went out and its stalls (gaps between
two sends over STALL_S).
MODE ``coe BOX N``: in PREOP every slave's identity read by SDO (0x1018:1..4), then box BOX's
first TxPDO left out of 0x1C13 (complete access write; BOX < 0: no remap), config_map, OP,
N cycles with force commands on BOX's actuators (100 N per slot number + 1), its last
inputs recorded; then the master stops
sending, and after the watchdogs tripped it reads every slave's mailbox: the emergencies.
Also each abort a probe SDO gets (a missing object, a read-only write, an out-of-range gain).
MODE ``gain BOX OTHER KP NEWTONS N``: box BOX's force gain written by SDO, then a force step
on slot 0 of BOX and OTHER, each input stamped with the box cycle that made it (see
:func:`gain`).
"""

from __future__ import annotations

import json
import socket
import struct
import sys
import time

import pysoem

#: SOEM's stock timeouts: EC_TIMEOUTRET (a reply later than this is a lost frame: the
#: cycle's working counter comes short) and EC_TIMEOUTSTATE (a state change).
RECV_TIMEOUT_US = 2_000
STATE_TIMEOUT_US = 2_000_000
PROGRESS_S = 10.0
#: How long MODE dc's own read of the slaves' clocks waits for its reply [us]: a frame of
#: this process between SOEM's cycles, not SOEM's (whose cycles keep the stock 2 ms). What
#: it measures is the clocks' spread, not the reply time (``bench ethercat --wire`` has
#: that), so a loaded machine may take longer.
DC_READ_TIMEOUT_US = 20_000
#: How long MODE coe waits for the commanded box's emergencies after it stopped sending [s]
#: (they come 10 ms of box cycles later; a loaded machine runs those late).
EMCY_WAIT_S = 10.0
#: Cycles right after OP left out of the round-trip figures (not the steady state).
RTT_WARMUP = 20
SYNC0_CYCLE_NS = 1_000_000
#: MODE dc reports a gap between two of its cycles' sends longer than this [s] as a stall
#: (cycle, gap [ms]): the slaves' clocks went that long without a drift compensation.
STALL_S = 5e-3


def bring_up(ifname: str, dc: bool = False) -> tuple[pysoem.Master, dict]:
    """To OP; ``dc``: with distributed clocks, SYNC0 every 1 ms on every slave."""
    m = pysoem.Master()
    m.open(ifname)
    n = m.config_init()
    info = {"found": n, "slaves": [{"name": s.name, "man": s.man, "id": s.id, "rev": s.rev}
                                    for s in m.slaves]}
    info["image_bytes"] = m.config_map()
    if dc:
        info["dc_found"] = bool(m.config_dc())
        for s in m.slaves:
            s.dc_sync(True, SYNC0_CYCLE_NS)
    info["safeop"] = m.state_check(pysoem.SAFEOP_STATE, STATE_TIMEOUT_US)
    info["expected_wkc"] = m.expected_wkc
    m.state = pysoem.OP_STATE
    m.send_processdata()
    m.receive_processdata(RECV_TIMEOUT_US)
    m.write_state()
    info["op"] = m.state_check(pysoem.OP_STATE, STATE_TIMEOUT_US)
    m.read_state()
    info["states"] = [s.state for s in m.slaves]
    return m, info


def paced(m: pysoem.Master, n: int, each=None, rtt=None, progress=None,  # noqa: ANN001
          sent=None) -> tuple[int, list[int]]:  # noqa: ANN001
    """n cycles at 1 kHz; (cycles with a WKC other than expected, the first few WKCs).
    ``rtt(us)``: called with each cycle's send + receive time; ``progress(k, bad)``: every
    PROGRESS_S seconds; ``sent(k, t)``: each cycle's CLOCK_MONOTONIC time [s] just before
    its send."""
    bad, seen = 0, []
    clock = time.perf_counter
    t_next = clock()
    next_progress = t_next + PROGRESS_S
    for k in range(n):
        if each is not None:
            each(k)
        t0 = clock()
        if sent is not None:
            sent(k, t0)
        m.send_processdata()
        wkc = m.receive_processdata(RECV_TIMEOUT_US)
        if rtt is not None:
            rtt((clock() - t0) * 1e6)
        if progress is not None and t0 >= next_progress:
            progress(k, bad)
            next_progress += PROGRESS_S
        if wkc != m.expected_wkc:
            bad += 1
            if len(seen) < 10:
                seen.append(wkc)
        t_next += 1e-3
        pause = t_next - time.perf_counter()
        if pause > 0:
            time.sleep(pause)
    return bad, seen


def _dc_reader(ifname: str, n: int):  # noqa: ANN202 - a function of no arguments
    """A reader of every slave's 0x0910 and 0x092C in one frame of FPRDs (indexes from
    0x80, which SOEM never uses and drops), through a raw socket of this process."""
    from firmware_model.esc import registers as r
    from protocols import ethercat as ec

    sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x88A4))
    sock.bind((ifname, 0))
    sock.settimeout(DC_READ_TIMEOUT_US * 1e-6)
    dgs = []
    for i in range(n):
        station = 0x1001 + i   # SOEM's configured addresses
        dgs += [ec.Datagram(ec.Command.FPRD, 0x80 + 2 * i, station, r.DC_SYSTEM_TIME, bytes(8)),
                ec.Datagram(ec.Command.FPRD, 0x81 + 2 * i, station, r.DC_SYSTEM_DIFF, bytes(4))]
    frame = ec.encode_frame(dgs)

    def read() -> tuple | None:
        sock.setblocking(False)   # SOEM's frames since the last read: not ours
        try:
            while True:
                sock.recv(2048)
        except BlockingIOError:
            pass
        sock.settimeout(DC_READ_TIMEOUT_US * 1e-6)
        t_sent = time.monotonic()
        sock.send(frame)
        t_end = t_sent + DC_READ_TIMEOUT_US * 1e-6
        while time.monotonic() < t_end:
            try:
                got = sock.recv(2048)
            except TimeoutError:
                return None
            # a reply (source MAC bit 1 set by the slaves) to this frame (first index 0x80)
            if len(got) < 18 or not got[6] & 0x02 or got[17] != 0x80:
                continue
            try:
                back = ec.decode_frame(got)
            except ValueError:
                continue
            if back[0].idx != 0x80 or any(d.wkc != 1 for d in back):
                continue
            times = [struct.unpack("<q", d.data)[0] for d in back[0::2]]
            diffs = [struct.unpack("<I", d.data)[0] & 0x7FFFFFFF for d in back[1::2]]
            # (spread, largest 0x092C, each slave's time after the reference's, each
            # 0x092C, when the frame went out [s] and how long its reply took [us])
            return (max(times) - min(times), max(diffs), [t - times[0] for t in times], diffs,
                    t_sent, round((time.monotonic() - t_sent) * 1e6))
        return None

    return read


def bring_ups(ifname: str, n: int, image_bytes: int) -> dict:
    """``n`` bring-ups to OP, each from a fresh master, no step retried: how many reached OP
    with every slave and the full map, and what the others got."""
    ok, failed = 0, []
    for k in range(n):
        m, info = bring_up(ifname)
        good = (info["found"] > 0 and info["image_bytes"] == image_bytes
                and info["safeop"] == pysoem.SAFEOP_STATE and info["op"] == pysoem.OP_STATE
                and set(info["states"]) == {pysoem.OP_STATE})
        if good:
            ok += 1
        else:
            failed.append({"try": k, "found": info["found"], "image_bytes": info["image_bytes"],
                           "safeop": info["safeop"], "op": info["op"],
                           "states": sorted(set(info["states"]))})
        m.state = pysoem.INIT_STATE
        m.write_state()
        m.close()
    return {"bring_ups": n, "bring_ups_ok": ok, "failed": failed}


def _abort_of(call) -> int | None:  # noqa: ANN001
    try:
        call()
    except pysoem.SdoError as exc:
        return exc.abort_code
    return None


def coe(ifname: str, box: int, n: int) -> dict:
    """MODE coe (see the module's docstring)."""
    m = pysoem.Master()
    m.open(ifname)
    info: dict = {"found": m.config_init()}
    sdo_us: list[float] = []

    def timed_read(s, k: int) -> int:  # noqa: ANN001
        t = time.perf_counter()
        raw = s.sdo_read(0x1018, k)
        sdo_us.append((time.perf_counter() - t) * 1e6)
        return struct.unpack("<I", raw)[0]

    info["identity"] = [[timed_read(s, k) for k in range(1, 5)] for s in m.slaves]
    info["sdo_read_us"] = sdo_us  # wall time of each expedited upload (one box cycle or two)
    info["sii_identity"] = [[s.man, s.id, s.rev] for s in m.slaves]
    emcy: list[list] = []
    for k, s in enumerate(m.slaves):
        s.add_emergency_callback(
            lambda e, k=k: emcy.append([k, e.error_code, e.error_reg, e.b1, e.w1, e.w2]))
    if box >= 0:
        s = m.slaves[box]
        raw = s.sdo_read(0x1C13, 0, ca=True)
        count = raw[0]
        idx = list(struct.unpack_from(f"<{count}H", raw, 2))
        info["assigned_before"] = idx
        s.sdo_write(0x1C13, 0, struct.pack(f"<BB{count - 1}H", count - 1, 0, *idx[1:]), ca=True)
        raw = s.sdo_read(0x1C13, 0, ca=True)
        info["assigned_after"] = list(struct.unpack_from(f"<{raw[0]}H", raw, 2))
    probe = m.slaves[0]
    info["aborts"] = {
        "missing_object": _abort_of(lambda: probe.sdo_read(0x3000, 0)),
        "missing_subindex": _abort_of(lambda: probe.sdo_read(0x1018, 9)),
        "read_only": _abort_of(lambda: probe.sdo_write(0x1018, 1, b"\0\0\0\0")),
        "gain_too_high": _abort_of(lambda: probe.sdo_write(0x2000, 1, struct.pack("<f", 1e6))),
    }
    info["name"] = probe.sdo_read(0x1008, 0).decode()
    info["image_bytes"] = m.config_map()
    info["in_bytes"] = [len(s.input) for s in m.slaves]
    info["safeop"] = m.state_check(pysoem.SAFEOP_STATE, STATE_TIMEOUT_US)
    m.state = pysoem.OP_STATE
    m.send_processdata()
    m.receive_processdata(RECV_TIMEOUT_US)
    m.write_state()
    info["op"] = m.state_check(pysoem.OP_STATE, STATE_TIMEOUT_US)
    target = m.slaves[max(box, 0)]
    out = bytearray(target.output)
    for k in range(len(out) // 10):  # actuator slot k: force mode, enabled, 100 (k + 1) N
        struct.pack_into("<BBi", out, 10 * k, 1, 1, 10_000 * (k + 1))
    target.output = bytes(out)
    info["bad_wkc"], info["bad_wkc_values"] = paced(m, n)
    info["inputs_last"] = target.input.hex()
    # Nothing sent from now on: the MCU command watchdogs trip (after their 10 ms of box
    # cycles), then the ESCs' (100 ms of their clock). The emergencies are read until the
    # commanded box's actuators all sent theirs (however late a loaded machine runs the
    # boxes, up to EMCY_WAIT_S), then once more for any that should not be there.
    slots = len(target.output) // 10
    deadline = time.monotonic() + EMCY_WAIT_S
    while (sum(e[0] in (max(box, 0), -1) for e in emcy) < slots
           and time.monotonic() < deadline):
        _read_mailboxes(m, emcy, 1)
        time.sleep(0.01)
    _read_mailboxes(m, emcy, 6)
    info["emergencies"] = emcy
    m.read_state()
    info["after_stop"] = [s.state for s in m.slaves]
    m.state = pysoem.INIT_STATE
    m.write_state()
    m.close()
    return info


def _read_mailboxes(m: pysoem.Master, emcy: list, rounds: int) -> None:
    """Every slave's mailbox read ``rounds`` times, 3 ms apart (SM1 holds one message; a box
    puts the next one a cycle later); emergencies no callback took go to ``emcy``."""
    for s in m.slaves:
        for _ in range(rounds):
            try:
                s.mbx_receive()
            except pysoem.Emergency as e:  # (raised when no callback takes it)
                emcy.append([-1, e.error_code, e.error_reg, e.b1, e.w1, e.w2])
            if rounds > 1:
                time.sleep(0.003)


def _assign_cycle_counter(s) -> None:  # noqa: ANN001
    """Slave ``s``'s cycle-counter TxPDO appended to its TxPDO assignment (0x1C13, complete
    access, in PREOP): its inputs end with the number of the box cycle that made them."""
    from hil.fieldbus.esc.slaves import CYCLE_PDO

    raw = s.sdo_read(0x1C13, 0, ca=True)
    idx = [*struct.unpack_from(f"<{raw[0]}H", raw, 2), CYCLE_PDO]
    s.sdo_write(0x1C13, 0, struct.pack(f"<BB{len(idx)}H", len(idx), 0, *idx), ca=True)


def gain(ifname: str, box: int, other: int, kp: float, newtons: float, n: int) -> dict:
    """MODE gain: in PREOP box BOX's force gain of actuator slot 0 (0x2000:1) written by
    SDO and read back (and box OTHER's read), and both boxes' cycle counters assigned; OP;
    slot 0 of both enabled at 0 N for 200 cycles, then a NEWTONS step for the rest of N
    cycles; both f_pressure inputs per cycle, each with the box cycle that made it
    (``box_cycle``), and the box cycles of the inputs the step's frame brought back
    (``step_seen_cycle``: the boxes took the step in a later cycle), and every bit slot 0's
    MCU status word showed (``status_seen``)."""
    m = pysoem.Master()
    m.open(ifname)
    info: dict = {"found": m.config_init()}
    a, b = m.slaves[box], m.slaves[other]
    a.sdo_write(0x2000, 1, struct.pack("<f", kp))
    info["kp_read"] = struct.unpack("<f", a.sdo_read(0x2000, 1))[0]
    info["kp_other"] = struct.unpack("<f", b.sdo_read(0x2000, 1))[0]
    for s in (a, b):
        _assign_cycle_counter(s)
    info["image_bytes"] = m.config_map()
    info["safeop"] = m.state_check(pysoem.SAFEOP_STATE, STATE_TIMEOUT_US)
    m.state = pysoem.OP_STATE
    m.send_processdata()
    m.receive_processdata(RECV_TIMEOUT_US)
    m.write_state()
    info["op"] = m.state_check(pysoem.OP_STATE, STATE_TIMEOUT_US)
    f: dict[int, list[float]] = {box: [], other: []}
    cyc: dict[int, list[int]] = {box: [], other: []}
    status: dict[int, int] = {box: 0, other: 0}

    def each(k: int) -> None:
        for s, key in ((a, box), (b, other)):
            out = bytearray(s.output)
            struct.pack_into("<BBi", out, 0, 1, 1, 0 if k < 200 else round(newtons / 0.01))
            s.output = bytes(out)
            inp = s.input
            f[key].append(struct.unpack_from("<h", inp, 6)[0] * 0.1)
            cyc[key].append(struct.unpack_from("<I", inp, len(inp) - 4)[0])
            status[key] |= struct.unpack_from("<H", inp, 16)[0]

    info["bad_wkc"], info["bad_wkc_values"] = paced(m, n, each)
    info["f_pressure"] = [f[box], f[other]]
    info["box_cycle"] = [cyc[box], cyc[other]]
    info["status_seen"] = [status[box], status[other]]  # slot 0's status words, or-ed
    # the inputs read at cycle 201 came back in the frame that carried the step (cycle 200)
    info["step_seen_cycle"] = [cyc[box][201], cyc[other][201]] if n > 201 else None
    m.state = pysoem.INIT_STATE
    m.write_state()
    m.close()
    return info


def main(argv: list[str]) -> None:
    ifname, mode = argv[0], argv[1]
    if mode == "gain":
        print(json.dumps(gain(ifname, int(argv[2]), int(argv[3]), float(argv[4]),
                              float(argv[5]), int(argv[6]))))
        return
    if mode == "coe":
        print(json.dumps(coe(ifname, int(argv[2]), int(argv[3]))))
        return
    if mode == "bringups":
        print(json.dumps(bring_ups(ifname, int(argv[2]), int(argv[3]))))
        return
    m, info = bring_up(ifname, dc=mode == "dc")
    if mode == "dc":
        n, check = int(argv[2]), int(argv[3])
        read = _dc_reader(ifname, len(m.slaves))
        checks: list = []
        sends: list[float] = []

        def between(k: int) -> None:
            if k and k % check == 0:
                checks.append((k, read()))

        info["cycles"] = n
        info["bad_wkc"], info["bad_wkc_values"] = paced(
            m, n, between, sent=lambda _k, t: sends.append(t))
        # when its cycles went out (CLOCK_MONOTONIC [s], every CHECK-th and the last: to
        # match them with serve's record on the slaves' clock), and its stalls
        info["cycle_at_s"] = sends[::check]
        info["last_cycle_at_s"] = sends[-1] if sends else None
        info["stalls"] = [[k, round((sends[k] - sends[k - 1]) * 1e3, 1)]
                          for k in range(1, len(sends)) if sends[k] - sends[k - 1] > STALL_S]
        info["dc_checks"] = checks
        info["dc_time"] = m.dc_time
    if mode == "cycles":
        n, wait = int(argv[2]), float(argv[3])
        info["cycles"] = n
        info["bad_wkc"], info["bad_wkc_values"] = paced(m, n)
        time.sleep(wait)  # nothing sent: the slaves' watchdogs run out
        m.read_state()
        info["after_stop"] = [{"state": s.state, "al_status": s.al_status} for s in m.slaves]
    elif mode == "rtt":
        n = int(argv[2])
        for s in m.slaves:  # every actuator slot: force command, enabled
            out = bytearray(s.output)
            for k in range(len(out) // 10):
                struct.pack_into("<BBi", out, 10 * k, 1, 1, 10_000)
            s.output = bytes(out)
        from hil.fieldbus.reply_times import ReplyTimes

        rtt = ReplyTimes(late_us=RECV_TIMEOUT_US)
        skip = [RTT_WARMUP]

        def timed(us: float) -> None:
            if skip[0]:  # the first cycles after OP are not the steady state
                skip[0] -= 1
            else:
                rtt.add(us)

        def progress(k: int, bad: int) -> None:
            print(f"master: {k / 1000:.0f} of {n / 1000:.0f} s, wrong WKC {bad}, round trip "
                  f"max so far {rtt.max_us:.0f} us", file=sys.stderr, flush=True)

        info["bad_wkc"], info["bad_wkc_values"] = paced(m, n, rtt=timed, progress=progress)
        info["rtt_hist"] = {str(i): int(c) for i, c in enumerate(rtt.hist) if c}
        info["rtt_max_us"] = rtt.max_us
        info["rtt_cycles"] = int(rtt.hist.sum())
    elif mode == "force":
        box, slot, newtons, n = int(argv[2]), int(argv[3]), float(argv[4]), int(argv[5])
        s = m.slaves[box]
        out = bytearray(s.output)
        struct.pack_into("<BBi", out, 10 * slot, 1, 1, round(newtons / 0.01))
        s.output = bytes(out)
        f = []

        def sample(_k: int) -> None:
            f.append(struct.unpack_from("<h", s.input, 22 * slot + 6)[0] * 0.1)

        info["bad_wkc"], info["bad_wkc_values"] = paced(m, n, sample)
        info["f_pressure"] = f
    m.state = pysoem.INIT_STATE
    m.write_state()
    m.close()
    print(json.dumps(info))


if __name__ == "__main__":
    main(sys.argv[1:])
