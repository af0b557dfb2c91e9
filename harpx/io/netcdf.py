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

Archives are also readable by tools that know the CF and UGRID conventions but not harpx.
:func:`to_netcdf` adds, in the file only:

- the global ``Conventions`` attribute (:data:`CONVENTIONS`, plus ``UGRID-1.0`` for meshes),
  unless the dataset has its own;
- for a ``tracked/1`` dataset with a volume mesh (``hex8``, ``hex20``, ``hex27``, ``tet4``,
  ``tet10``, ``wedge6``), a UGRID 1.0 three-dimensional mesh: the ``mesh`` topology variable
  (``cf_role = "mesh_topology"``, ``topology_dimension = 3``), node coordinates
  ``mesh_node_x``, ``mesh_node_y``, ``mesh_node_z`` (node; mm, copied from ``points``), the
  corner connectivity ``mesh_volume_nodes`` (cell, mesh_volume_corner; zero-based, the VTK
  corner order of ``cells``: bottom face then top face) and the shape of each cell
  ``mesh_volume_types`` (``flag_meanings = "tetrahedron wedge hexahedron"``); every data
  variable on ``node`` or ``cell`` gets ``mesh = "mesh"`` and ``location = "node"`` or
  ``"volume"``. Higher-order cells (``hex20``, ``tet10``) are described by their corners:
  the full connectivity stays in ``cells``.

:func:`open_dataset` drops exactly what was added (the global ``harpx_archive_added``
attribute lists it), so round trips stay exact.

Every numeric data variable is compressed (zlib, :data:`COMPRESSION_LEVEL`) and stored in
chunks of one frame (``time: 1``, every other dimension whole), so opening an archive with
``chunks={"time": 1}`` reads one frame per task and matches the stored chunks.
"""

from __future__ import annotations

import numbers
import os
import shutil
import tempfile
import warnings
from collections.abc import Hashable, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Literal

import xarray as xr

from harpx._typing import PathLike
from harpx.errors import ArchiveError, HarpxWarning, user_stacklevel
from harpx.io.files import (
    _available_memory,
    _check_path,
    _fsync_directory,
    _target_mode,
    check_writable_target,
    remove_stale_temporaries,
    temporary_prefix,
)
from harpx.io.netcdf_codec import (
    COMPRESSION_LEVEL,
    CONVENTIONS,
    MESH,
    UGRID_CONVENTIONS,
    _add_conventions,
    _compression,
    _decode,
    _encode_attrs,
)

__all__ = [
    "COMPRESSION_LEVEL",
    "CONVENTIONS",
    "MESH",
    "UGRID_CONVENTIONS",
    "check_writable_target",
    "open_dataset",
    "remove_stale_temporaries",
    "temporary_prefix",
    "to_netcdf",
]

_ENGINE: Literal["netcdf4"] = "netcdf4"


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
        node or a read-only file (never replaced:
        :func:`~harpx.io.files.check_writable_target`), or writing
        fails (a full disk is named as such); the previous content of ``path`` is then left
        intact.
    TypeError
        If ``ds`` is not an xarray.Dataset or ``path`` not a str or os.PathLike.

    Notes
    -----
    Numeric and boolean data variables are compressed with zlib at level
    ``COMPRESSION_LEVEL`` (4) and chunked one frame at a time along ``time``. The file
    also carries the CF ``Conventions`` attribute and, for tracked meshes, a UGRID 1.0 mesh
    topology (see the module docstring); :func:`open_dataset` removes both again. A failed
    write of dask-backed variables returns only once every write task has stopped (on
    dask's threaded scheduler, the default), so it leaves nothing behind. Only a process
    killed mid-write (e.g. SIGKILL), or a failed lazy write computed by a dask.distributed
    client (whose tasks still running are not waited for), can leave a stray temporary
    file ``.<name>.harpx-<host>-<pid>-*.tmp`` beside the target; the target itself is
    never partial, and the next write of the same target removes such leftovers once
    their process is gone (:func:`~harpx.io.files.remove_stale_temporaries`).

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
    if not isinstance(ds, xr.Dataset):
        hint = "; convert with da.to_dataset(name=...)" if isinstance(ds, xr.DataArray) else ""
        raise TypeError(f"to_netcdf needs an xarray.Dataset, got {type(ds).__name__!r}{hint}")
    _check_path(path)
    if "harpx_schema" in ds.attrs:
        from harpx.schema import validate

        validate(ds)
    path = Path(path)
    encoded = _add_conventions(_encode_attrs(ds))
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
            _write(encoded, tmp, encoding)
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


def _write(ds: xr.Dataset, tmp: Path, encoding: dict[Hashable, dict[str, Any]]) -> None:
    """Write ``ds`` to ``tmp``; dask-backed variables are computed with every write task
    finished when this returns, also when one of them fails.

    dask's threaded scheduler raises the first failing task's error at once while the
    other tasks still run on its shared thread pool; xarray then closes the file and a
    task still writing reopens it (append mode), re-creating the temporary file after it
    was deleted. The write graph therefore runs on a thread pool of its own (as many
    threads as the threaded scheduler would use), which is shut down, waiting for running
    tasks and cancelling queued ones, before this returns. Other schedulers (synchronous,
    processes, a distributed client) are used as configured.
    """
    lazy = any(var.chunks is not None for var in ds.variables.values())
    if not lazy:
        ds.to_netcdf(tmp, engine=_ENGINE, format="NETCDF4", encoding=encoding)
        return
    import dask
    import dask.threaded
    from dask.system import CPU_COUNT

    delayed = ds.to_netcdf(tmp, engine=_ENGINE, format="NETCDF4", encoding=encoding, compute=False)
    if dask.base.get_scheduler(collections=[delayed]) is not dask.threaded.get:
        dask.compute(delayed)
        return
    executor = getattr(dask.threaded, "ContextAwareThreadPoolExecutor", ThreadPoolExecutor)
    pool = executor(dask.config.get("num_workers", None) or CPU_COUNT)
    try:
        dask.compute(delayed, scheduler="threads", pool=pool)
    finally:
        # no task writes any more when this returns: running ones finished, queued ones
        # cancelled (after a failure the file stays open, unchanged, until the failed
        # graph is garbage-collected; the caller deletes it)
        pool.shutdown(wait=True, cancel_futures=True)


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
        memory currently available (Linux ``MemAvailable``); where that is unknown, 16 GiB
        are assumed available, so the default is 8 GiB.

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
    TypeError
        If ``path`` is not a str or os.PathLike.
    ValueError
        If ``chunks`` or ``max_bytes`` is not of the kinds above (e.g. a negative size).

    Warns
    -----
    HarpxWarning
        If the archive declares a newer ``harpx_schema`` version than this harpx reads
        (e.g. ``"tracked/2"``): upgrade harpx.

    Examples
    --------
    A dataset with a boolean variable and list and bool attributes, written with
    :func:`to_netcdf` into a temporary directory and read back with their types:

    >>> import pathlib, tempfile
    >>> from harpx.io.netcdf import open_dataset, to_netcdf
    >>> ds = xr.Dataset({"mask": ("x", [True, False, True])},
    ...                 attrs={"upsample_factors": [1, 2, 2], "flipped": False})
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = open_dataset(to_netcdf(ds, pathlib.Path(tmp) / "a.nc"))
    >>> str(back["mask"].dtype), back.attrs["upsample_factors"], back.attrs["flipped"]
    ('bool', [1, 2, 2], False)
    >>> back.identical(ds)
    True
    """
    _check_path(path)
    _check_chunks(chunks)
    if max_bytes is not None and (
        isinstance(max_bytes, bool)
        or not isinstance(max_bytes, numbers.Integral)
        or int(max_bytes) < 1
    ):
        raise ValueError(f"max_bytes={max_bytes!r} must be a positive whole number of bytes")
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
        opened = ds
        ds = _decode(ds)
        if ds is not opened:
            # decoding dropped or assigned variables, which returns a dataset without the
            # file's closer: give it back, so that close() (or a with block) releases a lazy
            # file
            ds.set_close(opened.close)
    except ArchiveError:
        raise
    except Exception as exc:
        raise ArchiveError(
            f"cannot read {str(path)!r} as a NetCDF archive ({type(exc).__name__}: {exc}); "
            "the file may be truncated, corrupt or not NetCDF"
        ) from exc
    from harpx.schema import newer_schema

    newer = newer_schema(ds.attrs.get("harpx_schema"))
    if newer:
        warnings.warn(
            f"archive {str(path)!r}: {newer}. Until then its variables may be misread, and "
            "validate() and the trackers refuse it",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return ds


def _check_chunks(chunks: Any) -> None:
    """ValueError naming a ``chunks`` argument xarray would misreport as a corrupt file."""
    if chunks is None or isinstance(chunks, str) and chunks == "auto":
        return
    if not isinstance(chunks, Mapping):
        raise ValueError(
            f"chunks={chunks!r} must be None, 'auto' or a mapping of dimension name to chunk "
            "size (e.g. {'time': 1}; {} keeps the file's own chunks)"
        )
    for dim, size in chunks.items():
        ok = (
            size is None
            or size == "auto"
            or (
                isinstance(size, numbers.Integral)
                and not isinstance(size, bool)
                and (int(size) >= 1 or int(size) == -1)
            )
        )
        if not ok:
            raise ValueError(
                f"chunks[{dim!r}] is {size!r}; expected a positive chunk size, -1 (the whole "
                "dimension), 'auto' or None"
            )


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
