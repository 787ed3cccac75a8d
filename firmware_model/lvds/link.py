"""The LVDS link between the MCU board and one driver board: the word-by-word sweep of the
two shared memories, its timing, and fault injection.

Both ends send their memory round-robin, one 45-bit word (start | address | data | CRC)
after the other, without gaps (thesis 6.3.1). At ``lvds_bit_rate_hz`` = 10 MHz one word
takes 4.5 us: 11.1 words per 50 us tick, so a sweep of the 16-word downstream memory takes
72 us and of the 32-word upstream memory 144 us. Bits are accounted exactly with an integer
accumulator; a word counts as received in the tick in which its last bit arrives.

Order inside a tick (``hil.sim.actuator``): downstream words of the tick reach the driver's
memory, the driver computes, then the upstream words of the tick carry its fresh values.

Value level: words travel as (address, data) with a CRC verdict decided by the fault
settings. Bit level (:class:`BitLevelLink`): words are encoded by :mod:`protocols.lvds`,
corrupted bits are flipped on the wire and an :class:`~protocols.lvds.LvdsStreamDecoder`
recovers them, as the receiving FPGA's deserialiser does.

Fault settings per direction (``LK_*``): ``stopped`` (no bits at all: cable pulled),
``corrupt_every`` N (every N-th word has one bit flipped; 1 = all words, 0 = none). Value
level only: ``drop_every`` N (every N-th word is lost: the receiver sees no start bit, so
nothing is stored and nothing counted at the receiver; ``*_dropped`` counts them),
``dup_every`` N (every N-th word is sent twice: it takes the next word's slot, so the sweep
falls one word behind), ``delay`` D ticks (the words carry the sender's memory as it was D
ticks earlier: a latency of D ticks, up to ``HIST_TICKS`` - 1). The sender's memory of each
tick is kept in a ring at the end of the state array for that.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from firmware_model.calibration import FirmwareCalibration, calibration
from firmware_model.fpga import layout as B
from firmware_model.fpga.fixed import sat_u
from protocols import lvds

LINK_NAMES = (
    "bits_num",        # bit-rate * tick_ns: bits per tick, times 1e9
    "down_acc", "down_ptr", "down_stopped", "down_corrupt_every", "down_phase",
    "up_acc", "up_ptr", "up_stopped", "up_corrupt_every", "up_phase",
    "down_words", "up_words", "master_crc_failures",
    "down_drop_every", "down_drop_phase", "down_dup_every", "down_dup_phase", "down_delay",
    "down_dropped", "down_t",
    "up_drop_every", "up_drop_phase", "up_dup_every", "up_dup_phase", "up_delay",
    "up_dropped", "up_t",
)
(LK_BITS_NUM, LK_DOWN_ACC, LK_DOWN_PTR, LK_DOWN_STOPPED, LK_DOWN_CORRUPT, LK_DOWN_PHASE,
 LK_UP_ACC, LK_UP_PTR, LK_UP_STOPPED, LK_UP_CORRUPT, LK_UP_PHASE, LK_DOWN_WORDS, LK_UP_WORDS,
 LK_MASTER_CRC,
 LK_DOWN_DROP, LK_DOWN_DROP_PHASE, LK_DOWN_DUP, LK_DOWN_DUP_PHASE, LK_DOWN_DELAY,
 LK_DOWN_DROPPED, LK_DOWN_T,
 LK_UP_DROP, LK_UP_DROP_PHASE, LK_UP_DUP, LK_UP_DUP_PHASE, LK_UP_DELAY,
 LK_UP_DROPPED, LK_UP_T) = range(len(LINK_NAMES))
N_LINK = len(LINK_NAMES)
#: Ticks of sender memory kept for the ``delay`` fault, and the ring's row width (words).
HIST_TICKS = 64
HIST_W = 32
LK_DOWN_HIST = N_LINK
LK_UP_HIST = N_LINK + HIST_TICKS * HIST_W
#: The words of the latest tick, per direction, for logs: a count, then per word
#: (address, data, fate) with fate WORD_OK, WORD_CRC_BAD or WORD_DROPPED.
MAX_WORDS_TICK = 16
WORDS_W = 1 + 3 * MAX_WORDS_TICK
LK_DOWN_WORDLOG = N_LINK + 2 * HIST_TICKS * HIST_W
LK_UP_WORDLOG = LK_DOWN_WORDLOG + WORDS_W
N_LINK_STATE = LK_UP_WORDLOG + WORDS_W
WORD_OK, WORD_CRC_BAD, WORD_DROPPED = 0, 1, 2
WORD_BITS = lvds.WORD_BITS
_WORD_DEN = WORD_BITS * 1_000_000_000
# The per-tick kernels below take rows of larger arrays and allocate nothing: compiled
# without numba's runtime (``_nrt=False``) they count no references on those views. Left
# to the default, they were compiled with or without it depending on which caller compiled
# them first (numba's callees inherit the flag) and the cache kept that: the same sweeps
# took ~160 or ~95 ns per actuator tick depending on the install's history.


@njit(cache=True, _nrt=False)
def receive_word(st, down, addr, data, crc_ok):
    """LVDS endpoint, downstream side: store one received word or discard it.

    A word that failed its CRC is counted and dropped; a good word is stored at its
    address (addresses beyond the memory are ignored) and restarts the link watchdog.
    """
    if not crc_ok:
        st[B.F_ERR_LINK_CRC] = sat_u(st[B.F_ERR_LINK_CRC] + 1, 16)
        return
    if 0 <= addr < B.DOWN_WORDS:
        down[addr] = data & 0xFFFF
    st[B.F_SINCE_VALID] = 0


def link_state(cal: FirmwareCalibration) -> np.ndarray:
    """A fresh link state: both sweeps at address 0, no faults."""
    cal = calibration(cal)
    lk = np.zeros(N_LINK_STATE, dtype=np.int64)
    lk[LK_BITS_NUM] = int(cal.fpga["lvds_bit_rate_hz"]) * int(cal.tick_ns)
    return lk


def sweep_time_s(cal: FirmwareCalibration, words: int) -> float:
    """Time to send ``words`` words back to back, s."""
    return words * WORD_BITS / calibration(cal).fpga["lvds_bit_rate_hz"]


@njit(cache=True, inline="always")
def _words_this_tick(lk, acc_index):
    acc = lk[acc_index] + lk[LK_BITS_NUM]
    n = acc // _WORD_DEN
    lk[acc_index] = acc - n * _WORD_DEN
    return n


@njit(cache=True, inline="always")
def _corrupted(lk, every_index, phase_index):
    every = lk[every_index]
    if every <= 0:
        return False
    ph = lk[phase_index] + 1
    if ph >= every:
        lk[phase_index] = 0
        return True
    lk[phase_index] = ph
    return False


@njit(cache=True, inline="always")
def _remember(lk, t_index, hist, mem):
    """Keep the sender's memory of this tick; return the ring row holding the memory
    ``delay`` ticks ago (this tick's when there is no delay or not enough history)."""
    t = lk[t_index]
    row = hist + (t % HIST_TICKS) * HIST_W
    for i in range(mem.shape[0]):
        lk[row + i] = mem[i]
    lk[t_index] = t + 1
    d = lk[t_index + (LK_DOWN_DELAY - LK_DOWN_T)]
    back = t - d if t >= d else 0
    return hist + (back % HIST_TICKS) * HIST_W


@njit(cache=True, inline="always")
def _log_word(lk, base, addr, data, fate):
    k = lk[base]
    if k < MAX_WORDS_TICK:
        p = base + 1 + 3 * k
        lk[p] = addr
        lk[p + 1] = data
        lk[p + 2] = fate
        lk[base] = k + 1


@njit(cache=True, inline="always")
def _clean_sweep(lk, ptr_index, log_base, src, n, size, dest, dest_words, mask):
    """``n`` words sent round-robin from the ring row ``src`` with no word fault, each
    logged WORD_OK and stored at its address in ``dest`` as ``data & mask`` (addresses
    beyond ``dest_words`` are ignored, as :func:`receive_word` does); advances the
    pointer."""
    addr = lk[ptr_index]
    k = 0
    for _ in range(n):
        data = lk[src + addr]
        if k < MAX_WORDS_TICK:
            q = log_base + 1 + 3 * k
            lk[q] = addr
            lk[q + 1] = data
            lk[q + 2] = WORD_OK
            k += 1
        if addr < dest_words:
            dest[addr] = data & mask
        addr = addr + 1 if addr + 1 < size else 0
    lk[log_base] = k
    lk[ptr_index] = addr


@njit(cache=True, _nrt=False)
def sweep_down(lk, master_down, st, down):
    """Downstream words of one tick: MCU memory -> driver endpoint (value level)."""
    n = _words_this_tick(lk, LK_DOWN_ACC)
    src = _remember(lk, LK_DOWN_T, LK_DOWN_HIST, master_down)
    lk[LK_DOWN_WORDLOG] = 0
    if lk[LK_DOWN_STOPPED] != 0:
        return
    size = master_down.shape[0]
    if lk[LK_DOWN_DUP] <= 0 and lk[LK_DOWN_DROP] <= 0 and lk[LK_DOWN_CORRUPT] <= 0:
        # No word faults (the usual case): the loop below without its fault bookkeeping,
        # counters kept in locals (the tick's hottest loop; same words, same state).
        _clean_sweep(lk, LK_DOWN_PTR, LK_DOWN_WORDLOG, src, n, size, down, B.DOWN_WORDS, 0xFFFF)
        lk[LK_DOWN_WORDS] += n
        if n > 0:
            st[B.F_SINCE_VALID] = 0
        return
    for _ in range(n):
        addr = lk[LK_DOWN_PTR]
        if not _corrupted(lk, LK_DOWN_DUP, LK_DOWN_DUP_PHASE):
            # a compare, not a modulo: an integer division per word was most of the sweep's cost
            lk[LK_DOWN_PTR] = addr + 1 if addr + 1 < size else 0
        lk[LK_DOWN_WORDS] += 1
        data = lk[src + addr]
        if _corrupted(lk, LK_DOWN_DROP, LK_DOWN_DROP_PHASE):
            lk[LK_DOWN_DROPPED] += 1
            _log_word(lk, LK_DOWN_WORDLOG, addr, data, WORD_DROPPED)
            continue
        bad = _corrupted(lk, LK_DOWN_CORRUPT, LK_DOWN_PHASE)
        _log_word(lk, LK_DOWN_WORDLOG, addr, data, WORD_CRC_BAD if bad else WORD_OK)
        receive_word(st, down, addr, data, not bad)


@njit(cache=True, _nrt=False)
def sweep_up(lk, up, master_up):
    """Upstream words of one tick: driver memory -> MCU memory (value level)."""
    n = _words_this_tick(lk, LK_UP_ACC)
    src = _remember(lk, LK_UP_T, LK_UP_HIST, up)
    lk[LK_UP_WORDLOG] = 0
    if lk[LK_UP_STOPPED] != 0:
        return
    size = up.shape[0]
    if lk[LK_UP_DUP] <= 0 and lk[LK_UP_DROP] <= 0 and lk[LK_UP_CORRUPT] <= 0:
        _clean_sweep(lk, LK_UP_PTR, LK_UP_WORDLOG, src, n, size, master_up,
                     master_up.shape[0], -1)
        lk[LK_UP_WORDS] += n
        return
    for _ in range(n):
        addr = lk[LK_UP_PTR]
        if not _corrupted(lk, LK_UP_DUP, LK_UP_DUP_PHASE):
            # a compare, not a modulo: an integer division per word was most of the sweep's cost
            lk[LK_UP_PTR] = addr + 1 if addr + 1 < size else 0
        lk[LK_UP_WORDS] += 1
        data = lk[src + addr]
        if _corrupted(lk, LK_UP_DROP, LK_UP_DROP_PHASE):
            lk[LK_UP_DROPPED] += 1
            _log_word(lk, LK_UP_WORDLOG, addr, data, WORD_DROPPED)
            continue
        if _corrupted(lk, LK_UP_CORRUPT, LK_UP_PHASE):
            lk[LK_MASTER_CRC] += 1
            _log_word(lk, LK_UP_WORDLOG, addr, data, WORD_CRC_BAD)
        else:
            master_up[addr] = data
            _log_word(lk, LK_UP_WORDLOG, addr, data, WORD_OK)


#: The bit :func:`_flip` flips in a line word.
FLIP_BIT = 12


def _flip(word: int) -> int:
    """One bit error in a data bit of a line word (the CRC catches every single-bit error)."""
    return word ^ (1 << FLIP_BIT)


def line_words(wordlogs: np.ndarray, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(times, 45-bit line words) of the words that reached the receiver, from rows of one
    direction's word log (``wordlogs[:, :WORDS_W]``, one row per tick at ``t_ns``): a word
    that failed its CRC is the word with the data bit :func:`_flip` flips; dropped words
    never reached the line."""
    count = wordlogs[:, 0]
    slots = wordlogs[:, 1:WORDS_W].reshape(len(wordlogs), MAX_WORDS_TICK, 3)
    mask = np.arange(MAX_WORDS_TICK)[None, :] < count[:, None]
    w = slots[mask]
    t = np.repeat(t_ns, count)
    keep = w[:, 2] != WORD_DROPPED
    w, t = w[keep], t[keep]
    line = lvds.encode_words_array(w[:, 0].astype(np.uint64), w[:, 1])
    line = np.where(w[:, 2] == WORD_CRC_BAD, line ^ np.uint64(1 << FLIP_BIT), line)
    return t, line.astype(np.uint64)


class BitLevelLink:
    """The same link with real line bits: :mod:`protocols.lvds` encoder and stream decoder.

    Uses the value-level link state ``lk`` for the timing and the fault settings, so both
    paths sweep the same words in the same ticks.
    """

    def __init__(self) -> None:
        self.down_rx = lvds.LvdsStreamDecoder()
        self.up_rx = lvds.LvdsStreamDecoder()
        self._down_crc_seen = 0
        self._up_crc_seen = 0

    def _send(self, lk: np.ndarray, acc: int, ptr: int, stopped: int, every: int, phase: int,
              mem: np.ndarray) -> list[int] | None:
        n = int(_words_this_tick(lk, acc))
        if lk[stopped]:
            return None
        bits: list[int] = []
        size = mem.shape[0]
        for _ in range(n):
            addr = int(lk[ptr])
            lk[ptr] = (addr + 1) % size
            word = lvds.encode_word(addr, int(mem[addr]))
            if _corrupted(lk, every, phase):
                word = _flip(word)
            bits.extend((word >> i) & 1 for i in range(WORD_BITS - 1, -1, -1))
        return bits

    def sweep_down(self, lk: np.ndarray, master_down: np.ndarray, st: np.ndarray,
                   down: np.ndarray) -> None:
        """Downstream words of one tick through the line code into the driver endpoint."""
        bits = self._send(lk, LK_DOWN_ACC, LK_DOWN_PTR, LK_DOWN_STOPPED, LK_DOWN_CORRUPT,
                          LK_DOWN_PHASE, master_down)
        if bits is None:
            return
        lk[LK_DOWN_WORDS] += len(bits) // WORD_BITS
        for w in self.down_rx.feed(bits):
            receive_word(st, down, w.addr, w.data, True)
        new_fail = self.down_rx.crc_failures - self._down_crc_seen
        self._down_crc_seen = self.down_rx.crc_failures
        for _ in range(new_fail):
            receive_word(st, down, 0, 0, False)

    def sweep_up(self, lk: np.ndarray, up: np.ndarray, master_up: np.ndarray) -> None:
        """Upstream words of one tick through the line code into the MCU's memory."""
        bits = self._send(lk, LK_UP_ACC, LK_UP_PTR, LK_UP_STOPPED, LK_UP_CORRUPT,
                          LK_UP_PHASE, up)
        if bits is None:
            return
        lk[LK_UP_WORDS] += len(bits) // WORD_BITS
        for w in self.up_rx.feed(bits):
            if w.addr < B.UP_WORDS:
                master_up[w.addr] = w.data
        new_fail = self.up_rx.crc_failures - self._up_crc_seen
        self._up_crc_seen = self.up_rx.crc_failures
        lk[LK_MASTER_CRC] += new_fail
