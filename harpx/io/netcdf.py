"""NetCDF archives of harpx datasets: atomic writes and exact round trips.

:func:`to_netcdf` validates the dataset (when it declares a ``harpx_schema``) before any file
is opened, writes it with the netCDF4 engine and zlib compression into a temporary file in the
target's directory, flushes it to disk (``os.fsync``) and only then renames it onto the target
with :func:`os.replace`. A crash or an error therefore never leaves a half-written archive: the
target holds either the previous content or the complete new one.

:func:`open_dataset` reverses every encoding, so ``open_dataset(to_netcdf(ds, p))`` is
identical to ``ds`` (values, dims, coordinates and attributes):

- boolean variables (``mask``) are stored as int8 by xarray's own coder and come back bool;
- string coordinates (``tag``, ``axis``, ``slice_axis``) come back as ``str`` arrays;
- attribute values netCDF cannot store as such (``bool``, lists and tuples, which netCDF
  returns as scalars or arrays) are encoded and their Python type is recorded in the
  ``harpx_attr_types`` attribute (JSON) of the variable or dataset, then restored on reading.
"""

from __future__ import annotations

import json
import numbers
import os
import re
import shutil
import socket
import stat
import tempfile
from collections.abc import Hashable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import PathLike
from harpx.errors import ArchiveError

__all__ = ["open_dataset", "to_netcdf"]

#: zlib compression level used for every numeric data variable.
COMPRESSION_LEVEL = 4
_TYPES_ATTR = "harpx_attr_types"
_ENGINE = "netcdf4"


def to_netcdf(ds: xr.Dataset, path: PathLike) -> Path:
    """Write a dataset atomically to a compressed NetCDF-4 archive.

    Parameters
    ----------
    ds : xarray.Dataset
        Dataset to write. If ``ds.attrs`` has ``harpx_schema`` it is validated first.
        Dask-backed variables are computed while writing.
    path : str or os.PathLike
        Target file (conventionally ``*.nc``). Its directory must exist. An existing file is
        replaced only once the new archive is complete on disk.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    SchemaError
        If the dataset declares a harpx schema and breaks it (no file is touched).
    ArchiveError
        If an attribute cannot be stored in NetCDF (no file is touched), the directory does
        not exist or is not writable, the target is a symbolic link, a directory, a device
        node or a read-only file (never replaced: :func:`check_writable_target`), or writing
        fails (a full disk is named as such); the previous content of ``path`` is then left
        intact.

    Notes
    -----
    Numeric and boolean data variables are compressed with zlib at level
    ``COMPRESSION_LEVEL`` (4). Only a process killed mid-write (e.g. SIGKILL) can leave a
    stray temporary file ``.<name>.harpx-<host>-<pid>-*.tmp`` beside the target; the target
    itself is never partial, and the next write of the same target removes such leftovers
    once their process is gone (:func:`remove_stale_temporaries`).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> ds = xr.Dataset({"a": ("x", [1.0, 2.0], {"units": "mm", "long_name": "a"})})
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = to_netcdf(ds, pathlib.Path(tmp) / "a.nc")
    ...     back = open_dataset(path)
    >>> back.identical(ds)
    True
    """
    if "harpx_schema" in ds.attrs:
        from harpx.schema import validate

        validate(ds)
    path = Path(path)
    encoded = _encode_attrs(ds)
    directory = check_writable_target(path)
    encoding = _compression(encoded)
    mode = _target_mode(path)
    remove_stale_temporaries(directory, path.name)
    try:
        fd, tmp_name = tempfile.mkstemp(
            dir=directory, prefix=temporary_prefix(path.name), suffix=".tmp"
        )
    except OSError as exc:
        raise ArchiveError(
            f"cannot write {str(path)!r}: cannot create a file in {str(directory)!r} "
            f"({exc.strerror or exc}); check the directory's permissions or choose another"
        ) from exc
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        try:
            encoded.to_netcdf(tmp, engine=_ENGINE, format="NETCDF4", encoding=encoding)
            with open(tmp, "rb+") as fh:
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(tmp, mode)
            os.replace(tmp, path)
        except Exception as exc:
            raise ArchiveError(
                f"writing {str(path)!r} failed ({type(exc).__name__}: {exc})"
                f"{_space_hint(directory, ds)}; the previous content of the file, if any, is "
                "unchanged"
            ) from exc
        _fsync_directory(directory)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


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


def _space_hint(directory: Path, ds: xr.Dataset) -> str:
    """'; the disk is full ...' when the directory has less free space than the data."""
    try:
        free = shutil.disk_usage(directory).free
    except OSError:
        return ""
    need = int(ds.nbytes)
    if free >= max(need, 1 << 20):
        return ""
    return (
        f"; the disk holding {str(directory)!r} is full or nearly so ({free / 2**20:.1f} MiB "
        f"free, the dataset is {need / 2**20:.1f} MiB before compression): free space or "
        "write elsewhere"
    )


def open_dataset(
    path: PathLike,
    *,
    chunks: Mapping[str, int] | str | None = None,
    max_bytes: int | None = None,
) -> xr.Dataset:
    """Open a NetCDF archive written by :func:`to_netcdf` (or any NetCDF-4 file).

    Parameters
    ----------
    path : str or os.PathLike
        Archive to read.
    chunks : mapping of str to int, "auto", {} or None, default None
        None loads everything into memory and closes the file. Otherwise the variables are
        dask arrays with these chunks (as in :func:`xarray.open_dataset`) and the file stays
        open until the dataset is closed. ``{}`` uses the chunks stored in the file.
    max_bytes : int, optional
        Largest in-memory size (bytes) an eager load (``chunks=None``) may have; checked
        from the sizes the file declares, before anything is read. Default: half the
        memory currently available (``MemAvailable``), or 8 GiB where that is unknown.

    Returns
    -------
    xarray.Dataset
        The dataset, with booleans, strings and attribute types restored. Times stay in ms
        as floats (no CF time decoding).

    Raises
    ------
    ArchiveError
        If the file does not exist or is a directory, is truncated or corrupt, is not
        NetCDF, or declares more data than ``max_bytes`` for an eager load; the message
        names the path.
    """
    path = Path(path)
    if path.is_dir():
        raise ArchiveError(
            f"cannot open {str(path)!r}: it is a directory; pass one .nc file in it "
            "(e.g. sorted(Path(folder).glob('*.nc')))"
        )
    if not path.is_file():
        raise ArchiveError(f"cannot open {str(path)!r}: no such file")
    try:
        ds = xr.open_dataset(
            path,
            engine=_ENGINE,
            chunks=chunks,
            decode_times=False,
            decode_timedelta=False,
        )
        if chunks is None:
            with ds:
                _check_size(ds, path, max_bytes)
                ds = ds.load()
        return _decode(ds)
    except ArchiveError:
        raise
    except Exception as exc:
        raise ArchiveError(
            f"cannot read {str(path)!r} as a NetCDF archive ({type(exc).__name__}: {exc}); "
            "the file may be truncated, corrupt or not NetCDF"
        ) from exc


def _available_memory() -> int:
    """Bytes of memory available now (Linux ``MemAvailable``), else 16 GiB."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 16 << 30


def _check_size(ds: xr.Dataset, path: Path, max_bytes: int | None) -> None:
    """Refuse an eager load larger than ``max_bytes`` (from declared sizes, nothing read)."""
    limit = _available_memory() // 2 if max_bytes is None else int(max_bytes)
    need = int(ds.nbytes)
    if need > limit:
        biggest = max(ds.variables.items(), key=lambda kv: kv[1].nbytes)
        raise ArchiveError(
            f"cannot load {str(path)!r} into memory: it declares {need / 2**30:.3g} GiB "
            f"(largest variable {str(biggest[0])!r} {dict(biggest[1].sizes)!r}), above the "
            f"{limit / 2**30:.3g} GiB allowed (max_bytes); open it lazily with "
            "open_dataset(path, chunks={}) or pass a larger max_bytes"
        )


# --- encoding helpers --------------------------------------------------------------------


def _encode_attrs(ds: xr.Dataset) -> xr.Dataset:
    """Shallow copy of ``ds`` whose attributes netCDF can store (types recorded)."""
    out = ds.copy(deep=False)
    out.attrs = _encode_mapping(ds.attrs, "the dataset")
    for name, var in ds.variables.items():
        out.variables[name].attrs = _encode_mapping(var.attrs, f"variable {name!r}")
    return out


def _encode_mapping(attrs: Mapping[Hashable, Any], owner: str) -> dict[Hashable, Any]:
    out: dict[Hashable, Any] = {}
    types: dict[str, str] = {}
    if _TYPES_ATTR in attrs:
        raise ArchiveError(f"attribute {_TYPES_ATTR!r} of {owner} is reserved by harpx; rename it")
    for key, value in attrs.items():
        if not isinstance(key, str):
            raise ArchiveError(f"attribute name {key!r} of {owner} is not a string")
        if isinstance(value, bool | np.bool_):
            out[key] = np.int8(value)
            types[key] = "bool"
        elif isinstance(value, list | tuple):
            items = list(value)
            _check_attr_items(items, key, owner)
            if items and all(isinstance(v, bool | np.bool_) for v in items):
                out[key] = np.asarray(items, dtype=np.int8)
                types[key] = f"{type(value).__name__}:bool"
            elif items and all(isinstance(v, str) for v in items):
                out[key] = items
                types[key] = type(value).__name__
            else:
                out[key] = np.asarray(items)
                types[key] = type(value).__name__
        elif isinstance(value, np.ndarray):
            _check_attr_items(list(value.ravel()), key, owner)
            if value.dtype == bool:
                out[key] = value.astype(np.int8)
                types[key] = "ndarray:bool"
            elif value.ndim != 1 or value.size == 1:
                out[key] = value.ravel()  # netCDF attributes are 1-D: record the shape
                types[key] = f"ndarray{value.shape}"
            else:
                out[key] = value
        elif isinstance(value, str | numbers.Number | np.number):
            out[key] = value
        else:
            raise ArchiveError(
                f"attribute {key!r} of {owner} has type {type(value).__name__!r}, which NetCDF "
                "cannot store; use a str, number, list of numbers or strings, or encode it "
                "(e.g. json.dumps)"
            )
    if types:
        out[_TYPES_ATTR] = json.dumps(types, sort_keys=True)
    return out


def _check_attr_items(items: list[Any], key: str, owner: str) -> None:
    if not items:
        raise ArchiveError(f"attribute {key!r} of {owner} is empty; NetCDF cannot store it")
    ok = all(isinstance(v, str | numbers.Number | np.number | np.bool_) for v in items)
    if not ok or (
        any(isinstance(v, str) for v in items) and not all(isinstance(v, str) for v in items)
    ):
        raise ArchiveError(
            f"attribute {key!r} of {owner} mixes types or holds non-numbers; NetCDF stores "
            "only homogeneous lists of numbers or strings"
        )


def _compression(ds: xr.Dataset) -> dict[Hashable, dict[str, Any]]:
    encoding: dict[Hashable, dict[str, Any]] = {}
    for name, var in ds.data_vars.items():
        if var.dtype.kind in "fiub" and var.size > 0:
            encoding[name] = {"zlib": True, "complevel": COMPRESSION_LEVEL}
    return encoding


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


# --- decoding helpers --------------------------------------------------------------------


def _decode(ds: xr.Dataset) -> xr.Dataset:
    ds.attrs = _decode_mapping(ds.attrs)
    for var in ds.variables.values():
        var.attrs = _decode_mapping(var.attrs)
    return _strings(ds)


def _strings(ds: xr.Dataset) -> xr.Dataset:
    """Object arrays of str (older netCDF4/xarray) → fixed-width unicode arrays."""
    replace: dict[Hashable, xr.Variable] = {}
    for name, var in ds.variables.items():
        if var.dtype != object:
            continue
        values = np.asarray(var.values)
        if values.size == 0 or all(isinstance(v, str) for v in values.ravel()):
            replace[name] = var.copy(data=values.astype(str))
    if not replace:
        return ds
    coords = {k: v for k, v in replace.items() if k in ds.coords}
    data = {k: v for k, v in replace.items() if k not in ds.coords}
    return ds.assign_coords(coords).assign(data)


def _decode_mapping(attrs: Mapping[Hashable, Any]) -> dict[Hashable, Any]:
    out = dict(attrs)
    raw = out.pop(_TYPES_ATTR, None)
    if raw is None:
        return out
    types: dict[str, str] = json.loads(str(raw))
    for key, kind in types.items():
        if key not in out:
            continue
        value = np.atleast_1d(np.asarray(out[key]))
        if kind == "bool":
            out[key] = bool(value[0])
        elif kind.startswith("ndarray("):
            shape = tuple(json.loads("[" + kind[len("ndarray(") : -1].rstrip(",") + "]"))
            out[key] = value.reshape(shape)
        elif kind == "ndarray:bool":
            out[key] = value.astype(bool)
        else:
            container, _, element = kind.partition(":")
            items = value.astype(bool).tolist() if element == "bool" else value.tolist()
            out[key] = tuple(items) if container == "tuple" else list(items)
    return out
