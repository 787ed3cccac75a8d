"""The current loop's RTL compiled with Verilator into a shared library with a C ABI
(``rtl_tick.cpp``), cached by a hash of everything that goes into it, and loaded with ctypes.

Build: Verilator turns the ``*.v`` of the RTL directory (top module ``current_loop``, its
parameters set from the board's constants) into C++; the ports it declares are checked
against the loop's port tables (:mod:`firmware_model.fpga.current_loop`); the wrapper is
generated for them and compiled with the C++ files and Verilator's runtime (compiled once
per Verilator version) into ``libcurrent_loop.so``. The cache key covers the RTL's bytes,
the parameters, the wrapper, the flags and the Verilator version, so an edited RTL builds
anew and an unchanged one loads in milliseconds. Cache: ``$XDG_CACHE_HOME/eha-hil/rtl-verilator``
(default ``~/.cache``), or ``$EHA_HIL_RTL_CACHE``.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware_model.fpga import layout as B
from firmware_model.fpga.current_loop import (
    INPUT_PORTS,
    INPUT_WIDTHS,
    OUTPUT_PORTS,
    OUTPUT_WIDTHS,
)
from firmware_model.fpga.rtl_abi import (
    IO_EDGE,
    IO_FIRST_MODEL,
    IO_FIRST_RTL,
    IO_FIRST_SIGNAL,
    IO_FIRST_TICK,
    IO_IN,
    IO_MISMATCHES,
    IO_OUT,
    IO_WORDS,
)
from plant.config import Config, ConfigError

RTL_DIR = Path(__file__).resolve().parents[2] / "firmware_model" / "fpga" / "rtl"
TOP = "current_loop"
WRAPPER = Path(__file__).resolve().parent / "rtl_tick.cpp"
#: Bumped when the C ABI of the wrapper changes (the library reports it; a mismatch rebuilds).
ABI = 1
VERILATOR = "verilator"
VERILATOR_FLAGS = ("--cc", "--top-module", TOP, "-Wno-fatal", "-Wno-lint", "-Wno-style",
                   "-O3", "--x-assign", "fast", "--x-initial", "fast", "--noassert")
CXX_FLAGS = ("-std=c++17", "-O2", "-fPIC", "-w")
#: The clock and reset beside the loop's ports.
CONTROL_PORTS = {"clk": 1, "rst": 1}
#: The top's parameters and the board constants (``layout.C_*``) they are set from.
PARAMETERS = {"TOP": B.C_PWM_TOP, "V_LIMIT": B.C_V_LIMIT, "MA_TO_I": B.C_MA_TO_I,
              "MV_TO_V": B.C_MV_TO_V, "KP_SHIFT": B.C_KP_SHIFT, "KI_SHIFT": B.C_KI_SHIFT}


class RtlError(RuntimeError):
    """The RTL did not build or the simulation failed; the message says why."""


def rtl_sources(rtl_dir: Path = RTL_DIR) -> list[Path]:
    """The Verilog files of ``rtl_dir`` (its ``*.v``; ``*.vh`` are included from there)."""
    sources = sorted(Path(rtl_dir).glob("*.v"))
    if not sources:
        raise RtlError(f"{rtl_dir}: no Verilog (*.v) files")
    return sources


def missing_tools() -> list[str]:
    """What the Verilator build needs that is not installed."""
    return [t for t in (VERILATOR, cxx()) if shutil.which(t) is None]


def cxx() -> str:
    return os.environ.get("CXX") or "g++"


def cache_dir() -> Path:
    own = os.environ.get("EHA_HIL_RTL_CACHE")
    if own:
        return Path(own)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "eha-hil" / "rtl-verilator"


def top_file(rtl_dir: Path) -> Path:
    """The file of ``rtl_dir`` that declares ``module current_loop``."""
    pattern = re.compile(rf"^\s*module\s+{TOP}\b", re.MULTILINE)
    for path in rtl_sources(rtl_dir):
        if pattern.search(path.read_text(errors="replace")):
            return path
    raise RtlError(f"{rtl_dir}: no file declares module {TOP} (the top must be named so)")


def parameters(c: np.ndarray) -> dict[str, int]:
    """The top's parameter values for the board constants ``c``."""
    return {name: int(c[index]) for name, index in PARAMETERS.items()}


def _run(cmd: list[str], cwd: Path, what: str) -> None:
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if r.returncode:
        raise RtlError(f"{what}: {first_error(r.stderr + r.stdout)}")


def first_error(text: str) -> str:
    """The first error line of a Verilator or compiler output (it names the file)."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    for mark in ("%Error", "error:", "Error"):
        for ln in lines:
            if mark in ln:
                return ln[:300]
    return lines[0][:300] if lines else "no message"


def declared_ports(header: Path) -> dict[str, tuple[str, int]]:
    """name -> (direction, width) of the ports in a Verilated model's header."""
    ports = {}
    for kind, name, msb, lsb in re.findall(
            r"VL_(IN|OUT)(?:8|16|64|W)?\(&(\w+),(\d+),(\d+)", header.read_text()):
        ports[name] = ("input" if kind == "IN" else "output", int(msb) - int(lsb) + 1)
    return ports


def expected_ports() -> dict[str, tuple[str, int]]:
    want = {n: ("input", w) for n, w in CONTROL_PORTS.items()}
    want |= {n: ("input", INPUT_WIDTHS[n]) for n in INPUT_PORTS}
    want |= {n: ("output", OUTPUT_WIDTHS[n]) for n in OUTPUT_PORTS}
    return want


def check_ports(got: dict[str, tuple[str, int]], where: Path) -> None:
    """RtlError naming the first port that is missing, extra or of another kind or width."""
    want = expected_ports()
    for name, (direction, width) in want.items():
        if name not in got:
            raise RtlError(f"{where}: module {TOP} has no {direction} port {name} "
                           f"({width} bit)")
        if got[name] != (direction, width):
            raise RtlError(f"{where}: port {name} is an {got[name][0]} of {got[name][1]} bit, "
                           f"expected an {direction} of {width} bit")
    extra = sorted(set(got) - set(want))
    if extra:
        raise RtlError(f"{where}: module {TOP} has ports the loop does not drive: "
                       f"{', '.join(extra)}")


def port_code() -> str:
    """The wrapper's port functions for the loop's port tables."""
    lines = ["inline void apply_inputs(Vcurrent_loop* t, const int64_t* in) {"]
    for k, name in enumerate(INPUT_PORTS):
        mask = (1 << INPUT_WIDTHS[name]) - 1
        lines.append(f"    t->{name} = static_cast<uint64_t>(in[{k}]) & 0x{mask:x}ULL;")
    lines += ["}", "", "inline void read_outputs(const Vcurrent_loop* t, int64_t* out) {"]
    for k, (name, signed) in enumerate(OUTPUT_PORTS.items()):
        width = OUTPUT_WIDTHS[name]
        value = (f"sign_extend(t->{name}, {width})" if signed
                 else f"static_cast<int64_t>(t->{name})")
        lines.append(f"    out[{k}] = {value};")
    lines.append("}")
    return "\n".join(lines)


def wrapper_source() -> str:
    text = WRAPPER.read_text()
    for key, value in {"PORT_CODE": port_code(), "ABI": ABI, "IO_IN": IO_IN, "IO_OUT": IO_OUT,
                       "IO_EDGE": IO_EDGE, "N_IN": len(INPUT_PORTS),
                       "N_OUT": len(OUTPUT_PORTS)}.items():
        text = text.replace(f"@{key}@", str(value))
    return text


@functools.cache
def _version() -> str:
    """Verilator's version line (asked once per process: the script starts in ~0.1 s)."""
    r = subprocess.run([VERILATOR, "--version"], capture_output=True, text=True)
    return r.stdout.strip()


def _runtime(root: Path, version: str) -> list[Path]:
    """Verilator's runtime objects (verilated.cpp and its threads), compiled once per
    Verilator version and compiler flags."""
    key = hashlib.sha256(f"{version} {cxx()} {CXX_FLAGS}".encode()).hexdigest()[:16]
    out = cache_dir() / f"runtime-{key}"
    objs = [out / "verilated.o", out / "verilated_threads.o"]
    if all(o.exists() for o in objs):
        return objs
    out.mkdir(parents=True, exist_ok=True)
    for obj in objs:
        tmp = obj.with_suffix(f".tmp{os.getpid()}")
        _run([cxx(), *CXX_FLAGS, "-c", f"-I{root}/include", f"-I{root}/include/vltstd",
              str(root / "include" / f"{obj.stem}.cpp"), "-o", str(tmp)], out,
             f"{cxx()} on Verilator's {obj.stem}.cpp")
        tmp.replace(obj)
    return objs


def build(rtl_dir: Path, c: np.ndarray) -> Path:
    """The library of the RTL in ``rtl_dir`` for the board constants ``c`` (cached)."""
    rtl_dir = Path(rtl_dir)
    missing = missing_tools()
    if missing:
        raise RtlError(f"{', '.join(missing)} not installed (make system-deps)")
    top = top_file(rtl_dir)
    params = parameters(c)
    version = _version()
    wrapper = wrapper_source()
    digest = hashlib.sha256(
        repr((version, VERILATOR_FLAGS, CXX_FLAGS, cxx(), sorted(params.items()))).encode())
    digest.update(wrapper.encode())
    for path in sorted(rtl_dir.glob("*.v")) + sorted(rtl_dir.glob("*.vh")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    lib = cache_dir() / digest.hexdigest()[:16] / f"lib{TOP}.so"
    if lib.exists():
        return lib
    try:
        _compile(rtl_dir, top, params, version, wrapper, lib)
    except OSError as exc:  # the cache cannot be written (permissions, a full disk)
        raise RtlError(f"cannot build into {lib.parent}: {exc}") from None
    return lib


def _compile(rtl_dir: Path, top: Path, params: dict[str, int], version: str, wrapper: str,
             lib: Path) -> None:
    root = Path(subprocess.run([VERILATOR, "--getenv", "VERILATOR_ROOT"], capture_output=True,
                               text=True).stdout.strip())
    lib.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="build-", dir=lib.parent) as tmp:
        work = Path(tmp)
        obj = work / "obj"
        _run([VERILATOR, *VERILATOR_FLAGS, f"-I{rtl_dir}",
              *(f"-G{k}={v}" for k, v in params.items()), "--Mdir", str(obj),
              *map(str, rtl_sources(rtl_dir))], work, f"{VERILATOR} on {rtl_dir}")
        check_ports(declared_ports(obj / f"V{TOP}.h"), top)
        (work / "rtl_tick.cpp").write_text(wrapper)
        generated = sorted(p for p in obj.glob(f"V{TOP}*.cpp"))
        out = work / lib.name
        _run([cxx(), *CXX_FLAGS, "-shared", f"-I{obj}", f"-I{root}/include",
              f"-I{root}/include/vltstd", str(work / "rtl_tick.cpp"), *map(str, generated),
              *map(str, _runtime(root, version)), "-o", str(out), "-pthread",
              "-Wl,-Bsymbolic"], work, f"{cxx()} on the Verilated {rtl_dir}")
        out.replace(lib)


def _signal(index: int) -> str:
    return list(OUTPUT_PORTS)[index]


class RtlLoop:
    """One Verilated current loop loaded from its library: its exchange buffer (``io``,
    :data:`~firmware_model.fpga.rtl_abi.IO_WORDS` int64) and the addresses the board's
    compiled tick calls (:meth:`attach`)."""

    def __init__(self, lib: Path, rtl_dir: Path | str = "") -> None:
        self.rtl_dir = str(rtl_dir)
        self._lib = ctypes.CDLL(str(lib))
        L = self._lib
        L.eha_rtl_abi.restype = ctypes.c_int64
        if L.eha_rtl_abi() != ABI:
            raise RtlError(f"{lib}: C ABI {L.eha_rtl_abi()}, expected {ABI}")
        L.eha_rtl_new.argtypes = [ctypes.c_void_p]
        L.eha_rtl_new.restype = ctypes.c_void_p
        L.eha_rtl_free.argtypes = [ctypes.c_void_p]
        L.eha_rtl_run.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                                  ctypes.c_int64]
        self.io = np.zeros(IO_WORDS, dtype=np.int64)
        self.handle = L.eha_rtl_new(self.io.ctypes.data)
        _LOADED.append((self.rtl_dir, self.io))
        self.tick_address = ctypes.cast(L.eha_rtl_tick, ctypes.c_void_p).value
        self.path = lib

    def attach(self, c: np.ndarray) -> None:
        """Point the board constants ``c`` at this model (``layout.C_RTL_*``)."""
        c[B.C_RTL_TICK] = self.tick_address
        c[B.C_RTL_HANDLE] = self.handle
        c[B.C_RTL_IO] = self.io.ctypes.data

    def tick_function(self) -> ctypes._CFuncPtr:
        """The library's per-tick function for a call from Python (``fn(loop.handle)``)."""
        fn = self._lib.eha_rtl_tick
        fn.argtypes = [ctypes.c_void_p]
        fn.restype = None
        return fn

    def run(self, inputs: np.ndarray) -> np.ndarray:
        """One tick (clock edge) per row of ``inputs`` (n x len(INPUT_PORTS) int64); the
        output ports of each (n x len(OUTPUT_PORTS) int64), continuing from the model's
        state."""
        x = np.ascontiguousarray(inputs, dtype=np.int64)
        out = np.zeros((len(x), len(OUTPUT_PORTS)), dtype=np.int64)
        self._lib.eha_rtl_run(self.handle, x.ctypes.data, out.ctypes.data, len(x))
        return out

    def divergence(self) -> Divergence | None:
        """Where the RTL in the loop first differed from the board model (None: never)."""
        return _divergence(self.rtl_dir, self.io)

    def __del__(self) -> None:
        handle = getattr(self, "handle", None)
        if handle:
            self._lib.eha_rtl_free(handle)
            self.handle = None


@dataclass(frozen=True)
class Divergence:
    """The first tick on which the RTL's outputs differed from the board model's on the same
    inputs and integrators, and how many ticks differed in all."""

    rtl_dir: str
    tick: int
    signal: str
    model: int
    rtl: int
    ticks: int

    def line(self) -> str:
        return (f"fpga.impl = 'rtl': the RTL in {self.rtl_dir} differs from the board model "
                f"first at tick {self.tick}, signal {self.signal}: model {self.model}, RTL "
                f"{self.rtl} ({self.ticks} ticks differ)")


def _divergence(rtl_dir: str, io: np.ndarray) -> Divergence | None:
    n = int(io[IO_MISMATCHES])
    if n == 0:
        return None
    return Divergence(rtl_dir, int(io[IO_FIRST_TICK]), _signal(int(io[IO_FIRST_SIGNAL])),
                      int(io[IO_FIRST_MODEL]), int(io[IO_FIRST_RTL]), n)


#: (RTL directory, exchange buffer) of every loop loaded in this process since the last
#: :func:`take_divergences`, so that a command can report a difference after the run even
#: when the stack that ran it is gone.
_LOADED: list[tuple[str, np.ndarray]] = []


def take_divergences() -> list[Divergence]:
    """The divergences of the loops loaded since the last call (and forget them)."""
    found = [d for d in (_divergence(r, io) for r, io in _LOADED) if d is not None]
    _LOADED.clear()
    return found


def load(cfg: Config, c: np.ndarray) -> RtlLoop:
    """The configured RTL (``fpga.rtl_dir``, default the project's) built for the board
    constants ``c`` and attached to them; ConfigError (one line) if it cannot be built."""
    text = cfg.get("fpga.rtl_dir")
    rtl_dir = Path(text) if text else RTL_DIR
    try:
        if not rtl_dir.is_dir():
            raise RtlError(f"{rtl_dir}: not a directory")
        loop = RtlLoop(build(rtl_dir, c), rtl_dir)
    except RtlError as exc:
        raise ConfigError(f"fpga.impl = 'rtl': {exc}") from None
    loop.attach(c)
    return loop


__all__ = ["RTL_DIR", "Divergence", "RtlError", "RtlLoop", "build", "cache_dir",
           "check_ports", "declared_ports", "load", "missing_tools", "take_divergences",
           "top_file"]
