"""Where a command reads and writes: the rules that keep inputs safe and system errors readable.

- An input (protocol sheet, mapping, DBC, calibration JSON, stop table, manifest) is a regular file
  of bounded size: a device, FIFO or directory is refused before it is opened, so reading it ends
  in a time bounded by its size. :func:`input_file` checks one (or a folder, where one is taken).
- An output lands only on a regular file or a new path, never on a file the command reads nor on
  another output of the same command (same resolved path, or the same inode: hard links,
  symlinks). :func:`check_outputs` checks them all at once, before any work is done. The command
  line calls both from the paths each parser declares (:mod:`mountcal.cli.path_options`).
- An ``OSError`` is a :class:`SystemFailure` naming the path, the operation and what to do.
- :func:`output_lock` keeps two runs from writing one output at the same time; its lock file is
  created with ``O_EXCL|O_NOFOLLOW``, so a symlink planted under its name truncates nothing.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import stat
import sys
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from mountcal.core import budget
from mountcal.core.errors import InputError, MountcalError

SMALL_INPUT_LIMIT_BYTES = 256 * 2**20  # protocol sheets, mappings, DBCs, results, stop tables, manifests
LIMIT_VARIABLE = "MOUNTCAL_MAX_INPUT_MB"  # raises the limit above, in MiB

PathLike = str | os.PathLike[str]


class SystemFailure(MountcalError):
    """The operating system refused a read or a write (no space, no permission, ...)."""

    exit_code = 5

    def __init__(self, path: str, operation: str, err: OSError, *, left: str = "no partial file was left") -> None:
        """``left`` says what the failed write left behind (said where space ran out)."""
        self.path, self.operation, self.errno = path, operation, err.errno
        reason = err.strerror or str(err)
        code = errno.errorcode.get(err.errno or 0, "")
        todo = _todo(err.errno).replace("{left}", left)
        super().__init__(f"{path}: {operation} failed: {reason}{f' ({code})' if code else ''}. {todo}")


def _todo(code: int | None) -> str:
    todo = {
        errno.ENOSPC: "Free space on that disk or write to another one; {left}.",
        errno.EDQUOT: "Free space within your quota or write elsewhere; {left}.",
        errno.EFBIG: "The file is larger than this system allows (see `ulimit -f`); write elsewhere; {left}.",
        errno.EACCES: "Choose a folder you may write to (or a file you may read), or fix its permissions.",
        errno.EPERM: "Choose a folder you may write to (or a file you may read), or fix its permissions.",
        errno.EROFS: "That file system is read-only: write elsewhere.",
        errno.EISDIR: "Name a file, not a directory.",
        errno.ENOTDIR: "A part of the path is a file, not a folder: check the path.",
        errno.ENOENT: "Check the path.",
        errno.EIO: "The device reported an I/O error: check the disk, then retry.",
    }
    return todo.get(code or 0, "Check the path and the system, then retry.")


STDIN = "-"


def small_input_limit() -> int:
    """The size limit of a small input, in bytes (``MOUNTCAL_MAX_INPUT_MB`` raises it)."""
    return budget.setting("input")


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "a special file"


def special_kind(path: PathLike) -> str | None:
    """What ``path`` is when it exists and is not a regular file ("a FIFO (named pipe)"), else None."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    return None if stat.S_ISREG(mode) else _kind(mode)


def input_file(path: PathLike, what: str, *, limit: int | None = None, folders: bool = False) -> Path:
    """Check that ``path`` is a regular file of at most ``limit`` bytes (or, with ``folders``, a
    folder); return it as a Path.

    ``what`` names the input in the message ("the protocol sheet"). The file is not opened: a FIFO
    or a device would block or never end.
    """
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError as err:
        raise InputError(str(path), f"{what} ({_a_file(folders)})", "no such file", "Check the path.") from err
    except OSError as err:
        if err.errno == errno.ELOOP:
            found, todo = "a symlink loop", f"Point the path at {_a_file(folders)}."
            raise InputError(str(path), f"{what} ({_a_file(folders)})", found, todo) from err
        raise SystemFailure(str(path), f"reading {what}", err) from err
    if folders and stat.S_ISDIR(st.st_mode):
        return path
    if not stat.S_ISREG(st.st_mode):
        raise InputError(
            str(path), f"{what} as a regular file", _kind(st.st_mode), "Pass a regular file; mountcal reads no devices."
        )
    limit = small_input_limit() if limit is None else limit
    if st.st_size > limit:
        raise InputError(
            str(path),
            f"{what} of at most {limit / 2**20:g} MiB",
            f"{st.st_size / 2**20:.1f} MiB",
            f"Check that this is the right file, or raise the limit with {LIMIT_VARIABLE}=N (MiB).",
        )
    return path


def _a_file(folders: bool) -> str:
    return "a file or folder" if folders else "a file"


def read_input_bytes(path: PathLike, what: str, *, limit: int | None = None) -> bytes:
    """The bytes of a small input, after :func:`input_file`; never more than the limit. ``-`` is stdin."""
    limit = small_input_limit() if limit is None else limit
    if str(path) == STDIN:
        data = sys.stdin.buffer.read(limit + 1)
        if len(data) > limit:
            raise InputError(STDIN, f"{what} of at most {limit / 2**20:g} MiB", "more on stdin", "Pass a file.")
        return data
    path = input_file(path, what, limit=limit)
    try:
        with path.open("rb") as f:
            data = f.read(limit + 1)
    except OSError as err:
        raise SystemFailure(str(path), f"reading {what}", err) from err
    if len(data) > limit:  # grew since the check
        raise InputError(str(path), f"{what} of at most {limit / 2**20:g} MiB", "a file still growing", "Retry.")
    return data


def _same(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name one file: the same path once ``..`` and symlinks are resolved, or
    the same inode (a hard link; a case-insensitive file system's other spelling)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def _output_stat(name: str, out: Path) -> os.stat_result | None:
    """What is at an output's path now (None: nothing yet); a symlink loop on the way is refused."""
    try:
        return os.stat(out)
    except OSError as err:
        if err.errno == errno.ELOOP:
            raise InputError(
                f"{name} {out}", "a path to write", "a symlink loop", "Remove the loop or name another path."
            ) from err
        return None


def check_outputs(
    outputs: Mapping[str, PathLike | None], inputs: Mapping[str, PathLike | Iterable[PathLike] | None]
) -> None:
    """Refuse outputs that would replace an input, each other, or anything but a regular file.

    Parameters
    ----------
    outputs : mapping
        Option name (``"-o"``, ``"--report"``) to the path it names; None for an output not asked.
    inputs : mapping
        Option name (``"input"``, ``"--dbc"``) to a path, several paths, or None.
    """
    read: list[tuple[str, Path]] = []
    for name, value in inputs.items():
        if value is None:
            continue
        many = [value] if isinstance(value, str | os.PathLike) else list(value)
        read += [(name, Path(p)) for p in many if str(p) != "-"]
    written: list[tuple[str, Path]] = []
    for name, value in outputs.items():
        if value is None:
            continue
        out = Path(value)
        st = _output_stat(name, out)
        if st is not None and not stat.S_ISREG(st.st_mode):
            raise InputError(
                f"{name} {out}",
                "a regular file or a new path to write",
                _kind(st.st_mode),
                "Name a file; mountcal never replaces a directory, device, FIFO or socket.",
            )
        clashes = [
            (
                path,
                "an output path other than the files this command reads",
                f"the {what} file {path}",
                f"Choose another {name} path; mountcal never overwrites its input.",
            )
            for what, path in read
        ]
        clashes += [
            (
                path,
                "a path of its own for each output",
                f"the path also given to {other}",
                f"Give {name} and {other} different paths.",
            )
            for other, path in written
        ]
        for path, expected, found, todo in clashes:
            if _same(out, path):
                raise InputError(f"{name} {out}", expected, found, todo)
        written.append((name, out))


@contextlib.contextmanager
def output_lock(output: PathLike) -> Iterator[None]:
    """Hold an exclusive lock on ``output`` for the block, or refuse at once naming the holder.

    The lock is ``flock`` on a hidden ``.NAME.lock`` beside the output (released by the kernel when
    the process ends, however it ends); the file holds the holder's pid for the message.
    """
    output = Path(output)
    lock = output.with_name(f".{output.name}.lock")
    try:
        output.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise SystemFailure(str(lock), "creating the lock file", err) from err
    fd = _open_lock_file(lock, output)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as err:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
            raise InputError(
                str(output),
                "an output no other mountcal run is writing",
                f"it locked by process {holder} ({lock})",
                "Wait for that run to finish (or stop it), or choose another -o.",
            ) from err
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)  # releases the lock; the file stays (removing it would race a waiting run)


def _open_lock_file(lock: Path, output: Path) -> int:
    """The lock file, created with ``O_EXCL|O_NOFOLLOW`` or opened without following a symlink.

    Whatever else is planted under its name (a symlink to a file of yours, a hard link, a FIFO) is
    refused before anything is written: the holder's pid is written into the file, which would
    otherwise truncate the file a link points at.
    """
    flags = os.O_RDWR | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    try:
        try:
            fd = os.open(lock, flags | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:  # left by an earlier run (it is never removed: see output_lock)
            fd = os.open(lock, flags)
    except OSError as err:
        if err.errno != errno.ELOOP:
            raise SystemFailure(str(lock), "creating the lock file", err) from err
        found = "a symlink"
    else:
        st = os.fstat(fd)
        if stat.S_ISREG(st.st_mode) and st.st_nlink == 1:
            return fd
        os.close(fd)
        found = "a hard link to another file" if stat.S_ISREG(st.st_mode) else _kind(st.st_mode)
    raise InputError(
        str(lock),
        f"the lock file of {output} (a regular file mountcal creates)",
        found,
        "Remove it (mountcal writes nothing through it), then run again.",
    )


def read_document(path: str | os.PathLike[str], what: str, *, toml: bool = False) -> Any:
    """A JSON (or TOML) file parsed within the budget (:func:`mountcal.core.budget.document`): a regular
    file of at most the input limit, whose size is charged before a byte of it is read."""
    size = input_file(path, what).stat().st_size  # a FIFO or a device is refused unopened
    budget.charge("document", size, str(path), f"bytes of JSON and TOML ({what})")
    return budget.document(read_input_bytes(path, what), str(path), what, toml=toml, charged=True)


__all__ = [
    "SMALL_INPUT_LIMIT_BYTES",
    "SystemFailure",
    "check_outputs",
    "input_file",
    "output_lock",
    "read_document",
    "read_input_bytes",
    "small_input_limit",
    "special_kind",
]
