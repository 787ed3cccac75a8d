"""Build and run the MCU law's C (``firmware_model/mcu/c/``): a shared library for the host
(ctypes) and a bare-metal Cortex-M4F image for QEMU's ``netduinoplus2``.

The contraction decision: GCC in its GNU C modes contracts ``a * b + c`` into one fused
multiply-add (on the Cortex-M4F ``vfma.f32``, rounded once), where the Python model rounds
the product and the sum separately. Every build here therefore pins ``-ffp-contract=off``
(``contract="fast"`` exists only to show that the comparison catches the difference)."""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import struct
import subprocess
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from firmware_model.mcu.c_abi import CONFIG, INPUT, OUTPUT

SOURCE_DIR = Path(__file__).resolve().parents[2] / "firmware_model" / "mcu" / "c"
#: The host library: the law and its lanes (mcu_law_lanes.c, the robot engine's batches).
LAW = ("mcu_law.c", "mcu_law_lanes.c")
IMAGE = ("target/startup.c", "target/main.c", "mcu_law.c")
CONTRACTIONS = ("off", "fast")

COMMON_FLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror=double-promotion")
#: -Bsymbolic: the library's calls between its own functions bind to its own definitions.
#: Without it, a build loaded after another one whose symbols are global (the robot
#: engine's, which numba calls by name) would run the first one's functions inside.
HOST_FLAGS = (*COMMON_FLAGS, "-fPIC", "-shared", "-Wl,-Bsymbolic")
#: The host build with contraction: x86-64 needs -mfma for a fused multiply-add to exist.
HOST_FMA_FLAGS = ("-mfma",)
TARGET_FLAGS = (*COMMON_FLAGS, "-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16",
                "-mfloat-abi=hard", "-ffunction-sections", "-fdata-sections",
                "--specs=rdimon.specs", "-nostartfiles", "-T", "target/netduinoplus2.ld",
                "-Wl,--gc-sections")
ARM_GCC = "arm-none-eabi-gcc"
ARM_OBJDUMP = "arm-none-eabi-objdump"
QEMU = "qemu-system-arm"
QEMU_ARGS = ("-M", "netduinoplus2", "-nographic", "-semihosting-config",
             "enable=on,target=native", "-icount", "shift=0")
FUSED = ("vfma", "vfms", "vfnma", "vfnms")
MAGIC = 0x4C55434D  # "MCUL"


class BuildError(RuntimeError):
    """A compiler, QEMU or the image failed; the message says which and why."""


def missing_tools(target: str) -> list[str]:
    """The system tools ``target`` ("host-c", "qemu" or "image") needs that are not
    installed."""
    tools = {"host-c": (host_compiler() or "cc",),
             "qemu": (ARM_GCC, ARM_OBJDUMP, QEMU),
             "image": (ARM_GCC, host_compiler() or "cc")}[target]
    return [t for t in tools if shutil.which(t) is None]


def host_compiler() -> str | None:
    return next((c for c in (os.environ.get("CC"), "cc", "gcc") if c and shutil.which(c)), None)


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "eha-hil" / "mcu-c"


def _build(compiler: str, flags: tuple[str, ...], sources: tuple[str, ...], name: str) -> Path:
    """Compile the law's ``sources`` once per content and flags into the cache."""
    inputs = sorted(SOURCE_DIR.rglob("*.[ch]")) + [SOURCE_DIR / "target/netduinoplus2.ld"]
    return compile_cached(compiler, flags, sources, inputs, name, cwd=SOURCE_DIR)


def compile_cached(compiler: str, flags: tuple[str, ...], sources: Sequence[str | Path],
                   inputs: Iterable[Path], name: str, cwd: Path | None = None) -> Path:
    """Compile ``sources`` into ``name`` once per compiler, flags and the bytes of ``inputs``
    (every file the build reads), in the cache; the output path. Written under a temporary
    name and renamed, so a build killed half-way leaves nothing a later run would trust."""
    digest = hashlib.sha256(" ".join((compiler, *flags)).encode())
    for path in inputs:
        digest.update(path.read_bytes())
    out = _cache_dir() / digest.hexdigest()[:16] / name
    if out.exists():
        return out
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(f".tmp{os.getpid()}")
        cmd = [compiler, *flags, *map(str, sources), "-o", str(tmp)]
        r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
        if r.returncode:
            raise BuildError(f"{compiler} failed on {', '.join(Path(s).name for s in sources)}"
                             f": {_first_error(r.stderr)}")
        tmp.replace(out)
    except OSError as exc:
        raise BuildError(f"cannot build into {out.parent}: {exc}") from None
    return out


def _first_error(text: str) -> str:
    """The compiler's first error line (the rest of its output follows from it)."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return next((ln for ln in lines if "error" in ln), lines[0] if lines else "no message")


def _contract_flag(contract: str) -> str:
    if contract not in CONTRACTIONS:
        raise ValueError(f"contract {contract!r}: expected one of {', '.join(CONTRACTIONS)}")
    return f"-ffp-contract={contract}"


def host_flags(contract: str = "off") -> tuple[str, ...]:
    extra = HOST_FMA_FLAGS if contract == "fast" else ()
    return (*HOST_FLAGS, *extra, _contract_flag(contract))


def target_flags(contract: str = "off") -> tuple[str, ...]:
    return (*TARGET_FLAGS, _contract_flag(contract))


def build_host(contract: str = "off") -> Path:
    """The host shared library (``libmcu_law.so``)."""
    compiler = host_compiler()
    if compiler is None:
        raise BuildError("no C compiler (cc, gcc or $CC) found")
    return _build(compiler, host_flags(contract), LAW, f"libmcu_law-{contract}.so")


def build_image(contract: str = "off") -> Path:
    """The netduinoplus2 image (``mcu_law-<contract>.elf``)."""
    return _build(ARM_GCC, target_flags(contract), IMAGE, f"mcu_law-{contract}.elf")


def fused_instructions(elf: Path) -> list[str]:
    """Lines of ``elf``'s disassembly that are fused multiply-adds."""
    r = subprocess.run([ARM_OBJDUMP, "-d", str(elf)], capture_output=True, text=True,
                       check=True)
    return [line.strip() for line in r.stdout.splitlines()
            if any(f"\t{op}" in line or f" {op}." in line for op in FUSED)]


class HostLaw:
    """The host library through ctypes."""

    def __init__(self, path: Path) -> None:
        lib = ctypes.CDLL(str(path))
        lib.mcu_law_sizes.argtypes = [ctypes.c_uint32]
        lib.mcu_law_sizes.restype = ctypes.c_uint32
        sizes = tuple(lib.mcu_law_sizes(k) for k in range(3))
        if sizes != (CONFIG.itemsize, INPUT.itemsize, OUTPUT.itemsize):
            raise BuildError(f"{path}: record sizes {sizes} differ from the Python records")
        lib.mcu_law_run.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint32,
                                    ctypes.c_void_p]
        lib.mcu_law_run.restype = None
        lib.mcu_law_init.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        lib.mcu_law_init.restype = None
        lib.mcu_law_step.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        lib.mcu_law_step.restype = None
        lib.mcu_law_step_many.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint32,
                                          ctypes.c_void_p]
        lib.mcu_law_step_many.restype = None
        self.state_size = lib.mcu_law_sizes(3)
        for name, args in (("mcu_lanes_load", 4), ("mcu_lanes_step", 5),
                           ("mcu_lanes_store", 5)):
            fn = getattr(lib, name)
            fn.argtypes = [ctypes.c_void_p] * (args - 1) + [ctypes.c_uint32]
            fn.restype = None
        lib.mcu_lanes_size.restype = ctypes.c_uint32
        lib.mcu_lanes_build.argtypes = [ctypes.c_int32]
        lib.mcu_lanes_build.restype = ctypes.c_int32
        #: Bytes of one batch's lanes (``mcu_lanes``: :meth:`lanes_load`).
        self.lanes_size = lib.mcu_lanes_size()
        self._lib = lib

    def init(self, state: ctypes.Array, config: np.ndarray) -> None:
        """A fresh program state in ``state`` (``state_size`` bytes)."""
        self._lib.mcu_law_init(state, np.ascontiguousarray(config, dtype=CONFIG).ctypes.data)

    def step(self, state: ctypes.Array, inp: np.ndarray, out: np.ndarray) -> None:
        """One cycle: ``inp`` and ``out`` are single records (0-d arrays)."""
        self._lib.mcu_law_step(state, inp.ctypes.data, out.ctypes.data)

    def step_many(self, states: np.ndarray, inp: np.ndarray, out: np.ndarray) -> None:
        """One cycle of ``len(inp)`` programs: ``states`` holds their states back to back
        (``state_size`` bytes each), ``inp`` and ``out`` are arrays of records."""
        self._lib.mcu_law_step_many(states.ctypes.data, inp.ctypes.data, len(inp),
                                    out.ctypes.data)

    def lane_buffer(self) -> np.ndarray:
        """Room for one batch's lanes (``mcu_lanes``, zeros), on a 64-byte boundary."""
        raw = np.zeros(self.lanes_size + 64, dtype=np.uint8)
        skip = -raw.ctypes.data % 64
        return raw[skip:skip + self.lanes_size]

    def lanes_load(self, lanes: np.ndarray, states: np.ndarray, rows: np.ndarray) -> None:
        """The programs ``states`` (back to back, ``state_size`` bytes each) of ``rows``
        (int64, at most ``MCU_LW``) into the lanes of ``lanes`` (:meth:`lane_buffer`)."""
        rows = self._rows(rows)
        self._lib.mcu_lanes_load(lanes.ctypes.data, states.ctypes.data, rows.ctypes.data,
                                 len(rows))

    def lanes_step(self, lanes: np.ndarray, inp: np.ndarray, out: np.ndarray,
                   rows: np.ndarray) -> None:
        """One step of the loaded lanes, their input records ``inp[rows]``; their
        downstream words into ``out[rows]``."""
        rows = self._rows(rows)
        self._lib.mcu_lanes_step(lanes.ctypes.data, inp.ctypes.data, out.ctypes.data,
                                 rows.ctypes.data, len(rows))

    def lanes_store(self, lanes: np.ndarray, states: np.ndarray, out: np.ndarray,
                    rows: np.ndarray) -> None:
        """The lanes back into ``states`` of ``rows`` and their output records ``out[rows]``."""
        rows = self._rows(rows)
        self._lib.mcu_lanes_store(lanes.ctypes.data, states.ctypes.data, out.ctypes.data,
                                  rows.ctypes.data, len(rows))

    def lanes_build(self, avx2: int = -1) -> int:
        """Which build of the lane step runs (1: AVX2, 0: any x86-64); 0 or 1 selects it
        (1 only on a CPU with AVX2), for every caller of this library."""
        return int(self._lib.mcu_lanes_build(avx2))

    @staticmethod
    def _rows(rows: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(rows, dtype=np.int64)

    def init_at(self, address: int, config: np.ndarray) -> None:
        """A fresh program state at ``address`` (``state_size`` bytes)."""
        self._lib.mcu_law_init(address, np.ascontiguousarray(config, dtype=CONFIG).ctypes.data)

    def run(self, config: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """n steps from a fresh state."""
        config = np.ascontiguousarray(config, dtype=CONFIG)
        inputs = np.ascontiguousarray(inputs, dtype=INPUT)
        out = np.zeros(len(inputs), dtype=OUTPUT)
        self._lib.mcu_law_run(config.ctypes.data, inputs.ctypes.data, len(inputs),
                              out.ctypes.data)
        return out


def run_qemu(elf: Path, config: np.ndarray, inputs: np.ndarray,
             timeout_s: float = 3600.0) -> np.ndarray:
    """Run ``elf`` on the emulated netduinoplus2 over ``inputs``; its outputs."""
    with tempfile.TemporaryDirectory(prefix="eha-hil-qemu-") as tmp:
        work = Path(tmp)
        with open(work / "mcu_in.bin", "wb") as f:
            f.write(struct.pack("<5I", MAGIC, CONFIG.itemsize, INPUT.itemsize, OUTPUT.itemsize,
                                len(inputs)))
            f.write(np.asarray(config, dtype=CONFIG).tobytes())
            f.write(np.ascontiguousarray(inputs, dtype=INPUT).tobytes())
        cmd = [QEMU, *QEMU_ARGS, "-kernel", str(elf)]
        try:
            r = subprocess.run(cmd, cwd=work, capture_output=True, text=True,
                               timeout=timeout_s)
        except subprocess.TimeoutExpired as exc:
            raise BuildError(f"{QEMU} did not finish within {timeout_s:g} s") from exc
        if r.returncode:
            message = (r.stderr or r.stdout).strip().splitlines()
            raise BuildError(f"{QEMU} exited with {r.returncode}: "
                             f"{message[-1] if message else 'no message'}")
        out = np.fromfile(work / "mcu_out.bin", dtype=OUTPUT)
    if len(out) != len(inputs):
        raise BuildError(f"the image wrote {len(out)} outputs for {len(inputs)} inputs")
    return out
