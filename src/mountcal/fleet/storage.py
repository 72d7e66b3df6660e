"""Logs in object storage (S3, MinIO, any fsspec URL): list, identify and fetch them in bounded memory.

- :func:`list_objects` lists every object under a URL (``s3://bucket/LOG``) with its size and a
  *stamp* — ETag, size and modification time — which keys its result instead of a hash of its
  bytes: resuming a fleet in a bucket reads no log again.
- :func:`local_copies` fetches the objects of one log (the splits of one session) to a private
  scratch folder on the worker, in blocks of :data:`BLOCK_BYTES` (the memory one fetch holds),
  and deletes them when the log is calibrated; :func:`local_folder` fetches a log that is a prefix
  (a Sensor Logger recording, a ROS 2 bag …) into one folder, its objects at their paths below it.
  mountcal's readers work on files (memory maps, seeks), so a worker holds one log's objects on its
  scratch disk at a time — never the fleet.

Endpoint and credentials come from the standard AWS variables and profiles (``AWS_ACCESS_KEY_ID``,
``AWS_SECRET_ACCESS_KEY``, ``AWS_PROFILE``, ``AWS_ENDPOINT_URL`` for MinIO or another S3-compatible
server), read by botocore, or from ``--storage-option KEY=VALUE`` (fsspec's options of the
protocol, e.g. ``endpoint_url=…``, ``anon=true``). s3fs comes with ``pip install 'mountcal[fleet]'``.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import re
import shutil
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from mountcal.core.errors import InputError

BLOCK_BYTES = 8 << 20  # one ranged read of a fetch: the memory a worker's fetch holds
SCRATCH_PREFIX = "mountcal-fetch-"  # + the worker's pid; a killed worker's folder is removed by the next sweep
SCRATCH_LOCK = ".held"  # locked by the fetch that owns the folder: the kernel releases it when the worker dies
_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
STORAGE_OPTION = "--storage-option"


def is_url(text: str) -> bool:
    """Whether ``text`` names an object store (``s3://…``, ``gcs://…``, ``memory://…``), not a local path."""
    return bool(_URL.match(text))


@dataclass(frozen=True)
class RemoteObject:
    """One listed object: its URL, size in bytes, stamp (what identifies this version of it) and its path
    below the URL listed (its key's rest; ``""`` for an object the URL names itself)."""

    url: str
    size: int
    stamp: str
    relative: str = ""


def parse_storage_options(items: Sequence[str]) -> dict[str, Any]:
    """``KEY=VALUE`` strings as fsspec options; ``true``/``false`` and numbers are converted.

    Raises
    ------
    InputError
        An item without ``=`` or without a key.
    """
    options: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise InputError(
                f"{STORAGE_OPTION} {item}",
                "KEY=VALUE (an fsspec storage option, e.g. endpoint_url=http://127.0.0.1:9000)",
                repr(item),
                "Write the option as KEY=VALUE.",
            )
        options[key.strip()] = _typed(value.strip())
    return options


def _typed(value: str) -> Any:
    if value.lower() in ("true", "false"):
        return value.lower() == "true"
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    return value


def filesystem(url: str, options: Mapping[str, Any]) -> tuple[Any, str]:
    """The fsspec filesystem of ``url`` and the path inside it.

    Raises
    ------
    InputError
        The protocol's package is missing, or the options do not fit it.
    """
    import fsspec

    key = (url.split("://", 1)[0], repr(sorted(options.items())), _storage_environment())
    held = _FILESYSTEMS.get(key)
    if held is not None and "::" not in url:  # a chained URL's path is the chain's to strip
        return held, str(held._strip_protocol(url))
    try:
        # fsspec reuses a filesystem made with the same arguments, whatever the environment now says: a
        # notebook that points AWS_ENDPOINT_URL (or a profile, or keys) elsewhere between two runs would
        # list the old server's bucket. A filesystem is reused here only where the environment is the same.
        fs, path = fsspec.core.url_to_fs(url, skip_instance_cache=True, **dict(options))
        held = _FILESYSTEMS.setdefault(key, fs)  # fsspec is untyped: the filesystem stays Any
        return held, str(path)
    except ImportError as err:
        raise InputError(
            url,
            "a storage URL mountcal can open",
            f"the package for it is not installed ({err})",
            "Install it: pip install 'mountcal[fleet]' (s3fs for s3://).",
        ) from err
    except (TypeError, ValueError) as err:
        raise InputError(
            url, "storage options the protocol takes", str(err), f"Check {STORAGE_OPTION} and the URL."
        ) from err


_FILESYSTEMS: dict[tuple[Any, ...], Any] = {}
_ENVIRONMENT_PREFIXES = ("AWS_", "FSSPEC_", "GOOGLE_", "AZURE_")  # where fsspec's protocols read settings


def _storage_environment() -> tuple[tuple[str, str], ...]:
    return tuple(sorted((k, v) for k, v in os.environ.items() if k.startswith(_ENVIRONMENT_PREFIXES)))


def storage_error(url: str, err: BaseException, doing: str) -> InputError:
    """A storage failure (no such bucket, no credentials, no endpoint) in the user's terms."""
    if isinstance(err, FileNotFoundError):
        found, todo = "no such bucket, folder or object", "Check the URL."
    elif isinstance(err, PermissionError):
        found, todo = f"access denied ({err})", "Check the credentials (AWS_PROFILE, AWS_ACCESS_KEY_ID …)."
    else:
        found = f"{type(err).__name__}: {err}"
        todo = (
            "Check the endpoint and credentials: the AWS variables (AWS_ENDPOINT_URL for MinIO or another "
            "S3-compatible server, AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY, AWS_PROFILE) "
            f"or {STORAGE_OPTION} KEY=VALUE."
        )
    return InputError(url, f"a readable object store ({doing})", found, todo)


_STORAGE_ERRORS: tuple[type[BaseException], ...] = (OSError, ValueError, RuntimeError)


def _storage_errors() -> tuple[type[BaseException], ...]:
    """The exceptions a storage call raises for the user's reasons (botocore's, when it is installed)."""
    try:
        from botocore.exceptions import BotoCoreError, ClientError
    except ImportError:
        return _STORAGE_ERRORS
    return (*_STORAGE_ERRORS, BotoCoreError, ClientError)


def stamp_of(info: Mapping[str, Any]) -> str:
    """What identifies one version of an object: its ETag (or checksum), size and modification time."""
    tag = next((info[k] for k in ("ETag", "etag", "md5", "checksum") if info.get(k)), None)
    mtime = next((info[k] for k in ("LastModified", "mtime", "last_modified", "updated") if info.get(k)), None)
    size = info.get("size", info.get("Size"))
    return f"etag={str(tag).strip(chr(34))} size={size} mtime={mtime}"


def list_objects(url: str, options: Mapping[str, Any]) -> list[RemoteObject]:
    """Every object under ``url`` (recursively; hidden names skipped), sorted by URL.

    Raises
    ------
    InputError
        Nothing there, or the store refused (the message says what to check).
    """
    fs, root = filesystem(url, options)
    try:
        found = fs.find(root, detail=True, withdirs=False) if fs.isdir(root) else {root: fs.info(root)}
    except _storage_errors() as err:
        raise storage_error(url, err, "listing") from err
    protocol = url.split("://", 1)[0]
    top = root.rstrip("/") + "/"
    objects = []
    for path, info in found.items():
        if info.get("type", "file") != "file":
            continue
        relative = PurePosixPath(path).parts[len(PurePosixPath(root).parts) :]
        if any(part.startswith(".") for part in relative):
            continue
        below = path[len(top) :] if path.startswith(top) else ""  # as stored (a key may hold "//")
        objects.append(RemoteObject(f"{protocol}://{path}", int(info.get("size") or 0), stamp_of(info), below))
    if not objects:
        raise InputError(url, "objects under this URL", "none", "Check the bucket and prefix.")
    return sorted(objects, key=lambda o: o.url)


def folder_stamp(objects: Sequence[RemoteObject]) -> str:
    """The stamp of a log that is a folder of objects: its objects' paths inside it and their stamps (as a
    local folder's key is its files' paths and digests)."""
    digest = hashlib.sha256()
    for obj in sorted(objects, key=lambda o: o.relative):
        digest.update(f"{obj.relative}\0{obj.stamp}\0".encode())
    return f"objects={len(objects)} sha256={digest.hexdigest()}"


def is_file_path(relative: str) -> bool:
    """Whether an object's path below a prefix can be a file's path inside a local folder (no empty, ``.``
    or ``..`` part: a copy never lands outside its folder)."""
    return all(part not in ("", ".", "..") for part in relative.split("/"))


@contextlib.contextmanager
def local_copies(urls: Sequence[str], options: Mapping[str, Any], stamps: Sequence[str | None]) -> Iterator[list[str]]:
    """Local files holding the objects ``urls`` for the block (each under its own name, so the reader
    sees its suffix), fetched in :data:`BLOCK_BYTES` reads; deleted afterwards however the block ends.

    Raises
    ------
    InputError
        An object is missing, unreadable, or changed since it was listed (its stamp differs).
    """
    with _scratch() as scratch:
        paths = []
        for i, (url, stamp) in enumerate(zip(urls, stamps, strict=True)):
            target = os.path.join(scratch, str(i), PurePosixPath(filesystem(url, options)[1]).name)
            os.mkdir(os.path.dirname(target))
            _fetch(url, stamp, options, target)
            paths.append(target)
        yield paths


@contextlib.contextmanager
def local_folder(url: str, objects: Sequence[RemoteObject], options: Mapping[str, Any]) -> Iterator[str]:
    """A local folder holding the objects of a log that is a prefix in storage (``url``; a Sensor Logger
    recording, a ROS 2 bag …), each at its path below the prefix (``relative``) and checked against its
    listed stamp, fetched as :func:`local_copies` fetches; deleted afterwards however the block ends.

    Raises
    ------
    InputError
        An object is missing, unreadable, changed since it was listed, or has no file's path.
    """
    with _scratch() as scratch:
        folder = os.path.join(scratch, "0", PurePosixPath(filesystem(url, options)[1]).name or "log")
        for obj in objects:
            if not is_file_path(obj.relative):  # the listing sets these aside: never written outside the folder
                raise InputError(obj.url, f"an object below {url}", f"the path {obj.relative!r}", "Rename it.")
            target = os.path.join(folder, *obj.relative.split("/"))
            os.makedirs(os.path.dirname(target), exist_ok=True)
            _fetch(obj.url, obj.stamp, options, target)
        yield folder


@contextlib.contextmanager
def _scratch() -> Iterator[str]:
    """A private scratch folder on the worker, locked while the block runs and deleted afterwards;
    killed workers' folders are swept before and after."""
    remove_orphans()
    scratch = tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-")
    lock = os.path.join(scratch, SCRATCH_LOCK)
    held = os.open(lock + ".new", os.O_CREAT | os.O_WRONLY, 0o600)
    try:
        fcntl.flock(held, fcntl.LOCK_EX)
        os.rename(lock + ".new", lock)  # seen by others only once locked
        yield scratch
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
        os.close(held)
        remove_orphans()  # again: a worker killed moments ago may still have held its lock at the start


def _fetch(url: str, stamp: str | None, options: Mapping[str, Any], target: str) -> None:
    """One object into the file ``target``, in :data:`BLOCK_BYTES` reads, refused if it is not the version listed."""
    fs, path = filesystem(url, options)
    try:
        fs.invalidate_cache(path)  # the object as it is now, not as a listing in this process cached it
        info = fs.info(path)
        if stamp is not None and stamp_of(info) != stamp:
            raise InputError(
                url,
                "the object as it was listed",
                f"another version ({stamp_of(info)}; listed {stamp})",
                "It changed during the run: run the same command again.",
            )
        with fs.open(path, "rb", block_size=BLOCK_BYTES, cache_type="none") as src, open(target, "wb") as out:
            shutil.copyfileobj(src, out, BLOCK_BYTES)
    except InputError:
        raise
    except _storage_errors() as err:
        raise storage_error(url, err, "reading an object") from err


def remove_orphans() -> int:
    """Delete the scratch folders of workers that were killed while fetching, and say how many: their
    lock is free (a pid alone is not proof: on a busy machine a dead worker's pid is soon another
    process's). Each fetch sweeps before and after; the fleet command sweeps once more when its
    workers are done, since a killed process may release its lock a moment after it looks dead."""
    removed = 0
    for folder in Path(tempfile.gettempdir()).glob(f"{SCRATCH_PREFIX}*-*"):
        if _orphaned(folder):
            shutil.rmtree(folder, ignore_errors=True)
            removed += not folder.exists()
    return removed


def _orphaned(folder: Path) -> bool:
    pid = folder.name[len(SCRATCH_PREFIX) :].split("-", 1)[0]
    try:
        held = os.open(folder / SCRATCH_LOCK, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:  # no lock yet (a fetch starting) or not ours: only a dead pid says so
        return pid.isdigit() and not _alive(int(pid))
    try:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False  # its fetch holds it
    finally:
        os.close(held)
    return True


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: alive, and not ours to clean
        return True
    return True


__all__ = [
    "BLOCK_BYTES",
    "RemoteObject",
    "filesystem",
    "folder_stamp",
    "is_file_path",
    "is_url",
    "list_objects",
    "local_copies",
    "local_folder",
    "parse_storage_options",
    "remove_orphans",
    "stamp_of",
]
