"""What a running ``eha-hil`` command is doing: progress on stderr, and the one line Ctrl-C
prints.

A command notes where it is (:func:`at`) and the files it writes (:func:`output`); the
progress reporters of :func:`reporter` do the first on every update. When SIGINT arrives,
``hil.cli.main`` catches the KeyboardInterrupt once, after every ``with`` block on the way
out has closed its file, and prints :func:`interrupted_line`: the verb, the position, and
for each output whether it is complete, e.g.
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
    signum: int = 0                    # the stop signal that ended the command, if any


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


#: The signals a command ends on as on Ctrl-C: the terminal's, a service manager's stop
#: (systemd, docker, kill) and a closed terminal.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def interrupt_between_steps() -> Iterator[Callable[[], None]]:
    """Ctrl-C (and SIGTERM, SIGHUP) lands between two steps of a loop instead of anywhere.

    Inside the block those signals only set a flag; the loop calls the yielded ``check()``
    where stopping leaves every file consistent (e.g. between two fieldbus cycles, never
    inside a frame-log write), and ``check()`` raises KeyboardInterrupt. A second signal
    raises at once; a flag still set when the block ends raises there. The signal is
    noted (:func:`exit_code`)."""
    pending: list[int] = []

    def on_signal(signum: int, frame: object) -> None:
        noted(signum)
        if pending:
            raise KeyboardInterrupt
        pending.append(signum)

    def check() -> None:
        if pending:
            raise KeyboardInterrupt

    old: dict[int, object] = {}
    try:
        for sig in STOP_SIGNALS:
            prev = signal.getsignal(sig)
            # An ignored signal (SIGINT of a background job of a script, nohup's SIGHUP)
            # stays ignored, as Python leaves it; off the main thread signals cannot be
            # handled at all (ValueError).
            if prev is signal.SIG_IGN:
                continue
            signal.signal(sig, on_signal)
            old[sig] = prev
    except ValueError:
        yield lambda: None
        return
    try:
        yield check
    finally:
        for sig, prev in old.items():
            signal.signal(sig, prev)
    check()


def noted(signum: int) -> None:
    """Remember the signal that ends the command (its exit code is 128 + its number)."""
    _state.signum = signum


def exit_code() -> int:
    """130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP: what a shell reports for each."""
    return 128 + (_state.signum or signal.SIGINT)


def interrupted_line() -> str:
    """The one line for an interrupted command (starting on a fresh line of stderr)."""
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
    return f"{lead}{st.verb}: interrupted {where}; {saved}"


def readable_log(path: Path) -> str:
    """"" if the frame log at ``path`` opens and its summary reads, else why not."""
    from hil.framelog.reader import FrameLogError, FrameLogReader

    try:
        info = FrameLogReader(path).info()
    except (FrameLogError, OSError, ValueError) as exc:
        return str(exc)
    return "" if info.complete else f"not closed: {info.stop_reason}"
