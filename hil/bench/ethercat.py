"""``eha-hil bench ethercat``: time per bus cycle of the ESC chain (hydra_full), in this
process, after the in-process master (:mod:`hil.fieldbus.esc.master`) brought every slave
to OP.

Per cycle two figures (median and 99th percentile, wall ``time.perf_counter``):

* round trip: the cycle's LRW frames through the chain and back (encode, every ESC, decode)
  — what a master waits for on top of the wire;
* box cycle: one 1 ms step of the slaves' watchdogs and the boxes behind them.

Every actuator is enabled with a force command of its own. Rows: every box an echo model;
the same with the full stack (plant, driver boards, LVDS, MCU)
behind box 0. CPU time over wall time of the timed loop is given beside.

``--wire`` (root, pysoem): the same two rows with SOEM over a veth pair
(:func:`bench_wire`), the chain served in its own process at 1 kHz.
"""

from __future__ import annotations

import struct
import time

import numpy as np

from hil.fieldbus import reply_times
from hil.fieldbus.esc.chain import EscChain
from hil.fieldbus.esc.master import EscMaster
from hil.fieldbus.pdo import slot_sizes
from hil.fieldbus.topology import load_topology
from plant.config import Config

WARMUP = 20


def bench_row(cfg: Config, stack_boxes: tuple[int, ...], cycles: int) -> dict:
    chain = EscChain(load_topology("hydra_full"), cfg, "echo", stack_boxes)
    master = EscMaster(chain)
    master.bring_up()
    # Every actuator enabled with its own force command (as the bus benchmark's PC loop).
    j = 0
    for box, s in zip(chain.topology.boxes, master.slaves, strict=True):
        o = s.out_lad
        for slot in box.slots:
            if slot.kind == "actuator":
                j += 1
                struct.pack_into("<BBi", master.image, o, 1, 1, 1000 * j)  # 10 N * j
            o += slot_sizes(slot.kind)[0]
    rt = np.empty(cycles)
    box = np.empty(cycles)
    bad = 0
    for _ in range(WARMUP):
        master.cycle()
        chain.cycle()
    clock = time.perf_counter
    cpu0, wall0 = time.process_time(), clock()
    for k in range(cycles):
        t0 = clock()
        wkc = master.cycle()
        t1 = clock()
        chain.cycle()
        t2 = clock()
        rt[k], box[k] = t1 - t0, t2 - t1
        bad += wkc != master.expected_wkc
    wall = clock() - wall0
    cpu = time.process_time() - cpu0
    return {"boxes": "echo" if not stack_boxes else f"echo + full stack behind box "
            f"{', '.join(map(str, stack_boxes))}", "cycles": cycles,
            "frames_per_cycle": len(master.pieces), "image_bytes": len(master.image),
            "rt_median_us": float(np.median(rt) * 1e6),
            "rt_p99_us": float(np.percentile(rt, 99) * 1e6),
            "box_median_us": float(np.median(box) * 1e6),
            "box_p99_us": float(np.percentile(box, 99) * 1e6),
            "cpu_over_wall": cpu / wall, "wkc_errors": bad}


def bench_ethercat(cfg: Config, cycles: int = 2000) -> list[dict]:
    return [bench_row(cfg, (), cycles), bench_row(cfg, (0,), max(cycles // 4, 50))]


def bench_wire(model: str = "robot", seconds: float = 60.0, bring_ups: int = 25,
               busy_cpu: int | None = None, progress=None) -> dict:  # noqa: ANN001
    """SOEM (pysoem, stock timeouts) against ``serve --transport ethercat --model MODEL
    --realtime`` over a veth pair in a network namespace of its own, hydra_full: ``bring_ups``
    bring-ups to OP (no step retried), then ``seconds`` of 1 kHz cycles with every actuator
    commanded. Round trip = SOEM's send + receive of a cycle's frames, in the master's
    process, as a 1 us histogram (memory bounded for any length). ``busy_cpu``: a process
    of this benchmark's own keeps that CPU busy (SCHED_OTHER) during the cycles.
    ``progress(line)``: the master's progress lines. Root only."""
    from hil.fieldbus.esc.veth import run_master, start_serve, stop_serve, veth_namespace

    load0 = _load()
    with veth_namespace() as ns:
        serve = start_serve(ns, "--model", model)
        try:
            ups = run_master(ns, "bringups", str(bring_ups), str(IMAGE_BYTES),
                             timeout_s=60 + 10 * bring_ups) if bring_ups \
                else {"bring_ups": 0, "bring_ups_ok": 0, "failed": []}
            with _busy(busy_cpu):
                load1 = _load()
                res = run_master(ns, "rtt", str(int(seconds * 1000)),
                                 timeout_s=seconds * 1.5 + 120, progress=progress)
        finally:
            report = stop_serve(serve)
    hist = np.zeros(reply_times.HIST_US + 1, dtype=np.int64)
    for us, count in res["rtt_hist"].items():
        hist[int(us)] = count
    return {"model": model, "seconds": seconds, "load_before": load0,
            "load_cycles_start": load1, "load_after": _load(), "busy_cpu": busy_cpu,
            **ups, "cycles": res["rtt_cycles"], "wkc_errors": res["bad_wkc"],
            "rtt_us": reply_times.summary(hist, res["rtt_max_us"]),
            "rtt_histogram_us": reply_times.decades(hist),
            "serve": {k: report.get(k) for k in SERVE_KEYS}}


#: What the benchmark keeps of serve's report (hil.cli.serve, --json).
SERVE_KEYS = ("reply_us", "frames_answered", "frames_late", "cycles", "overruns",
              "slipped_cycles", "lag_max_ms", "lag_max_at_s", "worst_cycle_ms", "wall_s",
              "realtime", "failures", "exit_code", "frame_gap_max_us", "frame_work_max_us",
              "frame_run_delay_ms", "box_run_delay_ms", "steal_ms", "late_replies",
              "start_monotonic_s")


class _busy:
    """A process that keeps one CPU busy (a loop at SCHED_OTHER pinned to ``cpu``) for the
    duration of the ``with``; nothing if ``cpu`` is None."""

    def __init__(self, cpu: int | None) -> None:
        self.cpu = cpu
        self.proc = None

    def __enter__(self) -> None:
        if self.cpu is None:
            return
        import subprocess
        import sys

        self.proc = subprocess.Popen(
            [sys.executable, "-c", "import os, sys\n"
             f"os.sched_setaffinity(0, {{{self.cpu}}})\nwhile True: pass"])

    def __exit__(self, *exc: object) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()


IMAGE_BYTES = 1552  # hydra_full's process image (docs/ethercat-slaves.md)


def _load() -> str:
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


def format_wire(r: dict) -> str:
    s = r["serve"]
    q = reply_times.line
    steal = s.get("steal_ms") or {}
    late = s.get("late_replies") or []
    lines = [
        f"EtherCAT over a veth pair: SOEM (stock timeouts, 1 kHz) <-> serve --model "
        f"{r['model']} --realtime (hydra_full, 16 slaves), {r['seconds']:g} s"
        + (f", CPU {r['busy_cpu']} held busy by another process" if r["busy_cpu"] is not None
           else ""),
        f"load average (1/5/15 min) before {r['load_before']}, at the cycles' start "
        f"{r['load_cycles_start']}, after {r['load_after']} (the figures are this "
        "machine's under that load)",
        "| what | value |", "|---|---:|",
        f"| bring-ups to OP, no step retried | {r['bring_ups_ok']} of {r['bring_ups']} |",
        f"| cycles / with a wrong working counter | {r['cycles']} / {r['wkc_errors']} |",
        f"| round trip at the master p50 / p99 / p99.9 / max | {q(r['rtt_us'])} |",
        f"| reply time in the slaves p50 / p99 / p99.9 / max | {q(s['reply_us'])} |",
        f"| replies later than 1 ms | {s['frames_late']} of {s['frames_answered']} |",
        f"| frame thread: longest absence past its 1 ms poll / longest work | "
        f"{s['frame_gap_max_us']:.0f} / {s['frame_work_max_us']:.0f} us |",
        f"| frame / box thread waited for its CPU (in this machine) | "
        f"{_opt(s['frame_run_delay_ms'])} / {_opt(s['box_run_delay_ms'])} ms |",
        f"| time the hypervisor stole from the CPUs during the serving | "
        f"{', '.join(f'{c} {v:.0f} ms' for c, v in steal.items()) or 'unknown'} |",
        f"| box cycles run / overran / slipped | {s['cycles']} / {s['overruns']} / "
        f"{s['slipped_cycles']} |",
        f"| lag of simulated behind wall time, max | {s['lag_max_ms']:.2f} ms "
        f"(at {s['lag_max_at_s']:.1f} s) |",
        f"| box cycle compute, worst | {s['worst_cycle_ms']:.2f} ms |",
        f"| real time | {', '.join(s['realtime']['applied']) or 'off'} |",
    ]
    if late:
        worst = sorted(late, key=lambda e: -e["reply_us"])[:5]
        lines.append(f"late replies (worst of the first {len(late)}): " + "; ".join(
            f"at {e['at_s']:.3f} s {e['reply_us']:.0f} us (woke after {e['wake_us']:.0f}, "
            f"work {e['work_us']:.0f})" for e in worst))
    if r["failed"]:
        lines.append(f"failed bring-ups: {r['failed']}")
    if s["failures"]:
        lines.append("serve reported: " + "; ".join(s["failures"]))
    return "\n".join(lines)


def _opt(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def format_table(rows: list[dict]) -> str:
    lines = ["| hydra_full, 16 ESC slaves | round trip median / p99 [us] | box cycle median / "
             "p99 [us] | CPU / wall | WKC errors |", "|---|---:|---:|---:|---:|"]
    for r in rows:
        box = ("-" if r["box_median_us"] != r["box_median_us"]  # NaN: not measured
               else f"{r['box_median_us']:.0f} / {r['box_p99_us']:.0f}")
        cpu = "-" if r["cpu_over_wall"] != r["cpu_over_wall"] else f"{r['cpu_over_wall']:.2f}"
        lines.append(f"| {r['boxes']} ({r['cycles']} cycles, {r['frames_per_cycle']} frames) "
                     f"| {r['rt_median_us']:.0f} / {r['rt_p99_us']:.0f} | {box} | {cpu} | "
                     f"{r['wkc_errors']} |")
    return "\n".join(lines)
