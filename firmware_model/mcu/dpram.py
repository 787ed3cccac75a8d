"""The MCU board's dual-port memory: the STM32's window onto up to five driver boards.

Thesis 6.3.1: the MCU board's FPGA runs the five LVDS channels; the STM32 reaches it over its
external SRAM bus, which ends in a dual-port memory inside that FPGA, and a state machine
copies between the LVDS memories and that dual-port memory, so the MCU program reads and
writes any driver-board value as a plain variable. This module is that dual-port memory:
its address map, range-checked word access, named access per board, and the copy state
machine (:meth:`DualPortRam.sync`). The LVDS memories themselves are the
:class:`~firmware_model.fpga.driver_board.LinkMemory` objects the harness sweeps; this
module never touches a link.

Address map (16-bit words; board ``k`` = 0..4, block base ``0x40 k``):

    word address                    MCU access  content
    ------------------------------  ----------  -----------------------------------------
    0x40 k + 0x00 .. 0x40 k + 0x0F  read/write  board k downstream memory: register ``a``
                                                of ``layout.DOWN_REGISTERS`` at 0x40 k + a
                                                (0x0D..0x0F spare)
    0x40 k + 0x10 .. 0x40 k + 0x1F  none        reserved gap: any access raises ValueError
    0x40 k + 0x20 .. 0x40 k + 0x3F  read only   board k upstream memory: register ``a`` of
                                                ``layout.UP_REGISTERS`` at 0x40 k + 0x20 + a
                                                (0x1F spare)

Total 5 x 0x40 = 0x140 words (640 bytes). On the STM32F4's FSMC (16-bit SRAM mode) word
``a`` is the half-word at byte address ``bank + 2 a``. :func:`markdown` prints the map per
board as the table in ``docs/mcu.md``.

Copy order of :meth:`DualPortRam.sync` (one call per 5 kHz MCU cycle): first the downstream
blocks of boards 0, 1, ... into each ``LinkMemory.down`` (all 16 words), then each
``LinkMemory.up`` into the upstream blocks (all 32 words). :meth:`DualPortRam.sync_down`
and :meth:`DualPortRam.sync_up` are the two halves; a harness that calls
``sync_up -> Mcu.step -> sync_down`` adds no latency, one that calls ``sync -> Mcu.step``
sends what the MCU wrote one MCU period (200 us) later.
"""

from __future__ import annotations

import numpy as np

from firmware_model.calibration import FirmwareCalibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.driver_board import LinkMemory, from_word
from firmware_model.fpga.params import down_defaults

MAX_BOARDS = 5
BOARD_STRIDE = 0x40        # words per board block
DOWN_OFFSET = 0x00         # downstream block inside a board block
GAP_OFFSET = 0x10          # reserved gap
UP_OFFSET = 0x20           # upstream block inside a board block
DPRAM_WORDS = MAX_BOARDS * BOARD_STRIDE

_DOWN_TYPE = {name: typ for _, name, typ, *_ in B.DOWN_REGISTERS}
_UP_TYPE = {name: typ for _, name, typ, *_ in B.UP_REGISTERS}
assert not set(_DOWN_TYPE) & set(_UP_TYPE), "register names must be unique across directions"
assert B.DOWN_WORDS <= GAP_OFFSET - DOWN_OFFSET and B.UP_WORDS <= BOARD_STRIDE - UP_OFFSET


def _check_board(k: int) -> int:
    if not isinstance(k, int | np.integer) or not 0 <= k < MAX_BOARDS:
        raise ValueError(f"board index {k!r}: the MCU board serves boards 0..{MAX_BOARDS - 1}")
    return int(k)


def down_base(k: int) -> int:
    """Word address of board ``k``'s downstream block."""
    return _check_board(k) * BOARD_STRIDE + DOWN_OFFSET


def up_base(k: int) -> int:
    """Word address of board ``k``'s upstream block."""
    return _check_board(k) * BOARD_STRIDE + UP_OFFSET


def address(k: int, name: str) -> int:
    """Word address of register ``name`` (downstream or upstream) of board ``k``."""
    if name in _DOWN_TYPE:
        return down_base(k) + B.down_address(name)
    if name in _UP_TYPE:
        return up_base(k) + B.up_address(name)
    raise KeyError(f"no register {name!r} in the downstream or upstream map")


def decode(addr: int) -> tuple[int, str, int]:
    """(board, block, offset in the block) of a word address; block is "down", "up" or
    "reserved". ValueError outside 0 .. DPRAM_WORDS - 1."""
    if not isinstance(addr, int | np.integer) or not 0 <= addr < DPRAM_WORDS:
        raise ValueError(f"DPRAM address {addr!r} outside 0x000..0x{DPRAM_WORDS - 1:03X}")
    k, off = divmod(int(addr), BOARD_STRIDE)
    if off >= UP_OFFSET:
        return k, "up", off - UP_OFFSET
    if off >= GAP_OFFSET:
        return k, "reserved", off - GAP_OFFSET
    return k, "down", off - DOWN_OFFSET


def markdown() -> str:
    """The address map as a Markdown table (``docs/mcu.md`` carries this output)."""
    rows = ["| board | downstream (MCU writes) | reserved | upstream (MCU reads) |",
            "|---|---|---|---|"]
    for k in range(MAX_BOARDS):
        d, g, u = down_base(k), k * BOARD_STRIDE + GAP_OFFSET, up_base(k)
        rows.append(f"| {k} | 0x{d:03X}..0x{d + GAP_OFFSET - DOWN_OFFSET - 1:03X} "
                    f"| 0x{g:03X}..0x{g + UP_OFFSET - GAP_OFFSET - 1:03X} "
                    f"| 0x{u:03X}..0x{u + BOARD_STRIDE - UP_OFFSET - 1:03X} |")
    return "\n".join(rows)


class DpramBoard(LinkMemory):
    """Board ``k``'s two blocks of the dual-port memory, with the :class:`LinkMemory`
    interface: ``down`` and ``up`` are views into the DPRAM words, ``write(name, value)``
    sets a downstream register (typed, range-checked), ``read(name)`` returns any register
    (upstream: as last copied in; downstream: as the MCU wrote it). An :class:`Mcu` can run
    on these views exactly as on the link memories themselves."""

    def __init__(self, ram: DualPortRam, k: int) -> None:
        self.index = _check_board(k)
        d, u = down_base(k), up_base(k)
        self.down = ram.words[d:d + B.DOWN_WORDS]
        self.up = ram.words[u:u + B.UP_WORDS]
        self.up_crc_errors = 0

    def read(self, name: str) -> int:
        """A register by name, typed (s16 registers signed)."""
        if name in _UP_TYPE:
            return from_word(self.up[B.up_address(name)], _UP_TYPE[name])
        if name in _DOWN_TYPE:
            return from_word(self.down[B.down_address(name)], _DOWN_TYPE[name])
        raise KeyError(f"no register {name!r} in the downstream or upstream map")


class DualPortRam:
    """The dual-port memory of the MCU board's FPGA (``DPRAM_WORDS`` 16-bit words).

    The downstream blocks start at the boards' boot values (``board.down_defaults``: current
    limit, trip current, PI gains), as the FPGA's memory initialisation would, so the first
    :meth:`sync` does not send zeros for those registers.
    """

    def __init__(self, cal: FirmwareCalibration) -> None:
        self.words = np.zeros(DPRAM_WORDS, dtype=np.int64)
        defaults = down_defaults(cal)
        for k in range(MAX_BOARDS):
            d = down_base(k)
            self.words[d:d + B.DOWN_WORDS] = defaults
        self._boards = [DpramBoard(self, k) for k in range(MAX_BOARDS)]
        self.cycles = 0
        self._links: list[LinkMemory] | None = None

    def attach(self, links: list[LinkMemory]) -> None:
        """The LVDS memories of boards 0, 1, ... for the argument-less sync calls (checked
        once here, not every cycle)."""
        self._check_links(links)
        self._links = list(links)

    # --- the STM32's bus side ----------------------------------------------------------------
    def read(self, addr: int) -> int:
        """The word at ``addr`` (0..0xFFFF); ValueError outside the map or in a gap."""
        k, block, off = decode(addr)
        if block == "reserved":
            raise ValueError(f"DPRAM address 0x{int(addr):03X} is in board {k}'s reserved gap "
                             f"0x{k * BOARD_STRIDE + GAP_OFFSET:03X}.."
                             f"0x{k * BOARD_STRIDE + UP_OFFSET - 1:03X}")
        return int(self.words[addr])

    def write(self, addr: int, value: int) -> None:
        """Store ``value`` (0..0xFFFF) at ``addr``; only downstream blocks are writable by
        the MCU (the upstream blocks belong to the copy state machine)."""
        k, block, off = decode(addr)
        if block != "down":
            what = "reserved gap" if block == "reserved" else "upstream block (read-only)"
            raise ValueError(f"DPRAM address 0x{int(addr):03X} is in board {k}'s {what}: "
                             f"the MCU writes only 0x{down_base(k):03X}.."
                             f"0x{down_base(k) + GAP_OFFSET - 1:03X}")
        if not isinstance(value, int | np.integer) or not 0 <= value <= 0xFFFF:
            raise ValueError(f"DPRAM word value {value!r} outside 0..0xFFFF")
        self.words[addr] = int(value)

    def board(self, k: int) -> DpramBoard:
        """Named access to board ``k``'s blocks."""
        return self._boards[_check_board(k)]

    # --- the copy state machine ------------------------------------------------------------
    def _check_links(self, links: list[LinkMemory]) -> None:
        if not 1 <= len(links) <= MAX_BOARDS:
            raise ValueError(f"the DPRAM copies 1..{MAX_BOARDS} link memories, got {len(links)}")
        for k, link in enumerate(links):
            if np.shares_memory(link.down, self.words) or np.shares_memory(link.up, self.words):
                raise ValueError(f"link {k} is a view of this DPRAM, not an LVDS memory")

    def sync_down(self, links: list[LinkMemory] | None = None) -> None:
        """Copy board k's downstream block into ``links[k].down``, k = 0, 1, ... (default:
        the attached links)."""
        links = self._attached(links)
        for k, link in enumerate(links):
            d = down_base(k)
            link.down[:] = self.words[d:d + B.DOWN_WORDS]

    def sync_up(self, links: list[LinkMemory] | None = None) -> None:
        """Copy ``links[k].up`` into board k's upstream block, k = 0, 1, ... (default: the
        attached links)."""
        links = self._attached(links)
        for k, link in enumerate(links):
            u = up_base(k)
            self.words[u:u + B.UP_WORDS] = np.asarray(link.up, dtype=np.int64) & 0xFFFF
            self._boards[k].up_crc_errors = link.up_crc_errors

    def _attached(self, links: list[LinkMemory] | None) -> list[LinkMemory]:
        if links is None:
            if self._links is None:
                raise ValueError("no links attached to this DPRAM (DualPortRam.attach)")
            return self._links
        self._check_links(links)
        return links

    def sync(self, links: list[LinkMemory] | None = None) -> None:
        """One pass of the copy state machine (once per 5 kHz cycle): every downstream
        block out to its link memory, then every link's upstream memory in. ``links[k]``
        is board k's LVDS memory; blocks of boards ``>= len(links)`` are not touched."""
        links = self._attached(links)
        self.sync_down(links)
        self.sync_up(links)
        self.cycles += 1


__all__ = ["BOARD_STRIDE", "DPRAM_WORDS", "DOWN_OFFSET", "GAP_OFFSET", "MAX_BOARDS",
           "UP_OFFSET", "DpramBoard", "DualPortRam", "address", "decode", "down_base",
           "markdown", "up_base"]
