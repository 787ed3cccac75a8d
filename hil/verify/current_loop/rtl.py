"""Build the current loop's RTL with Icarus Verilog and replay vectors through it under
cocotb (:mod:`hil.verify.current_loop.testbench`)."""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from firmware_model.fpga.current_loop import LOOP_INPUT, LOOP_OUTPUT
from hil.sim.verilator import RTL_DIR, RtlError, rtl_sources

__all__ = ["RTL_DIR", "RtlError", "missing_tools", "rtl_sources", "run_rtl"]

TOPLEVEL = "tb_current_loop"
TESTBENCH = Path(__file__).resolve().parent / "tb_current_loop.v"
ROOT = Path(__file__).resolve().parents[3]


def missing_tools() -> list[str]:
    """What the RTL check needs that is not installed."""
    missing = [t for t in ("iverilog", "vvp") if shutil.which(t) is None]
    try:
        import cocotb_tools.runner  # noqa: F401
    except ImportError:
        missing.append("cocotb (pip install 'eha-hil[test]')")
    return missing


def run_rtl(inputs: np.ndarray, rtl_dir: Path = RTL_DIR) -> np.ndarray:
    """Replay ``inputs`` through the RTL in ``rtl_dir``; one output record per input."""
    from cocotb_tools.runner import get_runner

    rtl_dir = Path(rtl_dir)
    sources = rtl_sources(rtl_dir)
    with tempfile.TemporaryDirectory(prefix="eha-hil-rtl-") as tmp:
        work = Path(tmp)
        vec, res = work / "vectors.npy", work / "outputs.npy"
        np.save(vec, np.ascontiguousarray(inputs, dtype=LOOP_INPUT))
        runner = get_runner("icarus")
        log = work / "build.log"
        try:
            with open(log, "w") as out, _redirect(out):
                runner.build(sources=[*sources, TESTBENCH], includes=[rtl_dir],
                             hdl_toplevel=TOPLEVEL, build_dir=work / "build", always=True,
                             timescale=("1ns", "1ps"))
                path = os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))
                runner.test(hdl_toplevel=TOPLEVEL, test_module="hil.verify.current_loop.testbench",
                            build_dir=work / "build", test_dir=work,
                            extra_env={"EHA_RTL_VECTORS": str(vec),
                                       "EHA_RTL_OUTPUTS": str(res), "PYTHONPATH": path})
        except (SystemExit, Exception) as exc:  # the runner exits on a failed build
            raise RtlError(f"the RTL in {rtl_dir} did not build or run: "
                           f"{_last_error(log) or exc}") from None
        if not res.exists():
            raise RtlError(f"the cocotb run of {rtl_dir} wrote no outputs: {_last_error(log)}")
        out = np.load(res)
    if out.dtype != LOOP_OUTPUT or len(out) != len(inputs):
        raise RtlError(f"the RTL gave {len(out)} outputs for {len(inputs)} inputs")
    return out


def _last_error(log: Path) -> str:
    try:
        lines = [ln.strip() for ln in log.read_text().splitlines() if ln.strip()]
    except OSError:
        return ""
    errors = [ln for ln in lines if "error" in ln.lower()]
    return (errors or lines or [""])[-1][:300]


class _redirect:
    """Send the runner's chatter (stdout and stderr, both file descriptors) to a log."""

    def __init__(self, file) -> None:
        self.file = file

    def __enter__(self):
        sys.stdout.flush()
        sys.stderr.flush()
        self.saved = (os.dup(1), os.dup(2))
        os.dup2(self.file.fileno(), 1)
        os.dup2(self.file.fileno(), 2)
        return self

    def __exit__(self, *exc) -> None:
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(self.saved[0], 1)
        os.dup2(self.saved[1], 2)
        os.close(self.saved[0])
        os.close(self.saved[1])
