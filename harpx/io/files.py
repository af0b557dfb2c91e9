"""The file system side of harpx's archive writers and readers.

Targets harpx must never replace are refused (:func:`check_writable_target`); temporary
files are named by host and process (:func:`temporary_prefix`) so that the leftovers of a
killed write can be told from a write still running and removed
(:func:`remove_stale_temporaries`). The private helpers check path arguments, give a new
file its permissions, persist a rename (``fsync`` of the directory) and read the memory
available (for the size checks of :func:`~harpx.io.netcdf.open_dataset` and
:func:`~harpx.io.dicom.read_tagged`).
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import stat
from pathlib import Path
from typing import Any

from harpx.errors import ArchiveError

__all__ = ["check_writable_target", "remove_stale_temporaries", "temporary_prefix"]


def check_writable_target(path: Path) -> Path:
    """Refuse targets harpx must never replace; return the target's directory.

    An existing target must be a regular file (not a symbolic link, directory, device
    node, FIFO or socket) that the user may write: :func:`os.replace` would otherwise
    turn a link into a file, replace a device node, or overwrite a file its owner made
    read-only.

    Parameters
    ----------
    path : pathlib.Path
        The file about to be written.

    Returns
    -------
    pathlib.Path
        Its directory (``.`` for a bare name).

    Raises
    ------
    ArchiveError
        Naming the path and what it is, and what to do instead.
    """
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise ArchiveError(
            f"cannot write {str(path)!r}: directory {str(directory)!r} does not exist; "
            "create it first"
        )
    if path.is_symlink():
        raise ArchiveError(
            f"refusing to write {str(path)!r}: it is a symbolic link (to "
            f"{os.readlink(path)!r}), which the atomic write would replace by a file; write to "
            "the link's target path instead, or remove the link"
        )
    if not path.exists():
        return directory
    st = path.stat()
    if not stat.S_ISREG(st.st_mode):
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        raise ArchiveError(
            f"refusing to write {str(path)!r}: it is {kind} (mode {stat.filemode(st.st_mode)}); "
            "choose a file name"
        )
    if not (st.st_mode & 0o222 and os.access(path, os.W_OK)):  # root may write any file
        raise ArchiveError(
            f"refusing to overwrite {str(path)!r}: the file is read-only; make it writable "
            "(chmod u+w) if it may be replaced, or write elsewhere"
        )
    return directory


def temporary_prefix(name: str) -> str:
    """Prefix of the temporary files harpx writes beside ``name`` (host and process id).

    The prefix lets :func:`remove_stale_temporaries` tell the leftovers of a killed
    harpx write from the temporary file of a write still running.

    Parameters
    ----------
    name : str
        File name (without directory) of the file being written.

    Returns
    -------
    str
        ``".<name>.harpx-<host>-<pid>-"``.
    """
    return f".{name}.harpx-{socket.gethostname()}-{os.getpid()}-"


def remove_stale_temporaries(directory: Path, name: str) -> list[Path]:
    """Delete temporary files of earlier harpx writes of ``name`` whose process has died.

    Only names harpx itself makes (:func:`temporary_prefix`, ``.tmp`` suffix) on this host
    are considered, and only when no process with the recorded id is alive; anything
    else beside the target is left alone.

    Parameters
    ----------
    directory : pathlib.Path
        Directory of the target.
    name : str
        File name of the target.

    Returns
    -------
    list of pathlib.Path
        The files or directories removed.
    """
    pattern = re.compile(rf"^\.{re.escape(name)}\.harpx-(?P<host>.+)-(?P<pid>\d+)-[^/]*\.tmp$")
    host = socket.gethostname()
    removed: list[Path] = []
    try:
        entries = list(directory.iterdir())
    except OSError:
        return removed
    for entry in entries:
        match = pattern.match(entry.name)
        if match is None or match["host"] != host or _alive(int(match["pid"])):
            continue
        try:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
        except OSError:
            continue
        removed.append(entry)
    return removed


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists but not ours (EPERM)
        return True
    return True


def _check_path(path: Any) -> None:
    """TypeError naming ``path`` unless it is a str or os.PathLike."""
    if not isinstance(path, str | os.PathLike):
        raise TypeError(
            f"path={path!r} must be a file path (str or os.PathLike), not {type(path).__name__}"
        )


def _available_memory() -> int:
    """Bytes of memory available now (Linux ``MemAvailable``), else 16 GiB (assumed).

    The readers allow an eager load half of this: 8 GiB where the memory is unknown.
    """
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 16 << 30


def _target_mode(path: Path) -> int:
    """Permissions for the new archive: the existing file's, else 0o666 minus the umask."""
    try:
        return path.stat().st_mode & 0o777
    except OSError:
        pass
    umask = 0o022
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                umask = int(line.split()[1], 8)
                break
    except (OSError, ValueError):
        pass
    return 0o666 & ~umask


def _fsync_directory(directory: Path) -> None:
    """Persist the rename itself (best effort; not supported on every platform)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
