"""Atomic file writes: write to a temporary file in the destination folder, fsync, then rename.

A reader (or a resumed run) therefore sees either the old file or the complete new one, never a
half-written file, even if the process is killed with SIGKILL.

``tempfile`` creates its files ``0600`` and folders ``0700`` whatever the umask; outputs that are
renamed into place from there are given the modes an ordinary ``open``/``mkdir`` would have
(``0644`` / ``0755`` under umask 022), so that a shared results folder stays readable.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import hashlib
import os
import re
import shutil
import socket
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

#: A temporary file written by a process on another machine is taken as left by a killed writer once it
#: is this old (seconds); on this machine the writer's process id (in the name) tells at once.
STALE_TEMPORARY_SECONDS = 3600.0
_WRITER = re.compile(r"\.w([A-Za-z0-9_-]+)-(\d+)\.[^/]*\.tmp[^/]*$")


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname().split(".")[0]) or "host"


def writer_tag() -> str:
    """``w<host>-<pid>``: put in temporary file names so that a cleaner can tell whose write it is."""
    return f"w{_host()}-{os.getpid()}"


def is_stale_temporary(path: str | os.PathLike[str]) -> bool:
    """Whether a temporary file (named by :func:`atomic_path`) was left by a writer that is gone: a dead
    process on this machine, or, for another machine's (or an untagged) file, older than
    :data:`STALE_TEMPORARY_SECONDS`.  Lets processes that share a folder without a lock clean up after
    killed writers without deleting each other's writes in progress."""
    path = Path(path)
    match = _WRITER.search(path.name)
    if match and match.group(1) == _host():
        pid = int(match.group(2))
        if pid == os.getpid():
            return False
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        except PermissionError:
            return False
        return False
    try:
        return time.time() - path.stat().st_mtime > STALE_TEMPORARY_SECONDS
    except FileNotFoundError:
        return False


def _temporary_beside(destination: Path, ext: str) -> Path:
    """A new empty file ``.<stem>.<writer>.<random>.tmp<ext>`` in ``destination``'s folder (created if needed);
    the name keeps the extension (libraries such as OpenImageIO pick the format from it) and the writer's
    tag (:func:`is_stale_temporary`)."""
    destination.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(
        prefix=f".{destination.stem}.{writer_tag()}.", suffix=f".tmp{ext}", dir=destination.parent
    )
    os.close(fd)
    return Path(name)


@contextlib.contextmanager
def atomic_path(destination: str | os.PathLike[str], suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to ``destination``; rename it onto ``destination`` on success.

    The temporary name keeps the destination's extension (libraries such as OpenImageIO pick the
    format from it).  On any exception the temporary file is removed and the destination untouched.
    """
    destination = Path(destination)
    tmp = _temporary_beside(destination, destination.suffix if suffix is None else suffix)
    try:
        yield tmp
        os.chmod(tmp, new_file_mode())
        _fsync_file(tmp)
        os.replace(tmp, destination)
        _fsync_dir(destination.parent)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def private_temporary(destination: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a fresh, uniquely named temporary file beside ``destination`` (created with the umask's mode),
    removed when the block ends; for writers that publish it themselves, e.g. with a hard link."""
    destination = Path(destination)
    tmp = _temporary_beside(destination, destination.suffix)
    try:
        os.chmod(tmp, new_file_mode())
        yield tmp
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def current_umask() -> int:
    """The process umask, read without changing it (Linux ``/proc``); elsewhere set and restored at once."""
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text(encoding="ascii").splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def new_file_mode() -> int:
    """The mode ``open`` gives a new file under the current umask (``0o644`` under umask 022)."""
    return 0o666 & ~current_umask()


def new_dir_mode() -> int:
    """The mode ``mkdir`` gives a new folder under the current umask (``0o755`` under umask 022)."""
    return 0o777 & ~current_umask()


def staging_dir(parent: str | os.PathLike[str], prefix: str, suffix: str = "") -> Path:
    """A new, uniquely named folder in ``parent`` with the umask's folder mode (``tempfile.mkdtemp`` gives 0700).

    Used to build an output folder that is renamed into place when complete.
    """
    folder = Path(tempfile.mkdtemp(prefix=prefix, suffix=suffix, dir=parent))
    os.chmod(folder, new_dir_mode())
    return folder


@contextlib.contextmanager
def staged_folder(
    destination: str | os.PathLike[str], prefix: str | None = None, suffix: str = ".tmp"
) -> Iterator[Path]:
    """Build a folder that replaces ``destination`` whole: yields a staging folder beside it, which is swapped
    in when the block ends normally (:func:`replace_folder`) and deleted when it raises.

    The staging folder is named ``<prefix><random><suffix>``; ``prefix`` defaults to ``.<name>.``.
    """
    destination = Path(destination)
    destination.parent.mkdir(parents=True, exist_ok=True)
    if prefix is None:
        prefix = f".{destination.name}."
    staging = staging_dir(destination.parent, prefix=prefix, suffix=suffix)
    try:
        yield staging
        replace_folder(staging, destination)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def replace_folder(staging: Path, destination: Path) -> None:
    """Put the complete folder ``staging`` at ``destination`` and delete the previous ``destination``.

    One ``renameat2(RENAME_EXCHANGE)`` where Linux offers it, so a reader sees the old folder or the new one,
    never a mix; elsewhere two renames (the old folder is moved aside first).
    """
    if not destination.exists():
        os.rename(staging, destination)
        return
    if _exchange(staging, destination):  # destination now holds the new files, staging the old ones
        shutil.rmtree(staging)
        return
    old = destination.with_name(f".{destination.name}.old")
    shutil.rmtree(old, ignore_errors=True)
    os.rename(destination, old)
    os.rename(staging, destination)
    shutil.rmtree(old)


_RENAME_EXCHANGE = 2  # linux/fs.h


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap two paths (Linux ``renameat2``); ``False`` where unavailable."""
    with contextlib.suppress(OSError, AttributeError, TypeError):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        at_fdcwd = -100
        result = libc.renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
        return result == 0
    return False


def write_bytes_atomic(destination: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``destination`` atomically."""
    with atomic_path(destination) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(destination: str | os.PathLike[str], text: str) -> None:
    """Write UTF-8 ``text`` to ``destination`` atomically."""
    write_bytes_atomic(destination, text.encode("utf-8"))


def sha256_file(path: str | os.PathLike[str], chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while chunk := handle.read(chunk_bytes):
            digest.update(chunk)
    return digest.hexdigest()


def _fsync_file(path: Path) -> None:
    with open(path, "rb") as handle:
        os.fsync(handle.fileno())


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
