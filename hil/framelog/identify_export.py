"""A frame log as an identification CSV (``eha-hil log export LOG --format identify OUT``).

What identification needs of a run is what the MCU read from one driver board: the
board's upstream register memory (``UP_REGISTERS`` of ``firmware_model/fpga/layout.py``),
which every MCU-level log carries once per MCU step:

* ``/lvds/<b>.<k>/up``, encoding ``eha-hil/mcu-up`` (``eha-hil bus run --log``: the link's
  upstream words + the MCU side's CRC-error count, uint16 x 34; uint32 x 33 in older
  logs), or
* ``/lvds/<board>/up``, encoding ``eha-hil/lvds-up`` (one u16 per register, the documented
  snapshot).

The registers are turned into the SI columns of :mod:`hil.identify.csvdata` as the MCU
decodes them (:mod:`firmware_model.mcu.measure`, in float64), with the sensor scales of the
firmware calibration of the log's own configuration (``[firmware]``: what the firmware
believes, not the plant's truth): ``iq`` (register ``iq``, mA), ``theta_m`` (the ABI
counter ``abi_count``, unwrapped; 0 at rotor angle 0 as the encoder counts), the five
pressures (ADC code -> volts -> Pa gauge), ``x_piston`` (BiSS count -
``firmware.biss_zero_count``, 5 nm), ``f_strain`` (AD7195 code, offset binary,
``firmware.strain_full_scale_n``), ``temp_c`` (temperature ADC code). ``t`` is the
frame's simulated time. The leading frames from before the board's first upstream sweep
reached the MCU (the memory's last word, the board's tick counter, still 0: every register
still 0) are left out. The load case comes from ``load.kind`` of the logged configuration,
the sample rate from the MCU period (``mcu.period_ticks`` x ``sim.tick_ns``), checked
against the frame times.

Anything missing -- no upstream channel, no configuration, a load kind identification has
no model for (``cart``), several boards and no ``board`` chosen -- is a
:class:`~hil.framelog.reader.FrameLogError` of one line.
"""

from __future__ import annotations

import json
import os
import re
import sys
import tomllib
from dataclasses import dataclass

import numpy as np

from firmware_model.fpga import layout as B
from hil.framelog.formats import ENC_MCU_UP, MCU_UP_WIDTH, MCU_UP_WIDTH_U32
from hil.framelog.reader import FrameLogError, FrameLogReader, LogInfo

#: Frame encodings that carry a board's upstream registers, and the words each frame has.
UP_ENCODINGS: dict[str, tuple[int, ...]] = {
    ENC_MCU_UP: (MCU_UP_WIDTH, MCU_UP_WIDTH_U32), "eha-hil/lvds-up": (len(B.UP_REGISTERS),)}
#: Plant load kind -> identification load case (``hil.identify.csvdata.LOAD_CASES``).
LOAD_CASE_OF_KIND: dict[str, str] = {"fixed": "fixed_piston", "free": "free_piston",
                                     "conrod": "conrod_fixed"}
#: Columns written, in the order of the identification CSV.
COLUMNS: tuple[str, ...] = ("t", "iq", "theta_m", "p_pump_a", "p_pump_b", "p_cyl_a",
                            "p_cyl_b", "p_acc", "x_piston", "f_strain", "temp_c")
_BOARD_OF_TOPIC = re.compile(r"^/lvds/(?P<board>[^/]+)/up$")
#: CSV column -> the MCU's measurement it holds (:func:`firmware_model.mcu.measure.
#: upstream_si`), in column order.
_COLUMNS = (("iq", "iq"), ("theta_m", "theta_m"), ("p_pump_a", "p_pump_a"),
            ("p_pump_b", "p_pump_b"), ("p_cyl_a", "p_cyl_a"), ("p_cyl_b", "p_cyl_b"),
            ("p_acc", "p_acc"), ("x_piston", "x_piston"), ("f_strain", "f_strain_raw"),
            ("temp_c", "temperature_c"))


@dataclass(frozen=True)
class IdentifyExport:
    """What :func:`export_identify` wrote: rows, load case, rate, board and topic, and how
    many leading frames were left out (before the first upstream sweep)."""

    rows: int
    load: str
    sample_rate_hz: float
    board: str
    topic: str
    skipped: int = 0


def _config(path: str, info: LogInfo):  # noqa: ANN202 - plant.config.Config
    """The run's configuration from the log's metadata (replay record: JSON; the
    ``eha-hil`` record's ``config``: JSON or TOML), checked against the schema."""
    from plant.config import Config, ConfigError, as_recorded, schema

    text = None
    for name in ("eha-hil.replay", "eha-hil"):
        text = info.metadata.get(name, {}).get("config")
        if text is not None:
            break
    if text is None:
        cut = f" (truncated: {info.stop_reason})" if info.truncated else ""
        raise FrameLogError(f"{path}: no run configuration in the log's metadata{cut}: the "
                            "load case and the sensor scales are unknown (--format identify "
                            "needs a log of `eha-hil bus run --log`)")
    try:
        try:
            tree = json.loads(text)
        except ValueError:
            tree = tomllib.loads(text)
        if not isinstance(tree, dict):
            raise ValueError("not a table")
        flat: dict[str, object] = {}

        def walk(node: dict, prefix: str) -> None:
            for k, v in node.items():
                if isinstance(v, dict):
                    walk(v, f"{prefix}{k}.")
                else:
                    flat[f"{prefix}{k}"] = v

        walk(tree, "")
        # a log from before [firmware] was built with the plant's values
        return Config(schema(), [f"log {path}"]).with_overrides(as_recorded(flat),
                                                                 f"log {path}")
    except (ValueError, tomllib.TOMLDecodeError, ConfigError) as exc:
        raise FrameLogError(f"{path}: run configuration in the metadata: {exc}") from None


def _boards(info: LogInfo) -> dict[str, tuple[str, str]]:
    """Board name -> (topic, encoding) of every upstream-register channel in the log."""
    out = {}
    for c in info.channels:
        m = _BOARD_OF_TOPIC.match(c.topic)
        if m and c.encoding in UP_ENCODINGS:
            out[m.group("board")] = (c.topic, c.encoding)
    return out


def signals(up: np.ndarray, cfg) -> dict[str, np.ndarray]:  # noqa: ANN001 - Config
    """SI columns (without ``t``) of upstream register frames ``up`` (n, >= 31 words),
    decoded by the MCU's model with the sensor scales of the firmware calibration ``cfg``
    (a configuration or a :class:`~firmware_model.calibration.FirmwareCalibration`)."""
    from firmware_model.calibration import calibration
    from firmware_model.mcu.measure import upstream_si

    si = upstream_si(up, calibration(cfg))
    return {column: si[name] for column, name in _COLUMNS}


def export_identify(log_path: str | os.PathLike[str], out_path: str | os.PathLike[str],
                    board: str | None = None, info: LogInfo | None = None) -> IdentifyExport:
    """Write the identification CSV of one board of ``log_path`` to ``out_path`` ("-":
    stdout); see the module docstring. ``board``: e.g. ``0.0``; needed only when the log
    has several. A truncated log exports what is readable. FrameLogError (one line) when
    the log cannot give what identification needs."""
    path = str(log_path)
    reader = FrameLogReader(log_path)
    if info is None:
        info = reader.info()
    boards = _boards(info)
    if not boards:
        raise FrameLogError(
            f"{path}: no upstream register channel (/lvds/<board>/up, "
            f"{' or '.join(UP_ENCODINGS)}): identification needs the current and sensors the "
            "MCU read; log at level mcu or full (eha-hil bus run --log FILE --level mcu)")
    if board is None:
        if len(boards) > 1:
            raise FrameLogError(f"{path}: {len(boards)} boards ({', '.join(boards)}): "
                                "choose one with --board")
        board = next(iter(boards))
    elif board not in boards:
        raise FrameLogError(f"{path}: no board {board!r} (boards: {', '.join(boards)})")
    topic, encoding = boards[board]
    cfg = _config(path, info)
    kind = cfg.get("load.kind")
    load = LOAD_CASE_OF_KIND.get(kind)
    if load is None:
        raise FrameLogError(f"{path}: load.kind = {kind!r}: identification has no load case "
                            f"for it (it fits {', '.join(LOAD_CASE_OF_KIND)}: "
                            f"{', '.join(LOAD_CASE_OF_KIND.values())})")
    period_ns = cfg.get("mcu.period_ticks") * cfg.get("sim.tick_ns")
    fs = 1e9 / period_ns
    t_ns, frames = reader.blocks(topic)
    if frames.ndim != 2 or frames.shape[1] not in UP_ENCODINGS[encoding]:
        raise FrameLogError(f"{path}: {topic}: frames of {frames.shape[-1]} words, "
                            f"{encoding} has "
                            f"{' or '.join(map(str, UP_ENCODINGS[encoding]))}")
    if len(t_ns) < 2:
        raise FrameLogError(f"{path}: {topic}: {len(t_ns)} frame(s): nothing to identify")
    steps = np.unique(np.diff(t_ns.astype(np.int64)))
    if steps.size != 1 or int(steps[0]) != period_ns:
        raise FrameLogError(f"{path}: {topic}: frames are not one per MCU period "
                            f"({period_ns} ns): steps of {steps[:5].tolist()} ns")
    # the MCU's memory is zero until the board's first upstream sweep has reached it; the
    # sweep ends with the tick counter, which is then non-zero
    filled = np.flatnonzero(frames[:, B.U_TICK] != 0)
    if filled.size == 0 or len(t_ns) - filled[0] < 2:
        raise FrameLogError(f"{path}: {topic}: the board's upstream memory never reached the "
                            "MCU (its tick counter stays 0): nothing to identify")
    skipped = int(filled[0])
    t_ns, frames = t_ns[skipped:], frames[skipped:]
    cols = signals(frames[:, :len(B.UP_REGISTERS)], cfg)
    # every value as its shortest exact text (repr): the CSV read back is the export, bit for
    # bit (a fixed number of digits moved values by ulps, and a fit's path with them)
    header = [f"# load: {load}", f"# sample_rate_hz: {float(fs)!r}",
              f"# source: eha-hil log export {os.path.basename(path)} --format identify "
              f"--board {board} (the MCU's reads of {topic}, SI units)"]
    t_s = [f"{t // 1_000_000_000}.{t % 1_000_000_000:09d}" for t in t_ns.tolist()]
    mat = np.column_stack([cols[c] for c in COLUMNS[1:]])
    body = [",".join([ts, *map(repr, row)]) for ts, row in
            zip(t_s, mat.tolist(), strict=True)]
    text = "\n".join([*header, ",".join(COLUMNS), *body]) + "\n"
    if str(out_path) == "-":
        sys.stdout.write(text)
    else:
        with open(out_path, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
    return IdentifyExport(len(t_ns), load, fs, board, topic, skipped)


__all__ = ["COLUMNS", "IdentifyExport", "LOAD_CASE_OF_KIND", "UP_ENCODINGS", "export_identify",
           "signals"]
