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

import json
import numbers
import os
import re
import shutil
import socket
import stat
import tempfile
import warnings
from collections.abc import Hashable, Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np
import xarray as xr

from harpx._typing import PathLike
from harpx.errors import ArchiveError, HarpxWarning

__all__ = ["open_dataset", "to_netcdf"]

#: zlib compression level used for every numeric data variable.
COMPRESSION_LEVEL = 4
#: Global ``Conventions`` attribute written when a dataset has none (UGRID is appended for
#: archives that carry a mesh topology).
CONVENTIONS = "CF-1.10"
UGRID_CONVENTIONS = "UGRID-1.0"
#: Name of the UGRID mesh topology variable in tracked archives.
MESH = "mesh"
_TYPES_ATTR = "harpx_attr_types"
_ADDED_ATTR = "harpx_archive_added"
# UGRID 1.0 volume shapes (flag value = index) and the harpx elements each describes by its
# leading (corner) vertices, which are in VTK order for every harpx element.
_VOLUME_SHAPES = ("tetrahedron", "wedge", "hexahedron")
_ELEMENT_SHAPES: dict[str, tuple[int, int]] = {
    "tet4": (0, 4),
    "tet10": (0, 4),
    "wedge6": (1, 6),
    "hex8": (2, 8),
    "hex20": (2, 8),
    "hex27": (2, 8),
}
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
        node or a read-only file (never replaced: :func:`check_writable_target`), or writing
        fails (a full disk is named as such); the previous content of ``path`` is then left
        intact.
    TypeError
        If ``ds`` is not an xarray.Dataset or ``path`` not a str or os.PathLike.

    Notes
    -----
    Numeric and boolean data variables are compressed with zlib at level
    ``COMPRESSION_LEVEL`` (4) and chunked one frame at a time along ``time``. The file
    also carries the CF ``Conventions`` attribute and, for tracked meshes, a UGRID 1.0 mesh
    topology (see the module docstring); :func:`open_dataset` removes both again. Only a
    process killed mid-write (e.g. SIGKILL) can leave a stray temporary file
    ``.<name>.harpx-<host>-<pid>-*.tmp`` beside the target; the target itself is never
    partial, and the next write of the same target removes such leftovers once their
    process is gone (:func:`remove_stale_temporaries`).

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
    TypeError
        If ``path`` is not a str or os.PathLike.
    ValueError
        If ``chunks`` or ``max_bytes`` is not of the kinds above (e.g. a negative size).

    Warns
    -----
    HarpxWarning
        If the archive declares a newer ``harpx_schema`` version than this harpx reads
        (e.g. ``"tracked/2"``): upgrade harpx.
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
        ds = _decode(ds)
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
            stacklevel=2,
        )
    return ds


def _check_path(path: Any) -> None:
    """TypeError naming ``path`` unless it is a str or os.PathLike."""
    if not isinstance(path, str | os.PathLike):
        raise TypeError(
            f"path={path!r} must be a file path (str or os.PathLike), not {type(path).__name__}"
        )


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
    for reserved in (_TYPES_ATTR, _ADDED_ATTR):
        if reserved in attrs:
            raise ArchiveError(f"attribute {reserved!r} of {owner} is reserved by harpx; rename it")
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
    """zlib and one-frame chunks (``time: 1``, other dims whole) for each numeric variable."""
    encoding: dict[Hashable, dict[str, Any]] = {}
    for name, var in ds.data_vars.items():
        if var.dtype.kind in "fiub" and var.size > 0:
            chunks = tuple(1 if dim == "time" else size for dim, size in var.sizes.items())
            encoding[name] = {"zlib": True, "complevel": COMPRESSION_LEVEL}
            if chunks:
                encoding[name]["chunksizes"] = chunks
    return encoding


# --- CF and UGRID for readers other than harpx ---------------------------------------------


def _add_conventions(ds: xr.Dataset) -> xr.Dataset:
    """Add the CF ``Conventions`` attribute and a UGRID mesh; record what was added."""
    added: dict[str, Any] = {"attrs": [], "variables": [], "variable_attrs": {}}
    mesh = _ugrid_mesh(ds)
    if mesh:
        ds = ds.assign(mesh)
        added["variables"] = sorted(mesh)
        for name in ds.data_vars:
            var = ds.variables[name]
            if name in mesh or name in ("points", "cells"):
                continue
            location = "node" if "node" in var.dims else "volume" if "cell" in var.dims else None
            if location is None or "mesh" in var.attrs or "location" in var.attrs:
                continue
            var.attrs = {**var.attrs, "mesh": MESH, "location": location}
            added["variable_attrs"][str(name)] = ["mesh", "location"]
    if "Conventions" not in ds.attrs:
        ds.attrs["Conventions"] = CONVENTIONS + (f" {UGRID_CONVENTIONS}" if mesh else "")
        added["attrs"].append("Conventions")
    if any(added.values()):
        ds.attrs[_ADDED_ATTR] = json.dumps(added, sort_keys=True)
    return ds


def _ugrid_mesh(ds: xr.Dataset) -> dict[str, xr.Variable]:
    """UGRID 1.0 volume-mesh variables of a tracked dataset ({} if it has no volume mesh)."""
    if ds.attrs.get("harpx_schema") != "tracked/1" or "points" not in ds or "cells" not in ds:
        return {}
    shape = _ELEMENT_SHAPES.get(str(ds["cells"].attrs.get("element")))
    points, cells = ds["points"], ds["cells"]
    if (
        shape is None
        or points.dims != ("node", "axis")
        or cells.dims != ("cell", "vertex")
        or cells.shape[0] == 0
        or cells.shape[1] < shape[1]
        or any(name in ds.variables or name in ds.dims for name in _mesh_names())
    ):
        return {}
    code, corners = shape
    xyz = np.asarray(points.values, dtype=np.float64)
    columns = [str(a) for a in ds["axis"].values] if "axis" in ds.coords else ["x", "y", "z"]
    variables: dict[str, xr.Variable] = {}
    for axis in ("x", "y", "z"):
        variables[f"mesh_node_{axis}"] = xr.Variable(
            "node",
            xyz[:, columns.index(axis)],
            {"units": "mm", "long_name": f"{axis} reference position of mesh node"},
        )
    variables["mesh_volume_nodes"] = xr.Variable(
        ("cell", "mesh_volume_corner"),
        np.asarray(cells.values[:, :corners], dtype=np.int64),
        {
            "cf_role": "volume_node_connectivity",
            "long_name": "corner nodes of each cell (bottom face, then top face)",
            "start_index": np.int64(0),
        },
    )
    variables["mesh_volume_types"] = xr.Variable(
        "cell",
        np.full(cells.shape[0], code, dtype=np.int8),
        {
            "cf_role": "volume_shape_type",
            "long_name": "shape of each cell",
            "flag_range": np.array([0, len(_VOLUME_SHAPES) - 1], dtype=np.int8),
            "flag_values": np.arange(len(_VOLUME_SHAPES), dtype=np.int8),
            "flag_meanings": " ".join(_VOLUME_SHAPES),
        },
    )
    variables[MESH] = xr.Variable(
        (),
        np.int32(0),
        {
            "cf_role": "mesh_topology",
            "long_name": "topology of the three-dimensional tracking mesh",
            "topology_dimension": np.int32(3),
            "node_coordinates": "mesh_node_x mesh_node_y mesh_node_z",
            "volume_node_connectivity": "mesh_volume_nodes",
            "volume_shape_type": "mesh_volume_types",
            "volume_dimension": "cell",
        },
    )
    return variables


def _mesh_names() -> tuple[str, ...]:
    return (
        MESH,
        "mesh_node_x",
        "mesh_node_y",
        "mesh_node_z",
        "mesh_volume_nodes",
        "mesh_volume_types",
        "mesh_volume_corner",
    )


def _drop_added(ds: xr.Dataset) -> xr.Dataset:
    """Remove what :func:`_add_conventions` put into the file."""
    raw = ds.attrs.pop(_ADDED_ATTR, None)
    if raw is None:
        return ds
    added = json.loads(str(raw))
    for key in added.get("attrs", []):
        ds.attrs.pop(key, None)
    for name, keys in added.get("variable_attrs", {}).items():
        if name in ds.variables:
            var = ds.variables[name]
            var.attrs = {k: v for k, v in var.attrs.items() if k not in keys}
    return ds.drop_vars([n for n in added.get("variables", []) if n in ds.variables])


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
    ds = _drop_added(ds)
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
