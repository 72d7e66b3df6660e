"""Atomic output: a file appears at its target only complete, never partial.

Two forms of the one rule, for the two ways libraries write:

- :func:`atomic_output` yields an open binary file (the streaming writers: Parquet row group by
  row group, MCAP record by record). It is an unnamed file in the target's folder (Linux
  ``O_TMPFILE``), linked to its name once complete: a process that dies before that — an
  exception, a crash, ``SIGKILL`` — leaves no file at all.
- :func:`atomic_path` yields a temporary path beside the target (for writers that want a path:
  ``DataFrame.to_csv``, ``pyarrow.parquet.write_table``), renamed onto the target on success and
  removed on an exception; only a hard kill can leave the hidden ``.NAME.*.part`` file.

A write the system refuses (no space, no permission, a directory in the way) is a
:class:`~mountcal.paths.SystemFailure` naming the target, with nothing left behind.

Both flush and ``fsync`` the data before the name changes, so that after a power cut the target
holds either its old content or the whole new one (``durable=False`` skips that for files that
are cheap to recompute, such as a fleet's per-log part files).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from mountcal.paths import SystemFailure


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
        _link_into_place(f.fileno(), folder, path.name)


@contextlib.contextmanager
def atomic_path(target: str | Path, *, durable: bool = True) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; on success sync it (unless ``durable`` is
    False) and rename it onto the target."""
    target = Path(target)
    with _refused_as_failure(target):
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
        os.close(fd)
    tmp = Path(name)
    try:
        with _refused_as_failure(target):
            tmp.chmod(0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual permissions
            yield tmp
            if durable:
                with tmp.open("rb+") as f:
                    os.fsync(f.fileno())
            os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def _refused_as_failure(target: Path) -> Iterator[None]:
    """An OSError of the write itself (no file named, or the target, its folder or temporary file)
    becomes a SystemFailure naming the target; an error reading some other file passes unchanged."""
    try:
        yield
    except OSError as err:
        name = None if err.filename is None else Path(os.fsdecode(err.filename))
        ours = name is None or name in (target, target.parent) or name.name.startswith(f".{target.name}.")
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


__all__ = ["atomic_output", "atomic_path"]
