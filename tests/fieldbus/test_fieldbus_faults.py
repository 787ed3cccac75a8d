"""Fault injection (hil.fieldbus.faults): configuration, determinism, corrupted frames never
applied, counters, the MCU command watchdog, the LVDS watchdog, limits, sensor faults."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from firmware_model.fpga import layout as B
from firmware_model.mcu.mcu import (
    BOARD_ENABLED,
    BOARD_FAULT,
    CMD_TIMEOUT,
    ENCODER_ERROR,
    FORCE_LIMITED,
    LINK_ERROR,
    SAFE_OFF,
    STRAIN_ERROR,
)
from hil.fieldbus import wire
from hil.fieldbus.faults import FaultError, load_faults, parse_faults
from hil.fieldbus.system import BusSystem

from .conftest import force_profile, full_robot_pc

TICK_S = 50e-6
CYCLE = 20  # ticks


# --- configuration ---------------------------------------------------------------------------

def test_parse_toml(tmp_path):
    path = tmp_path / "f.toml"
    path.write_text('seed = 5\n[[fault]]\nlink = "fieldbus.down"\nkind = "bitflip"\n'
                    'rate = 0.01\nbits = 2\nstart_s = 0.2\nend_s = 0.4\n'
                    '[[fault]]\nlink = "lvds.up"\nkind = "dead"\nbox = 0\nslot = 0\n')
    plan = load_faults(path)
    a, b = plan.faults
    assert (a.link, a.kind, a.rate, a.bits, a.seed) == ("fieldbus.down", "bitflip", 0.01, 2, 5)
    assert (a.start_cycle, a.end_cycle) == (200, 400)
    assert a.active(200) and a.active(399) and not a.active(400) and not a.active(199)
    assert (b.seed, b.box, b.slot, b.end_s) == (6, 0, 0, math.inf)
    assert plan.fieldbus == (a,) and plan.box_faults == (b,)


BAD = [
    ({"link": "fieldbus.sideways", "kind": "drop"}, "'link'"),
    ({"link": "fieldbus.down", "kind": "stuck"}, "'kind'"),
    ({"link": "fieldbus.down", "kind": "drop", "rate": 1.5}, "'rate'"),
    ({"link": "fieldbus.down", "kind": "drop", "rate": "often"}, "'rate'"),
    ({"link": "fieldbus.down", "kind": "drop", "start_s": 0.3, "end_s": 0.2}, "'end_s'"),
    ({"link": "fieldbus.down", "kind": "drop", "box": 0}, "'box'"),
    ({"link": "fieldbus.up", "kind": "delay", "delay_cycles": 0}, "'delay_cycles'"),
    ({"link": "fieldbus.up", "kind": "bitflip", "bits": 1.5}, "'bits'"),
    ({"link": "lvds.down", "kind": "dead", "slot": 0}, "'box'"),
    ({"link": "lvds.up", "kind": "delay", "box": 0, "slot": 0, "delay_ticks": 64},
     "'delay_ticks'"),
    ({"link": "lvds.down", "kind": "bitflip", "box": 0, "slot": 0, "rate": 0.0}, "'rate'"),
    ({"link": "sensor", "kind": "noisy", "box": 0, "slot": 0, "signal": "p_cyl_a"}, "'sigma'"),
    ({"link": "sensor", "kind": "stuck", "box": 0, "slot": 0, "signal": "smell"}, "'signal'"),
    ({"link": "sensor", "kind": "stuck", "box": 0, "slot": 0, "signal": "x_piston",
      "seed": -1}, "'seed'"),
]


@pytest.mark.parametrize(("entry", "key"), BAD)
def test_bad_entries_name_entry_and_key(entry, key):
    ok = {"link": "fieldbus.up", "kind": "drop"}
    with pytest.raises(FaultError) as err:
        parse_faults({"fault": [ok, entry]}, "scenario x.toml")
    msg = str(err.value)
    assert msg.startswith("scenario x.toml: fault #1") and key in msg and "\n" not in msg


def test_box_faults_checked_against_topology(cfg, bench, full):
    with pytest.raises(FaultError, match="fault #0.*'box' = 3"):
        BusSystem(bench, cfg, faults=[{"link": "lvds.down", "kind": "dead", "box": 3,
                                       "slot": 0}])
    with pytest.raises(FaultError, match="'slot' = 2"):
        BusSystem(full, cfg, faults=[{"link": "lvds.down", "kind": "dead", "box": 2,
                                      "slot": 2}])  # the foot sensor
    with pytest.raises(FaultError, match="stack box model"):
        BusSystem(full, cfg, model="echo", faults=[{"link": "lvds.down", "kind": "dead",
                                                    "box": 0, "slot": 0}])
    with pytest.raises(FaultError, match="'box'"):  # validated before the chain starts
        BusSystem(bench, cfg, "udp", transport_options={"port": 0},
                  faults=[{"link": "lvds.down", "kind": "dead", "box": 5, "slot": 0}])
    # bit flips without the CRC-32 trailer (udp's standard frame) would go unnoticed
    flip = [{"link": "fieldbus.down", "kind": "bitflip", "rate": 0.1}]
    with pytest.raises(FaultError, match="fault #0 .*need the CRC-32 trailer"):
        BusSystem(bench, cfg, "udp", transport_options={"port": 0}, faults=flip)
    with pytest.raises(FaultError, match="need the CRC-32 trailer"):
        BusSystem(bench, cfg, "inproc", faults=flip, crc_trailer=False)


@pytest.mark.slow
def test_box_faults_reach_a_chain_in_another_process(cfg, bench):
    """LVDS and sensor faults are handed to a remote chain: the same declaration gives the
    same bytes on inproc and on udp (chain in another process)."""
    faults = [{"link": "lvds.up", "kind": "bitflip", "rate": 0.02, "box": 0, "slot": 0,
               "start_s": 0.02, "end_s": 0.05},
              {"link": "sensor", "kind": "noisy", "box": 0, "slot": 0, "signal": "p_cyl_a",
               "sigma": 1e5, "start_s": 0.03, "end_s": 0.06, "seed": 5}]
    out = {}
    for tr, opts in (("inproc", None), ("udp", {"port": 0})):
        with BusSystem(bench, cfg, tr, faults=faults, transport_options=opts) as bs:
            out[tr] = bs.run(80, lambda c, m: force_profile(c + 100, m)).inputs
    clean = BusSystem(bench, cfg, "inproc")
    base = clean.run(80, lambda c, m: force_profile(c + 100, m)).inputs
    clean.close()
    assert np.array_equal(out["inproc"], out["udp"])
    assert not np.array_equal(out["inproc"], base)


# --- fieldbus faults -------------------------------------------------------------------------

MIXED = {"seed": 3, "fault": [
    {"link": "fieldbus.down", "kind": "bitflip", "rate": 0.1, "bits": 3, "start_s": 0.02,
     "end_s": 0.06},
    {"link": "fieldbus.up", "kind": "bitflip", "rate": 0.1, "start_s": 0.02, "end_s": 0.06},
    {"link": "fieldbus.up", "kind": "drop", "rate": 0.1, "start_s": 0.02, "end_s": 0.06},
    {"link": "fieldbus.up", "kind": "duplicate", "rate": 0.2, "start_s": 0.02, "end_s": 0.06},
    {"link": "fieldbus.down", "kind": "duplicate", "rate": 0.1, "start_s": 0.02},
    {"link": "fieldbus.down", "kind": "delay", "rate": 0.1, "delay_cycles": 2,
     "start_s": 0.02, "end_s": 0.06},
]}


def _check_counters(rec):
    m, f = rec.master, rec.faults
    # every frame of every cycle is either answered (ok or WKC error) or lost
    assert m["frames_sent"] == m["frames_ok"] + m["wkc_errors"] + m["lost_frames"]
    # every reply the master read is classified exactly once
    assert rec.transport["frames_received"] == (m["frames_ok"] + m["wkc_errors"]
                                                + m["bad_frames"] + m["stale_frames"])
    # the FCS catches every flipped frame (CRC-32: all 1..3-bit errors)
    assert m["bad_frames"] == f["up_flipped"]
    if rec.chain is not None:
        assert rec.chain["bad_frames"] == f["down_flipped"]


@pytest.mark.slow
def test_mixed_faults_deterministic_across_transports(cfg, bench):
    recs = {}
    # Bit flips are injected above the transport: only the CRC-32 trailer catches them, so
    # udp (whose standard frame has none) runs with it here.
    for transport, opts in (("inproc", None), ("udp", {"port": 0}), ("serial", None)):
        with BusSystem(bench, cfg, transport, faults=MIXED, transport_options=opts,
                       crc_trailer=True) as bs:
            # The first cycles with the patient default timeout (a fresh chain process
            # loads its compiled code); in the fault window a lost frame costs one timeout
            # of wall time: short, but long enough for any reply that does come.
            first = bs.run(10, force_profile)
            bs.reply_timeout_s = 0.15
            rest = bs.run(90, force_profile)
        recs[transport] = dataclasses.replace(rest, inputs=np.vstack([first.inputs,
                                                                      rest.inputs]))
    ref = recs["inproc"]
    _check_counters(ref)
    f = ref.faults
    assert f["down_flipped"] and f["up_flipped"] and f["up_dropped"] and f["down_delayed"]
    assert f["up_duplicated"] and f["down_duplicated"]
    assert ref.master["stale_frames"] >= f["up_duplicated"]
    assert ref.chain["stale_frames"] > 0  # delayed and duplicated requests
    for t in ("udp", "serial"):
        assert recs[t].master == ref.master, t
        assert recs[t].faults == ref.faults, t
        assert recs[t].inputs.tobytes() == ref.inputs.tobytes(), t
    # another seed, other faults
    with BusSystem(bench, cfg, faults=dict(MIXED, seed=4)) as bs:
        other = bs.run(100, force_profile)
    assert other.faults != ref.faults


def _sent_outputs(plan, frames):
    """(box, output bytes) of every box in the master's frames."""
    out = set()
    for frame in frames:
        (d,) = wire.open_frame(frame)
        for w in plan.windows:
            if w.out_len and d.lad <= w.lad and w.end <= d.lad + len(d.data):
                o = w.lad - d.lad
                out.add((w.box, bytes(d.data[o:o + w.out_len])))
    return out


def test_corrupted_frames_never_applied(cfg, full):
    faults = {"seed": 11, "fault": [
        {"link": "fieldbus.down", "kind": "bitflip", "rate": 0.3, "bits": 2},
        {"link": "fieldbus.up", "kind": "bitflip", "rate": 0.3, "bits": 1},
        {"link": "fieldbus.down", "kind": "duplicate", "rate": 0.1},
    ]}
    sent: list[bytes] = []

    def tap(cycle, tick, frame, direction):
        if direction == "tx":
            sent.append(frame)

    with BusSystem(full, cfg, "inproc", model="echo", faults=faults, tap=tap) as bs:
        applied: list[tuple[int, bytes]] = []
        for box in bs.chain.boxes:
            def record(data, box=box, orig=box.apply):
                applied.append((box.box.id, bytes(data)))
                orig(data)
            box.apply = record
        rec = bs.run(120, full_robot_pc)
    _check_counters(rec)
    assert rec.faults["down_flipped"] > 40 and rec.faults["up_flipped"] > 40
    good = _sent_outputs(bs.master.plan, sent)
    assert applied and all(a in good for a in applied)
    # with varying commands, a flipped command would have shown up as a new record
    assert len({a for a in applied}) > 100
    # bad replies are never applied: every input row is the echo of a sent command
    assert rec.master["frames_ok"] > 0 and rec.master["bad_frames"] == rec.faults["up_flipped"]


def test_command_watchdog_on_dropped_frames(cfg, bench):
    """All master->chain frames dropped for 100 ms: the MCU zeroes the force command
    (CMD_TIMEOUT) 10 ms after the last good frame (+ one cycle at most) and switches the
    board off (SAFE_OFF) 50 ms later."""
    faults = [{"link": "fieldbus.down", "kind": "drop", "start_s": 0.05, "end_s": 0.15}]
    seen = []
    with BusSystem(bench, cfg, "inproc", faults=faults) as bs:
        mcu = bs.chain.boxes[0].mcu
        step = mcu.step

        def logged(tick):
            step(tick)
            seen.append((tick, mcu.status[0], mcu.last_cmd_tick[0], float(mcu.tau_ref[0])))
        mcu.step = logged
        status = []

        def pc(cycle, m):
            status.append(m.actuator_inputs(0)["status"])
            m.set_actuator(0, "force", 200.0)
        rec = bs.run(200, pc)
    assert rec.faults["down_dropped"] == 100
    assert rec.master["lost_frames"] == 100
    last_good = 49 * CYCLE  # the last frame before the window, applied at its cycle's tick
    t_timeout = next(t for t, s, _, _ in seen if s & CMD_TIMEOUT)
    t_off = next(t for t, s, _, _ in seen if s & SAFE_OFF)
    assert max(lc for t, _, lc, _ in seen if t < t_timeout) == last_good
    age = (t_timeout - last_good) * TICK_S
    assert 0.010 < age <= 0.010 + 0.001
    assert 0.050 <= (t_off - t_timeout) * TICK_S <= 0.050 + 0.001
    # the force reference is zero from the timeout on, until the next good frame
    assert all(tau == 0.0 for t, s, _, tau in seen if t_timeout <= t < 150 * CYCLE)
    assert all(not s & CMD_TIMEOUT for t, s, _, _ in seen if t < t_timeout)
    # the master sees it once frames pass again: the first reply after the window
    assert status[151] & (CMD_TIMEOUT | SAFE_OFF) == CMD_TIMEOUT | SAFE_OFF
    assert not status[151] & BOARD_ENABLED
    assert all(s & BOARD_ENABLED for s in status[10:51])


def test_echo_watchdog_full_robot(cfg, full):
    faults = [{"link": "fieldbus.down", "kind": "drop", "start_s": 0.02, "end_s": 0.1}]
    with BusSystem(full, cfg, "inproc", model="echo", faults=faults) as bs:
        rec = bs.run(101, full_robot_pc)  # the last: the first cycle after the window
        st = [bs.master.actuator_inputs(j)["status"] for j in range(47)]
    assert rec.master["lost_frames"] == 2 * 80
    assert all(s & CMD_TIMEOUT and s & SAFE_OFF and not s & BOARD_ENABLED for s in st)


# --- LVDS faults -----------------------------------------------------------------------------

def test_lvds_down_dead_trips_board_watchdog(cfg, bench):
    faults = [{"link": "lvds.down", "kind": "dead", "box": 0, "slot": 0, "start_s": 0.05,
               "end_s": 0.06}]
    seen = []
    with BusSystem(bench, cfg, "inproc", faults=faults) as bs:
        box = bs.chain.boxes[0]
        step = box.mcu.step

        def logged(tick):
            step(tick)
            seen.append((tick, int(box.stacks[0].board.state[B.F_LATCHED])))
        box.mcu.step = logged
        status = []

        def pc(cycle, m):
            status.append(m.actuator_inputs(0)["status"])
            m.set_actuator(0, "force", 200.0)
        bs.run(80, pc)
    start = 50 * CYCLE
    lost = next(t for t, latched in seen if latched & B.ST_LINK_LOST)
    watchdog = cfg.get("fpga.watchdog_s")
    assert 0 < (lost - start) * TICK_S <= watchdog + 4 * TICK_S  # MCU step resolution
    assert all(not latched & B.ST_LINK_LOST for t, latched in seen if t < start)
    assert all(s & BOARD_ENABLED for s in status[10:50])
    assert status[53] & (LINK_ERROR | BOARD_FAULT) == LINK_ERROR | BOARD_FAULT
    assert not status[53] & BOARD_ENABLED
    assert status[-1] & BOARD_FAULT  # latched after the window, until a clear


def _lvds_run(cfg, bench, faults, cycles=60):
    rows = []

    def pc(cycle, m):
        rows.append(m.actuator_inputs(0))
        force_profile(cycle + 100, m)

    with BusSystem(bench, cfg, "inproc", faults=faults) as bs:
        bs.run(cycles, pc)
        link = bs.chain.boxes[0].stacks[0].link.copy()
    return rows, link


def test_lvds_word_drop_duplicate_delay(cfg, bench):
    """Value-level word faults in a window: every word dropped on the down link trips the
    board's watchdog like a dead cable, with no CRC count; duplicated and delayed upstream
    words change what the MCU measures but never count as link errors."""
    from firmware_model.lvds import link as LK

    win = {"box": 0, "slot": 0, "start_s": 0.02, "end_s": 0.03}
    rows, link = _lvds_run(cfg, bench, [{"link": "lvds.down", "kind": "drop", "rate": 1.0,
                                         **win}])
    assert link[LK.LK_DOWN_DROPPED] > 0
    assert any(r["status"] & BOARD_FAULT for r in rows[22:35])
    assert all(r["err_link_down"] == 0 for r in rows)
    clean, _ = _lvds_run(cfg, bench, None)
    for kind, extra in (("duplicate", {"rate": 0.5}), ("delay", {"delay_ticks": 40})):
        rows, _ = _lvds_run(cfg, bench, [{"link": "lvds.up", "kind": kind, **extra, **win}])
        assert rows[:20] == clean[:20]
        assert rows[21:32] != clean[21:32]
        assert all(not r["status"] & (LINK_ERROR | BOARD_FAULT) for r in rows)


def test_lvds_up_bitflips_are_counted(cfg, bench):
    faults = [{"link": "lvds.up", "kind": "bitflip", "rate": 0.5, "box": 0, "slot": 0,
               "start_s": 0.02, "end_s": 0.04}]
    errs, status = [], []

    def pc(cycle, m):
        x = m.actuator_inputs(0)
        errs.append(x["err_link_up"])
        status.append(x["status"])
        force_profile(cycle, m)

    with BusSystem(bench, cfg, "inproc", faults=faults) as bs:
        bs.run(60, pc)
    # the MCU side discards the corrupted upstream words and counts them, in the window only
    assert errs[20] == 0 and errs[45] > 0 and errs[-1] == errs[45]
    assert any(s & LINK_ERROR for s in status[21:41])
    assert not any(s & LINK_ERROR for s in status[:20] + status[45:])


# --- limits ----------------------------------------------------------------------------------

def test_commands_never_beyond_limits(cfg, bench):
    """Commands up to +/- 4 kN with faulty frames: the force reference stays within the
    1500 N limit and the current reference within 18 A, at every MCU step."""
    faults = {"seed": 2, "fault": [
        {"link": "fieldbus.down", "kind": "bitflip", "rate": 0.2, "bits": 3},
        {"link": "fieldbus.down", "kind": "duplicate", "rate": 0.1},
        {"link": "fieldbus.up", "kind": "drop", "rate": 0.1},
    ]}
    f_lim, i_lim = cfg.get("mcu.force_limit_n"), cfg.get("mcu.current_limit_a")
    refs = []

    def pc(cycle, m):
        m.set_actuator(0, "force", 4000.0 * math.sin(2 * math.pi * 5.0 * cycle * 1e-3))

    with BusSystem(bench, cfg, "inproc", faults=faults) as bs:
        mcu = bs.chain.boxes[0].mcu
        link = bs.chain.boxes[0].stacks[0].mcu_link
        step = mcu.step

        def logged(tick):
            step(tick)
            word = int(link.down[B.D_IQ_REF])
            word = word - 0x10000 if word & 0x8000 else word
            refs.append((float(mcu.tau_ref[0]), float(mcu.iq_ref[0]), word * 1e-3,
                         mcu.status[0]))
        mcu.step = logged
        rec = bs.run(300, pc)
    tau, iq, iq_word, status = (np.array(v) for v in zip(*refs, strict=True))
    assert rec.faults["down_flipped"] > 0
    assert np.abs(tau).max() <= f_lim * (1 + 1e-6)
    assert np.abs(iq).max() <= i_lim * (1 + 1e-6)
    assert np.abs(iq_word).max() <= i_lim + 1e-3
    assert np.abs(tau).max() > 0.9 * f_lim  # the limit was reached
    assert np.any(status & FORCE_LIMITED)


# --- sensor faults ---------------------------------------------------------------------------

def _bench_run(cfg, bench, faults, cycles=80):
    with BusSystem(bench, cfg, "inproc", faults=faults) as bs:
        rows = []

        def pc(cycle, m):
            force_profile(cycle + 100, m)  # the sine from the start
            rows.append(m.actuator_inputs(0))
        bs.run(cycles, pc)
        stacks = bs.chain.boxes[0].stacks
    return rows, stacks


def _sensor(kind, signal, **kw):
    return [dict(link="sensor", kind=kind, box=0, slot=0, signal=signal, start_s=0.03,
                 end_s=0.06, **kw)]


def test_sensor_stuck_strain(cfg, bench):
    clean, _ = _bench_run(cfg, bench, None)
    rows, stacks = _bench_run(cfg, bench, _sensor("stuck", "f_strain"))
    assert stacks[0].sensor_ticks == 30 * CYCLE
    # Explicit composition: the wrapper is not the stack, offers its parts by name and
    # passes nothing else on implicitly.
    wrapped = stacks[0]
    assert not hasattr(type(wrapped), "__getattr__")
    assert wrapped.board is wrapped.stack.board and wrapped.mcu_link is wrapped.stack.mcu_link
    assert wrapped.tick == wrapped.stack.tick > 0
    with pytest.raises(AttributeError):
        wrapped._bits  # noqa: B018 - a private of the stack is not reachable through it
    inside = [r["f_strain"] for r in rows[33:61]]
    assert len(set(inside)) <= 2  # held (one rounding step at most)
    assert len({r["f_strain"] for r in clean[33:61]}) > 10
    assert rows[:30] == clean[:30]  # nothing before the window


def test_sensor_dead_and_noisy_pressure(cfg, bench):
    clean, _ = _bench_run(cfg, bench, None)
    dead, _ = _bench_run(cfg, bench, _sensor("dead", "p_cyl_a"))
    # code 0 on the A side: the pressure force reads far below the clean one
    assert all(d["f_pressure"] < c["f_pressure"] - 100.0 for d, c in
               zip(dead[35:60], clean[35:60], strict=True))
    noisy1, _ = _bench_run(cfg, bench, _sensor("noisy", "p_cyl_a", sigma=2e5, seed=1))
    noisy2, _ = _bench_run(cfg, bench, _sensor("noisy", "p_cyl_a", sigma=2e5, seed=1))
    noisy3, _ = _bench_run(cfg, bench, _sensor("noisy", "p_cyl_a", sigma=2e5, seed=2))
    assert noisy1 == noisy2 and noisy1 != noisy3
    diff = np.array([n["f_pressure"] - c["f_pressure"] for n, c in
                     zip(noisy1[35:60], clean[35:60], strict=True)])
    assert diff.std() > 5.0


def test_sensor_dead_strain_rejected(cfg, bench):
    rows, _ = _bench_run(cfg, bench, _sensor("dead", "f_strain"))
    # the AD7195 reports every conversion clamped (ERR): the board keeps its last code
    assert len({r["f_strain"] for r in rows[33:61]}) <= 2
    # ... and says so; the MCU passes it to the PC in its status word, for the window only
    assert all(r["status"] & STRAIN_ERROR for r in rows[33:59])
    assert not any(r["status"] & STRAIN_ERROR for r in rows[:29] + rows[63:])
    assert not any(r["status"] & ENCODER_ERROR for r in rows)


@pytest.mark.parametrize("signal,counter", [("theta_m", "err_ssi"), ("x_piston", "err_biss")])
def test_sensor_dead_encoder_gives_no_valid_frame(cfg, bench, signal, counter):
    """A dead encoder delivers no valid frame for exactly the window: the board's master
    rejects one frame per tick (its error counter) and holds the last good reading."""
    clean, _ = _bench_run(cfg, bench, None)
    rows, stacks = _bench_run(cfg, bench, _sensor("dead", signal))
    assert rows[:30] == clean[:30]
    assert stacks[0].board.up_value(counter) == 30 * CYCLE
    assert _bench_run(cfg, bench, None)[1][0].board.up_value(counter) == 0
    assert all(r["status"] & ENCODER_ERROR for r in rows[33:59])
    assert not any(r["status"] & (ENCODER_ERROR | STRAIN_ERROR) for r in rows[:29] + rows[63:])
