"""Files a command writes: checked before the work, written whole or not at all, and
reported truthfully.

Every output option of the command line goes through here, in three steps:

1. **Before the work** (:func:`check_writable`, :func:`check_dir_writable`, called by the
   argument types of :mod:`hil.cli.args`): the directory must take a new file (a read-only
   file system, ``/proc``, a file used as a directory are refused with one line, exit 2,
   before any computation). :func:`check_not_inputs` refuses an output that is one of the
   command's inputs (the same file by inode, not by name), e.g. ``log export run.mcap
   run.mcap``.
2. **While writing** (:func:`replacing`, :func:`replacing_dir`): the writer writes a
   temporary file next to the target (same directory, same suffix, so writers that pick a
   format by the name still do) which is renamed over the target only when complete. A
   write that fails removes it: a target is the old file or the new one, never half of
   one. Streaming logs (``bus run --log``) are renamed after they are closed, also when the
   run was interrupted (the log of an interrupted run is a log of what ran).
   A target that is a character device (``/dev/null``, ``/dev/full``) is written in place.
3. **After the work** (:func:`write`, :func:`failed`, :func:`finish`): a write that fails
   after the computation does not lose the result. The command prints its result as
   usual (it says only what was written), and the root prints one line per failed file
   (``eha-hil VERB: plot x.png not written: No space left on device``) and exits 1.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

from hil.cli.contract import EXIT_FAILED, UsageError

#: Exit code of a command whose result was printed but one of whose files failed.
EXIT_WRITE_FAILED = EXIT_FAILED


class OutputError(UsageError):
    """An output that cannot be written, found before the work starts (one line, exit 2)."""


class OutputPath(str):
    """A command-line value that names a file or directory the command writes (the argument
    types of :mod:`hil.cli.args` return it, so :func:`check_not_inputs` can find them)."""


def _why(exc: OSError) -> str:
    return exc.strerror or str(exc)


def is_device(path: Path) -> bool:
    try:
        return stat.S_ISCHR(path.stat().st_mode)
    except OSError:
        return False


def check_writable(path: str | os.PathLike[str]) -> None:
    """OutputError unless a file can be created at ``path`` (its directory exists and takes
    a new file); an existing character device must open for writing."""
    p = Path(path)
    if is_device(p):
        try:
            with open(p, "ab"):
                pass
        except OSError as exc:
            raise OutputError(f"{path}: cannot write: {_why(exc)}") from None
        return
    _probe_parent(p, path, "directory")


def _probe_parent(p: Path, path: str | os.PathLike[str], what: str) -> None:
    """OutputError unless the directory ``path`` would be made in takes files."""
    parent = p.parent if str(p.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise OutputError(f"{path}: {parent} is not a directory")
    if not parent.is_dir():
        raise OutputError(f"{path}: {what} {parent} does not exist")
    _probe(parent, path)


def check_dir_writable(path: str | os.PathLike[str]) -> None:
    """OutputError unless ``path`` is (or can be made as) a directory that takes files."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{path}: exists and is not a directory")
    if p.is_dir():
        _probe(p, path)
        return
    _probe_parent(p, path, "parent directory")


def _probe(directory: Path, named: str | os.PathLike[str]) -> None:
    """Create and remove an empty file in ``directory`` (the only sure test: permissions,
    read-only mounts, /proc and root's capabilities all decide)."""
    try:
        fd, name = tempfile.mkstemp(prefix=".eha-hil-probe-", dir=directory)
    except OSError as exc:
        raise OutputError(f"{named}: cannot write in {directory}: {_why(exc)}") from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(name)


def check_not_inputs(outputs: Iterable[str], inputs: Iterable[str]) -> None:
    """OutputError if an output names the same file as an input (by device and inode, so
    ``./a.mcap``, ``a.mcap`` and a link to it are all caught)."""
    ins = [i for i in inputs if i and i != "-" and Path(i).is_file()]
    for out in outputs:
        if not out or out == "-" or not Path(out).exists():
            continue
        for i in ins:
            with contextlib.suppress(OSError):
                if os.path.samefile(out, i):
                    raise OutputError(f"{out}: is also an input ({i}); writing it would "
                                      "destroy it: give another file name")


def check_args(values: dict[str, object]) -> None:
    """:func:`check_not_inputs` over parsed arguments: the values typed :class:`OutputPath`
    are outputs, every other string (or string in a list) is a possible input."""
    outs: list[str] = []
    ins: list[str] = []
    for v in values.values():
        for item in (v if isinstance(v, list | tuple) else [v]):
            if isinstance(item, OutputPath):
                outs.append(item)
            elif isinstance(item, str):
                ins.append(item)
    check_not_inputs(outs, ins)


def _temp_name(p: Path) -> Path:
    fd, name = tempfile.mkstemp(prefix=f".{p.stem}.partial-", suffix=p.suffix,
                                dir=p.parent if str(p.parent) else ".")
    os.close(fd)
    return Path(name)


@contextlib.contextmanager
def replacing(path: str | os.PathLike[str], keep_on_interrupt: bool = False
              ) -> Iterator[Path]:
    """Yield a temporary path to write ``path``'s new content to; rename it over ``path``
    when the block ends normally. On an exception the temporary file is removed, except
    with ``keep_on_interrupt`` on KeyboardInterrupt (a streaming log its writer closed on
    the way out: what was recorded is kept under the real name)."""
    p = Path(path)
    if is_device(p):
        yield p
        return
    tmp = _temp_name(p)
    try:
        yield tmp
    except KeyboardInterrupt:
        if keep_on_interrupt and tmp.exists() and tmp.stat().st_size > 0:
            _commit(tmp, p)
        else:
            _discard(tmp)
        raise
    except BaseException:
        _discard(tmp)
        raise
    _commit(tmp, p)


def _commit(tmp: Path, p: Path) -> None:
    try:
        # mkstemp makes the file 0600; a finished output gets the usual umask mode
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, p)
    except OSError:
        _discard(tmp)
        raise


def _discard(tmp: Path) -> None:
    with contextlib.suppress(OSError):
        if tmp.is_dir():
            shutil.rmtree(tmp)
        else:
            tmp.unlink()


@contextlib.contextmanager
def replacing_dir(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary directory beside ``path``; when the block ends normally, create
    ``path`` if needed and move every file of the temporary one into it (each a rename:
    complete files only). On an exception nothing is moved and the temporary is removed."""
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    tmp = Path(tempfile.mkdtemp(prefix=f".{p.name}.partial-", dir=parent))
    try:
        yield tmp
        p.mkdir(exist_ok=True)
        for f in sorted(tmp.iterdir()):
            os.replace(f, p / f.name)
    finally:
        _discard(tmp)


class StreamFailed(Exception):
    """A file written while the command ran (a log, a capture) failed: the command stopped
    there; :func:`finish` prints which file and why (exit 1)."""


@contextlib.contextmanager
def streaming(paths: dict[str, str | None], labels: dict[str, str],
              checks: dict[str, Callable[[Path], str]] | None = None
              ) -> Iterator[dict[str, str]]:
    """Files a command writes while it runs (``bus run --log``, ``--capture``...): yields
    ``{key: temporary path}`` for each given path, renamed to its name when the block
    ends, also on an interruption (the writers have closed them by then: what ran is
    kept, complete). An OSError (a full disk) removes them all, notes each as not written
    and raises StreamFailed. ``checks``: how the interrupt line tells a readable file."""
    from hil.cli import progress as cli_progress

    given = {k: v for k, v in paths.items() if v}
    with contextlib.ExitStack() as stack:
        tmp: dict[str, str] = {}
        for key, path in given.items():
            cli_progress.output(labels[key], path, (checks or {}).get(key))
            tmp[key] = str(stack.enter_context(replacing(path, keep_on_interrupt=True)))
        try:
            yield tmp
        except OSError as exc:
            where = cli_progress.position() or "at the start"
            for key, path in given.items():
                failed(labels[key], path, f"{_why(exc)} (stopped {where})")
            raise StreamFailed from None


# --- failures after the work -------------------------------------------------------------------
@dataclass
class Failure:
    label: str
    path: str
    why: str


_failures: list[Failure] = []


def reset() -> None:
    """Forget earlier failures (a new command starts)."""
    _failures.clear()


def failed(label: str, path: str | os.PathLike[str], exc: BaseException | str) -> None:
    """Note that ``label`` ``path`` could not be written, and why (the exception or a
    sentence; reported by :func:`finish`)."""
    why = _why(exc) if isinstance(exc, OSError) else str(exc)
    _failures.append(Failure(label, str(path), why))


def failures() -> list[Failure]:
    return list(_failures)


def write(label: str, path: str | os.PathLike[str], fn: Callable[[Path], object]
          ) -> bool:
    """Run ``fn(tmp)`` to write ``path`` through :func:`replacing`; True when it is in
    place. An OSError is noted (:func:`failed`) and gives False: the caller goes on and
    prints its result without claiming the file."""
    return _write_through(replacing, label, path, fn)


def write_dir(label: str, path: str | os.PathLike[str], fn: Callable[[Path], object]
              ) -> bool:
    """As :func:`write`, for a directory of files (:func:`replacing_dir`)."""
    return _write_through(replacing_dir, label, path, fn)


def _write_through(replace: Callable, label: str, path: str | os.PathLike[str],
                   fn: Callable[[Path], object]) -> bool:
    from hil.cli import progress as cli_progress

    try:
        with replace(path) as tmp:
            fn(tmp)
    except OSError as exc:
        failed(label, path, exc)
        return False
    cli_progress.output(label, path, done=True)
    return True


@dataclass(frozen=True)
class Later:
    """A file a command writes after its result is printed (``Outcome.files``): ``fn(tmp)``
    writes it; ``said()`` is what follows "LABEL written to PATH" (e.g. " (120 rows)")."""

    label: str
    path: str
    fn: Callable[[Path], object]
    said: Callable[[], str] = lambda: ""
    directory: bool = False  # a directory of files (:func:`write_dir`)
    #: not a file: ``fn(None)`` runs after the result is printed and ``said()`` goes to
    #: stderr (e.g. serving a run's series to Foxglove until a client took them)
    action: bool = False


def write_later(files: Iterable[Later], json_mode: bool, say: Callable[[str], None]
                ) -> None:
    """Write each file of ``files`` (:func:`write`) after the result was printed; ``say``
    (the contract's stdout) gets "LABEL written to PATH" for people as each is in place
    (not under ``--json``, whose output is one object)."""
    from hil.cli import progress as cli_progress

    for f in files:
        sys.stdout.flush()
        if f.action:
            cli_progress.at(f"after the run, {f.label} (the result is printed above)")
            f.fn(None)  # type: ignore[arg-type]
            print(f.said(), file=sys.stderr, flush=True)
            continue
        cli_progress.at(f"while writing {f.label} {f.path} (the result is printed above)")
        done = (write_dir if f.directory else write)(f.label, f.path, f.fn)
        if done and not json_mode:
            say(f"{f.label} written to {f.path}{'/' if f.directory else ''}{f.said()}")


def finish(verb: str, code: int) -> int:
    """The command's exit code after its result is printed: one stderr line per file that
    failed, and at least EXIT_WRITE_FAILED when one did."""
    if not _failures:
        return code
    for f in _failures:
        print(f"{verb}: {f.label} {f.path} not written: {f.why}", file=sys.stderr, flush=True)
    _failures.clear()
    return code if code else EXIT_WRITE_FAILED


__all__ = ["EXIT_WRITE_FAILED", "Later", "OutputError", "OutputPath", "StreamFailed", "check_args",
           "check_dir_writable", "check_not_inputs", "check_writable", "failed", "failures",
           "finish", "replacing", "replacing_dir", "reset", "streaming", "write", "write_dir",
           "write_later"]
