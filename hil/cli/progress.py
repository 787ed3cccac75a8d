"""What a running ``eha-hil`` command is doing: progress on stderr, and the one line Ctrl-C
prints.

A command notes where it is (:func:`at`) and the files it writes (:func:`output`); the
progress reporters of :func:`reporter` do the first on every update. When SIGINT (or
SIGTERM, SIGHUP) arrives, the root (:mod:`hil.cli.root`) catches the KeyboardInterrupt once,
after every ``with`` block on the way out has closed its file, and prints
:func:`interrupted_line`: the verb, the position, and for each output whether it is
complete, e.g.
``eha-hil bus run: interrupted at t=1.230 s; log run.mcap closed and readable``.
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

#: Exit code of a command ended by SIGINT (128 + 2, what a shell reports).
EXIT_INTERRUPTED = 130


@dataclass
class _Output:
    label: str                         # "log", "plot", "report"
    path: Path
    check: Callable[[Path], str] | None = None  # a readability check: "" or the problem
    done: bool = False                 # complete before the interrupt


@dataclass
class _State:
    verb: str = "eha-hil"
    position: str = ""
    started: float = field(default_factory=time.perf_counter)
    outputs: list[_Output] = field(default_factory=list)
    line_open: bool = False            # a "\r" progress line still waits for its newline


_state = _State()


def start(verb: str) -> None:
    """A new command starts (``verb``: e.g. ``"eha-hil bus run"``)."""
    global _state
    _state = _State(verb=verb)


def at(position: str) -> None:
    """Where the command is, as the interrupt line should say it ("at t=1.2 s")."""
    _state.position = position


def position() -> str:
    """The position last noted with :func:`at` ("" if none)."""
    return _state.position


def output(label: str, path: str | Path, check: Callable[[Path], str] | None = None,
           done: bool = False) -> None:
    """A file the command writes; ``check(path)`` returns "" if it is readable as it is."""
    _state.outputs.append(_Output(label, Path(path), check, done))


def reporter(label: str, enabled: bool, unit: str = "", note: bool = True
             ) -> Callable[[int, int], None]:
    """A ``progress(i, n)`` callback: draws ``label: i/n UNIT`` on stderr (one line,
    redrawn) when ``enabled``, and with ``note`` (also when not drawing) notes the position
    "at i/n UNIT of LABEL" (``note=False``: the command notes a better one itself)."""
    suffix = f" {unit}" if unit else ""

    def report(i: int, n: int) -> None:
        if note:
            at(f"at {i}/{n}{suffix} of {label}")
        if not enabled:
            return
        end = "\n" if i >= n else ""
        print(f"\r{label}: {i}/{n}{suffix}", end=end, file=sys.stderr, flush=True)
        _state.line_open = not end

    return report


@contextmanager
def interrupt_between_steps() -> Iterator[Callable[[], None]]:
    """Ctrl-C (and SIGTERM, SIGHUP) lands between two steps of a loop instead of anywhere.

    Inside the block the signal only sets a flag; the loop calls the yielded ``check()`` where
    stopping leaves every file consistent (e.g. between two fieldbus cycles, never inside
    a frame-log write), and ``check()`` raises KeyboardInterrupt. A second Ctrl-C raises at
    once; a flag still set when the block ends raises there."""
    from hil.cli.signals import SIGNALS, Interrupted

    pending: list[int] = []

    def on_signal(signum: int, frame: object) -> None:
        if pending:
            raise Interrupted(signum)
        pending.append(signum)

    def check() -> None:
        if pending:
            raise Interrupted(pending[0])

    old = {}
    try:
        for signum in SIGNALS:
            # An ignored signal (SIGINT in a background job of a script, SIGHUP under
            # nohup) stays ignored, as Python leaves it; off the main thread signals
            # cannot be handled at all (ValueError).
            if signal.getsignal(signum) is not signal.SIG_IGN:
                old[signum] = signal.signal(signum, on_signal)
    except ValueError:
        yield lambda: None
        return
    try:
        yield check
    finally:
        for signum, handler in old.items():
            signal.signal(signum, handler)
    check()


def interrupted_line(signum: int = signal.SIGINT) -> str:
    """The one line for an interrupted command (starting on a fresh line of stderr); a
    signal other than Ctrl-C's is named ("interrupted by SIGTERM at ...")."""
    st = _state
    where = st.position or f"after {time.perf_counter() - st.started:.1f} s"
    parts = []
    done: dict[tuple[str, Path], list[str]] = {}  # finished files, by kind and directory
    for out in st.outputs:
        if out.done:
            done.setdefault((out.label, out.path.parent), []).append(out.path.name)
    for (label, folder), names in done.items():
        parts.append(f"{label} {names[0]}" if len(names) == 1 else
                     f"{label}s {', '.join(names)}")
        parts[-1] += f" written to {folder}/"
    for out in st.outputs:
        if out.done:
            continue
        if not out.path.exists():
            parts.append(f"{out.label} {out.path} not written")
            continue
        problem = out.check(out.path) if out.check else ""
        parts.append(f"{out.label} {out.path} closed and readable" if not problem
                     else f"{out.label} {out.path} is incomplete ({problem})")
    saved = "; ".join(parts) if parts else "nothing written"
    lead = "\n" if st.line_open else ""
    by = "" if signum == signal.SIGINT else f"by {signal.Signals(signum).name} "
    return f"{lead}{st.verb}: interrupted {by}{where}; {saved}"


def readable_log(path: Path) -> str:
    """"" if the frame log at ``path`` opens and its summary reads, else why not."""
    from hil.framelog.reader import FrameLogError, FrameLogReader

    try:
        info = FrameLogReader(path).info()
    except (FrameLogError, OSError, ValueError) as exc:
        return str(exc)
    return "" if info.complete else f"not closed: {info.stop_reason}"
