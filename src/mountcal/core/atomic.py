"""Atomic output: a file appears at its target only complete, never partial.

Two forms of the one rule, for the two ways libraries write, and a third for a file that must
exist while it grows:

- :func:`atomic_output` yields an open binary file (the streaming writers: Parquet row group by
  row group, MCAP record by record). It is an unnamed file in the target's folder (Linux
  ``O_TMPFILE``), linked to its name once complete: a process that dies before that — an
  exception, a crash, ``SIGKILL`` — leaves no file at all.
- :func:`atomic_path` yields a temporary path beside the target (for writers that want a path:
  ``DataFrame.to_csv``, ``pyarrow.parquet.write_table``), renamed onto the target on success and
  removed on an exception; only a hard kill can leave the hidden ``.NAME.*.part`` file.
- :class:`GrowingFile` is a file written as it grows (``live``'s recording and event log: a
  session's data must survive the session's end, however it ends). It is appended to by whole
  records and is never half a record long: what a crash, a full disk or a size limit leaves is
  a readable prefix.

A write the system refuses (no space, no permission, a directory in the way) is a
:class:`~mountcal.core.paths.SystemFailure` naming the target, with nothing left behind.

Both flush and ``fsync`` the data before the name changes, so that after a power cut the target
holds either its old content or the whole new one (``durable=False`` skips that for files that
are cheap to recompute, such as a fleet's per-log part files).
"""

from __future__ import annotations

import _thread
import contextlib
import errno
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

from mountcal.core.paths import SystemFailure

if TYPE_CHECKING:
    from sys import UnraisableHookArgs


@contextlib.contextmanager
def atomic_output(target: str | os.PathLike[str]) -> Iterator[BinaryIO]:
    """A binary file that appears at ``target`` only when the block completes without error.

    Where the file system lacks ``O_TMPFILE`` a hidden ``.NAME.*.part`` file beside the target is
    used and renamed into place.
    """
    path = Path(target)
    folder = path.parent if str(path.parent) else Path(".")
    with _refused_as_failure(path):
        folder.mkdir(parents=True, exist_ok=True)
    try:
        fd = os.open(folder, os.O_TMPFILE | os.O_WRONLY, 0o666 & ~_umask())
    except (AttributeError, OSError):
        fd = -1
    if fd < 0:
        with atomic_path(path) as tmp, tmp.open("wb") as f:
            yield f
        return
    with _refused_as_failure(path), os.fdopen(fd, "wb") as f:
        yield f
        f.flush()
        os.fsync(f.fileno())
        raise_if_interrupted()  # a Ctrl-C Python dropped while writing: the file is not named
        _link_into_place(f.fileno(), folder, path.name)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str], *, durable: bool = True, keep_name: bool = False) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; on success sync it (unless ``durable`` is
    False) and rename it onto the target.

    With ``keep_name`` the temporary path has the target's own file name, in a hidden
    ``.NAME.*.part`` folder beside it (for writers that record the file's name in the file, or
    write files of their own beside it); the folder is removed with all it holds.
    """
    target = Path(target)
    with _refused_as_failure(target):
        target.parent.mkdir(parents=True, exist_ok=True)
        if keep_name:
            folder = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent))
            tmp = folder / target.name
        else:
            fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
            os.close(fd)
            tmp = Path(name)
    try:
        with _refused_as_failure(target):
            if not keep_name:
                tmp.chmod(0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual permissions
            yield tmp
            if durable:
                with tmp.open("rb+") as f:
                    os.fsync(f.fileno())
            raise_if_interrupted()  # a Ctrl-C Python dropped while writing: the file is not named
            os.replace(tmp, target)
    finally:
        if keep_name:
            shutil.rmtree(tmp.parent, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def _refused_as_failure(target: Path) -> Iterator[None]:
    """An OSError of the write itself (no file named, or the target, its folder or temporary file)
    becomes a SystemFailure naming the target; an error reading some other file passes unchanged."""
    try:
        yield
    except OSError as err:
        name = None if err.filename is None else Path(os.fsdecode(err.filename))
        temporary = f".{target.name}."
        ours = name is None or name in (target, target.parent) or any(p.startswith(temporary) for p in name.parts)
        if not ours and not str(name).startswith("/proc/self/fd/"):
            raise
        raise SystemFailure(str(target), "writing", err) from err


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _link_into_place(fd: int, folder: Path, name: str) -> None:
    """Give the unnamed file ``fd`` the name ``folder/name``, replacing what is there atomically."""
    dir_fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        source = f"/proc/self/fd/{fd}"
        try:
            os.link(source, name, dst_dir_fd=dir_fd, follow_symlinks=True)
            return
        except FileExistsError:
            pass
        temp = f".{name}.{os.getpid()}.{id(source):x}.part"
        os.link(source, temp, dst_dir_fd=dir_fd, follow_symlinks=True)
        try:
            os.replace(temp, name, src_dir_fd=dir_fd, dst_dir_fd=dir_fd)
        except BaseException:
            os.unlink(temp, dir_fd=dir_fd)
            raise
    finally:
        os.close(dir_fd)


class GrowingFile:
    """A file written as it grows, always ending at a record boundary: a readable prefix whatever stops it.

    ``write`` stages bytes, at the end or over bytes already committed (a header rewritten in
    place); :meth:`commit` appends what was staged with one ``pwrite`` and then applies the
    rewrites. The first ``hidden`` bytes of each append are written as zeros and filled in last,
    once the rest is in the file: a format whose records start with a header that zeros mark as
    the end (BLF's object header) then never shows a half-written record, even to a process killed
    in the middle of the append. A failed append (no space, a size limit) cuts the file back to
    its last commit and raises :class:`~mountcal.core.paths.SystemFailure` saying what was kept.

    It replaces whatever is at ``path`` (a link there is removed, never written through). It is
    the file object python-can's writers take (``write``, ``seek``, ``tell``, ``close``).
    """

    def __init__(self, path: str | os.PathLike[str], what: str, *, hidden: int = 0) -> None:
        self.path, self.what, self.hidden = Path(path), what, hidden
        with _refused_as_failure(self.path):
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.path)  # replaced, as an atomic output is: a symlink or hard link is not followed
            flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
            self._fd = os.open(self.path, flags, 0o666)
        self.size = 0  # bytes committed
        self._pos = 0
        self._staged = bytearray()
        self._rewrites: list[tuple[int, bytes]] = []
        self.failed = False
        self.closed = False

    def write(self, data: bytes | bytearray | memoryview) -> int:
        data = bytes(data)
        if self._pos == self.size + len(self._staged):
            self._staged += data
        elif self._pos + len(data) <= self.size:
            self._rewrites.append((self._pos, data))
        else:
            raise ValueError(f"{self.path}: a write across the end of what is committed")
        self._pos += len(data)
        return len(data)

    def tell(self) -> int:
        return self._pos

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        base = {os.SEEK_SET: 0, os.SEEK_CUR: self._pos, os.SEEK_END: self.size + len(self._staged)}[whence]
        self._pos = base + offset
        return self._pos

    def seekable(self) -> bool:
        return True

    def flush(self) -> None:
        """Nothing: bytes reach the file at :meth:`commit` only, whole."""

    @property
    def pending(self) -> bool:
        """Whether bytes are staged (a commit would write)."""
        return bool(self._staged or self._rewrites)

    def commit(self) -> None:
        """Append what is staged, then apply the rewrites (see the class)."""
        if self.failed or not self.pending:
            return
        data = bytes(self._staged)
        try:
            if data:
                hidden = min(self.hidden, len(data))
                _pwrite_all(self._fd, b"\0" * hidden + data[hidden:], self.size)
                _pwrite_all(self._fd, data[:hidden], self.size)
            for offset, rewrite in self._rewrites:
                _pwrite_all(self._fd, rewrite, offset)
        except OSError as err:
            self.failed = True
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, self.size)
            kept = f"{self.path} is kept as it was before this write: {self.size} bytes, whole records only, readable"
            raise SystemFailure(str(self.path), f"writing {self.what}", err, left=kept) from err
        self.size += len(data)
        self._staged.clear()
        self._rewrites.clear()
        self._pos = min(self._pos, self.size)

    def close(self) -> None:
        """Commit what is staged (unless a write failed), sync, and close."""
        if self.closed:
            return
        try:
            self.commit()
            if not self.failed:
                with _refused_as_failure(self.path):
                    os.fsync(self._fd)
        finally:
            self.closed = True
            os.close(self._fd)


def _pwrite_all(fd: int, data: bytes, offset: int) -> None:
    """``data`` at ``offset``, however many calls the system takes; a write of nothing is no space."""
    view = memoryview(data)
    while view:
        done = os.pwrite(fd, view, offset)
        if done == 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        view, offset = view[done:], offset + done


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread as Ctrl-C's KeyboardInterrupt is (and handled as one)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


CLEAN_UP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
GRACE_S = 15.0  # an interrupted command still running this long after the signal is ended without its clean-up


_INTERRUPTED = threading.Event()  # a Ctrl-C arrived within removed_on_signals


def raise_if_interrupted() -> None:
    """Raise KeyboardInterrupt if a Ctrl-C arrived that Python could not raise where it landed.

    A signal handler's exception raised inside a callback (a weakref's, an import lock's) is only
    printed as "Exception ignored" and the code goes on; :func:`removed_on_signals` keeps such a
    Ctrl-C here instead: an atomic output checks it before it names its file, the command line
    when a command returns, and loops that wait (the fleet's) between their waits.
    """
    if _INTERRUPTED.is_set():
        raise KeyboardInterrupt


class Deadline:
    """Ends the process ``GRACE_S`` after :meth:`arm` unless :meth:`disarm` comes first.

    A Ctrl-C unwinds a command through its clean-up (workers stopped, threads joined); if any of it
    blocks for good — a thread waiting on a lock the interrupted code held, a worker pool that will
    not stop — the command would never end. The watcher is a daemon thread started beforehand and
    armed from the signal handler by releasing a raw lock: arming takes no lock the interrupted
    code may hold. Outputs are written whole or not at all, so ending without the clean-up leaves
    no partial file; only hidden temporary files may stay.
    """

    def __init__(self, code: int = 130, grace_s: float | None = None) -> None:
        self.code, self.grace_s = code, GRACE_S if grace_s is None else grace_s
        self._armed = _thread.allocate_lock()
        self._armed.acquire()
        self._over = _thread.allocate_lock()
        self._over.acquire()
        self._state = "idle"
        threading.Thread(target=self._watch, name="mountcal-interrupt-deadline", daemon=True).start()

    def arm(self, code: int | None = None) -> None:
        if self._state == "idle":
            self.code = self.code if code is None else code
            self._state = "armed"
            self._armed.release()

    def disarm(self) -> None:
        if self._state == "idle":
            self._state = "disarmed"
            self._armed.release()
        elif self._state == "armed":
            self._state = "disarmed"
            self._over.release()

    def _watch(self) -> None:
        self._armed.acquire()
        if self._state != "armed":
            return
        started = time.monotonic()
        if self._over.acquire(timeout=self.grace_s):
            return
        message = (
            f"mountcal: interrupted {time.monotonic() - started:.0f} s ago and its clean-up has not ended "
            "(a thread or worker that would not stop); ending now. Outputs are written whole or not "
            "at all: none is partial. Run the same command again.\n"
        )
        with contextlib.suppress(OSError):
            os.write(2, message.encode())
        os._exit(self.code)


@contextlib.contextmanager
def removed_on_signals() -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise :class:`Terminated` (as SIGINT raises
    KeyboardInterrupt), so every write in progress unwinds: the temporary files of
    :func:`atomic_path` are removed, an :func:`atomic_output` is never named, a lock is released.
    A second signal ends the process at once. A Ctrl-C that lands in a callback (where Python
    drops the exception with a traceback) is kept, silently, for :func:`raise_if_interrupted`.
    However the command unwinds, it ends within :data:`GRACE_S` of the first signal (:class:`Deadline`).
    Outside the main thread: no change.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    deadline = Deadline()

    def terminate(signum: int, _: object) -> None:
        for sig in CLEAN_UP_SIGNALS:
            signal.signal(sig, signal.SIG_DFL)
        deadline.arm(128 + signum)
        raise Terminated(signum)

    def interrupt(signum: int, frame: object) -> None:
        _INTERRUPTED.set()
        deadline.arm(130)
        signal.default_int_handler(signum, frame)  # type: ignore[arg-type]

    def unraisable(info: UnraisableHookArgs) -> None:
        if info.exc_type is not None and issubclass(info.exc_type, KeyboardInterrupt):
            _INTERRUPTED.set()  # a Ctrl-C dropped in a callback: kept for raise_if_interrupted
            return
        hook(info)

    _INTERRUPTED.clear()
    previous = {sig: signal.signal(sig, terminate) for sig in CLEAN_UP_SIGNALS}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not where Ctrl-C is ignored
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, interrupt)
    hook, sys.unraisablehook = sys.unraisablehook, unraisable
    try:
        yield
    finally:
        deadline.disarm()
        _INTERRUPTED.clear()  # its block is over: what it held has been raised or is moot
        sys.unraisablehook = hook
        for sig, handler in previous.items():
            signal.signal(sig, handler)


__all__ = [
    "Deadline",
    "GrowingFile",
    "Terminated",
    "atomic_output",
    "atomic_path",
    "raise_if_interrupted",
    "removed_on_signals",
]
