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
        not exist, or writing fails; the previous content of ``path`` is then left intact.

    Notes
    -----
    Numeric and boolean data variables are compressed with zlib at level
    ``COMPRESSION_LEVEL`` (4). Only a process killed mid-write (e.g. SIGKILL) can leave a
    stray temporary file ``.<name>.*.tmp`` beside the target; the target itself is never
    partial.

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
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise ArchiveError(
            f"cannot write {str(path)!r}: directory {str(directory)!r} does not exist; "
            "create it first"
        )
    encoding = _compression(encoded)
    mode = _target_mode(path)
    fd, tmp_name = tempfile.mkstemp(dir=directory, prefix=f".{path.name}.", suffix=".tmp")
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
                f"writing {str(path)!r} failed ({type(exc).__name__}: {exc}); the previous "
                "content of the file, if any, is unchanged"
            ) from exc
        _fsync_directory(directory)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def open_dataset(path: PathLike, *, chunks: Mapping[str, int] | str | None = None) -> xr.Dataset:
    """Open a NetCDF archive written by :func:`to_netcdf` (or any NetCDF-4 file).

    Parameters
    ----------
    path : str or os.PathLike
        Archive to read.
    chunks : mapping of str to int, "auto", {} or None, default None
        None loads everything into memory and closes the file. Otherwise the variables are
        dask arrays with these chunks (as in :func:`xarray.open_dataset`) and the file stays
        open until the dataset is closed. ``{}`` uses the chunks stored in the file.

    Returns
    -------
    xarray.Dataset
        The dataset, with booleans, strings and attribute types restored. Times stay in ms
        as floats (no CF time decoding).

    Raises
    ------
    ArchiveError
        If the file does not exist, is truncated or corrupt, or is not NetCDF; the message
        names the path.
    """
    path = Path(path)
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
                ds = ds.load()
        return _decode(ds)
    except Exception as exc:
        raise ArchiveError(
            f"cannot read {str(path)!r} as a NetCDF archive ({type(exc).__name__}: {exc}); "
            "the file may be truncated, corrupt or not NetCDF"
        ) from exc


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
