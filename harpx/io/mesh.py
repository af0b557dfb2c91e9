"""Export tracked results as ParaView time series and read their meshes back.

:func:`to_meshio` writes a ``tracked/1`` dataset (:mod:`harpx.schema`) as a time series
that ParaView opens directly:

``series="xdmf"``
    One XDMF 3 file (:class:`meshio.xdmf.TimeSeriesWriter`): the reference mesh once, then one
    grid per frame with its time (ms). Heavy data go to an HDF5 file beside it
    (``<stem>.h5``) when :mod:`h5py` is installed, else inline in the XML.
``series="vtu"``
    One binary VTU file per frame (``<stem>_0000.vtu``, ``<stem>_0001.vtu``, ...) and a
    ParaView collection file ``<stem>.pvd`` that lists them with their times (ms).

Every frame carries the reference node positions (mm) as geometry, so ParaView's *Warp By
Vector* filter on ``displacement`` shows the deformed body, and:

point data
    ``displacement`` (node, 3) in mm.
cell data
    ``green_strain`` as a 9-component tensor (row-major ``E_xx, E_xy, E_xz, E_yx, ...``,
    dimensionless), ``fiber_stretch``, ``epsilon_cell`` (rad), ``region`` (integer label;
    the names are stored as field data ``region:<name>`` in VTU files and as an XDMF
    ``Information`` element) and ``fiber`` (unit vectors), each where the dataset has it.

Cells keep the VTK/meshio node order of the dataset: ``hex8`` becomes ``hexahedron``,
``hex20`` ``hexahedron20`` (and ``tet4``, ``tet10``, ``wedge6``, ``hex27``, ``tri3``,
``quad4`` their meshio names).

:func:`read_body_mesh` reads the reference mesh back from any of these files (or any mesh
file meshio reads) as a :class:`~harpx.mechanics.mesh.MeshSpec` with its regions and fibres,
so ``Body(read_body_mesh(path), material, element=...)`` rebuilds the tracked body with the
same nodes and cells. It rejects inverted or degenerate hexahedra, naming them. Both
readers take named regions and boundaries from cell sets, named gmsh physical groups,
``region`` labels and scikit-fem's ``skfem:s:``/``skfem:b:`` cell data, and warn about
names they cannot map. ``hexahedron20`` cells are reduced to their corners (straight
edges); a warning says so when the file's edges were curved.

:func:`read_body` reads a model from a mesh file (hexahedra or tetrahedra, e.g. a mesh made
elsewhere, or one :meth:`~harpx.mechanics.body.Body.to_meshio` wrote) straight into a
:class:`~harpx.mechanics.body.Body`.

Writes are atomic per file: everything is written into a temporary directory beside the
target, flushed to disk, then moved into place with :func:`os.replace`, data files first and
the index file (``.xdmf`` / ``.pvd``) last. An error leaves the previous files untouched.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal
from xml.sax.saxutils import quoteattr

import meshio
import meshio.xdmf
import numpy as np
import xarray as xr

from harpx._typing import FloatArray, IntArray, PathLike
from harpx.errors import ArchiveError, SchemaError
from harpx.io.netcdf import (
    _check_path,
    _fsync_directory,
    check_writable_target,
    remove_stale_temporaries,
    temporary_prefix,
)
from harpx.mechanics._mesh_file_sets import REGION_FIELD, read_named_sets
from harpx.mechanics.body import Body
from harpx.mechanics.cells import volume_blocks, vtk_hex_corner_jacobians, warn_dropped_curvature
from harpx.mechanics.mesh import MeshSpec, hex_mesh
from harpx.mechanics.meshspec import labelled_spec
from harpx.schema import validate

__all__ = ["MESHIO_CELL_TYPES", "read_body", "read_body_mesh", "read_meshio", "to_meshio"]

#: harpx element name (``cells.attrs["element"]``) → meshio cell type (same node order).
MESHIO_CELL_TYPES: dict[str, str] = {
    "hex8": "hexahedron",
    "hex20": "hexahedron20",
    "hex27": "hexahedron27",
    "tet4": "tetra",
    "tet10": "tetra10",
    "wedge6": "wedge",
    "tri3": "triangle",
    "quad4": "quad",
}

#: Suffixes of the index file of each series kind; the first is the default.
_SUFFIXES: dict[str, tuple[str, ...]] = {"xdmf": (".xdmf", ".xmf"), "vtu": (".pvd", ".vtu")}
_XDMF_INFO = "harpx_region_names"


# --- export ------------------------------------------------------------------------------


def to_meshio(
    tracked: xr.Dataset, path: PathLike, *, series: Literal["vtu", "xdmf"] = "xdmf"
) -> list[Path]:
    """Write a tracked result as a ParaView time series (XDMF, or VTU files and a PVD).

    Parameters
    ----------
    tracked : xarray.Dataset
        ``tracked/1`` dataset with ``points`` (node, axis) in mm, ``cells`` (cell, vertex)
        whose ``element`` attribute names a cell type (e.g. ``"hex8"``, ``"hex20"``), and
        ``displacement`` (time, node, axis) in mm; optional ``green_strain``,
        ``fiber_stretch``, ``epsilon_cell``, ``region`` and ``fiber`` are exported too.
        Dask-backed variables are computed frame by frame.
    path : str or os.PathLike
        Target. For ``series="xdmf"`` the ``.xdmf`` file (suffix ``.xdmf``/``.xmf``, added
        if missing). For ``series="vtu"`` the ``.pvd`` collection file; the frames are
        written beside it as ``<stem>_0000.vtu``, ... (a ``.vtu`` suffix is replaced by
        ``.pvd``). The directory must exist.
    series : {"xdmf", "vtu"}, default "xdmf"
        One XDMF time series, or one VTU file per frame plus a PVD collection.

    Returns
    -------
    list of pathlib.Path
        The files written, the one to open in ParaView first (``.xdmf`` then ``.h5`` if
        any; or ``.pvd`` then the frames in time order).

    Raises
    ------
    SchemaError
        If ``tracked`` has no ``cells``, holds a point cloud (``element="points"``), has an
        element meshio cannot write, or breaks the ``tracked/1`` conventions. Nothing is
        written.
    ValueError
        If ``series`` is unknown or the suffix of ``path`` belongs to the other series.
    FileNotFoundError
        If the directory of ``path`` does not exist.
    TypeError
        If ``tracked`` is not an xarray.Dataset or ``path`` not a str or os.PathLike.

    See Also
    --------
    read_body_mesh : the reference mesh of an export, for :class:`~harpx.mechanics.body.Body`.

    Notes
    -----
    Each file is replaced atomically; when overwriting an earlier export, frames numbered
    beyond the new frame count are left on disk (the new PVD does not list them).

    Examples
    --------
    A two-frame result on two hexahedra, written as VTU frames and read back:

    >>> import tempfile, pathlib
    >>> from harpx.mechanics.body import Body
    >>> from harpx.mechanics.materials import NeoHookean
    >>> from harpx.mechanics.mesh import box
    >>> from harpx.schema import fill_standard_attrs
    >>> body = Body(box((2.0, 1.0, 1.0), (2, 1, 1)), NeoHookean(c1=1.0, kappa=100.0))
    >>> u = np.zeros((2, len(body.dof_points), 3))
    >>> tracked = fill_standard_attrs(xr.Dataset(
    ...     {"points": (("node", "axis"), body.dof_points),
    ...      "cells": (("cell", "vertex"), body.cells, {"element": "hex8"}),
    ...      "displacement": (("time", "node", "axis"), u)},
    ...     coords={"time": [0.0, 20.0], "axis": ["x", "y", "z"]},
    ...     attrs={"harpx_schema": "tracked/1"}))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     files = to_meshio(tracked, pathlib.Path(tmp) / "result", series="vtu")
    ...     back = Body(read_body_mesh(files[0]), body.material)
    >>> [f.name for f in files]
    ['result.pvd', 'result_0000.vtu', 'result_0001.vtu']
    >>> bool((back.cells == body.cells).all() and (back.dof_points == body.dof_points).all())
    True
    """
    if not isinstance(tracked, xr.Dataset):
        raise TypeError(
            f"to_meshio needs a tracked/1 xarray.Dataset, got {type(tracked).__name__!r}"
        )
    _check_path(path)
    if series not in _SUFFIXES:
        raise ValueError(f"series={series!r} is not supported; use 'xdmf' or 'vtu'")
    target = _target_path(Path(path), series)
    cell_type = _check_exportable(tracked)
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise FileNotFoundError(
            f"cannot write {str(target)!r}: directory {str(directory)!r} does not exist; "
            "create it first"
        )
    points = np.asarray(tracked["points"].values, dtype=np.float64)
    cells = np.asarray(tracked["cells"].values, dtype=np.int64)
    static, region_names = _static_cell_data(tracked)
    times = np.asarray(tracked["time"].values, dtype=np.float64)
    export = _Export(tracked, points, (cell_type, cells), static, region_names, times)
    with _staging(directory, target.name) as tmp:
        if series == "xdmf":
            names = _write_xdmf(tmp / target.name, export)
        else:
            names = _write_vtu(tmp, target, export)
        for name in names:
            _fsync(tmp / name)
        for name in names:  # never replace a link, device node or read-only file
            check_writable_target(directory / name)
        index, data = names[0], names[1:]
        for name in [*data, index]:  # the index file last: it only ever lists complete files
            os.replace(tmp / name, directory / name)
        _fsync_directory(directory)
    return [directory / name for name in names]


def _target_path(path: Path, series: str) -> Path:
    suffixes = _SUFFIXES[series]
    other = "vtu" if series == "xdmf" else "xdmf"
    suffix = path.suffix.lower()
    if suffix in _SUFFIXES[other]:
        raise ValueError(
            f"path {str(path)!r} ends in {path.suffix!r}, which belongs to series={other!r} "
            f"but series={series!r} was asked; use a {suffixes[0]!r} path or series={other!r}"
        )
    if series == "vtu" and suffix == ".vtu":
        return path.with_suffix(".pvd")
    if suffix in suffixes:
        return path
    return path.with_name(path.name + suffixes[0])


def _check_exportable(tracked: xr.Dataset) -> str:
    """The meshio cell type of ``tracked``; SchemaError before any file is opened."""
    if "cells" not in tracked.variables:
        raise SchemaError(
            "the dataset has no 'cells' (cell, vertex) connectivity, so there is no mesh to "
            "export; to_meshio needs a tracked/1 dataset from harpx.tracking.track.track"
        )
    element = tracked["cells"].attrs.get("element")
    if element == "points":
        raise SchemaError(
            "'cells' has element 'points': the dataset is a point cloud without cells (e.g. "
            "from track_harp); to_meshio exports finite-element meshes (track with "
            "harpx.tracking.track.track)"
        )
    if element not in MESHIO_CELL_TYPES:
        raise SchemaError(
            f"'cells' has element {element!r}; to_meshio writes {sorted(MESHIO_CELL_TYPES)!r} "
            "(set tracked['cells'].attrs['element'])"
        )
    validate(tracked, "tracked")
    return MESHIO_CELL_TYPES[str(element)]


def _static_cell_data(tracked: xr.Dataset) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    static: dict[str, np.ndarray] = {}
    names: dict[str, int] = {}
    if "region" in tracked.variables:
        static["region"] = np.asarray(tracked["region"].values).astype(np.int64)
        meanings = str(tracked["region"].attrs.get("flag_meanings", "")).split()
        names = {name: code for code, name in enumerate(meanings)}
    if "fiber" in tracked.variables:
        static["fiber"] = np.asarray(tracked["fiber"].values, dtype=np.float64)
    return static, names


def _frame_data(tracked: xr.Dataset, n: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Point and cell data of frame ``n`` (values loaded for this frame only)."""
    frame = tracked.isel(time=n)
    point = {"displacement": np.asarray(frame["displacement"].values, dtype=np.float64)}
    cell: dict[str, np.ndarray] = {}
    if "green_strain" in frame.variables:
        e = np.asarray(frame["green_strain"].transpose("cell", "i", "j").values, np.float64)
        cell["green_strain"] = e.reshape(e.shape[0], 9)
    for name in ("fiber_stretch", "epsilon_cell"):
        if name in frame.variables:
            cell[name] = np.asarray(frame[name].values, dtype=np.float64)
    return point, cell


@dataclass(frozen=True)
class _Export:
    """What either series writer exports: the frames of ``tracked`` on one mesh."""

    tracked: xr.Dataset
    points: FloatArray
    block: tuple[str, IntArray]
    static: Mapping[str, np.ndarray]
    region_names: Mapping[str, int]
    times: FloatArray

    def frames(self) -> Iterator[tuple[int, dict[str, np.ndarray], dict[str, list[np.ndarray]]]]:
        """Frame index, point data and meshio cell data (with the static fields), per frame."""
        for n in range(self.times.size):  # loop over frames
            point, cell = _frame_data(self.tracked, n)
            yield n, point, {name: [value] for name, value in {**cell, **self.static}.items()}


def _write_vtu(tmp: Path, target: Path, export: _Export) -> list[str]:
    field = {
        f"{REGION_FIELD}{k}": np.array([v], dtype=np.int64) for k, v in export.region_names.items()
    }
    frames = []
    for n, point, cell_data in export.frames():
        mesh = meshio.Mesh(export.points, [export.block], point_data=point, cell_data=cell_data)
        name = f"{target.stem}_{n:04d}.vtu"
        meshio.write(tmp / name, mesh, file_format="vtu", binary=True)
        _add_field_data(tmp / name, field)
        frames.append(name)
    _write_pvd(tmp / target.name, frames, export.times)
    return [target.name, *frames]


def _add_field_data(path: Path, field: Mapping[str, np.ndarray]) -> None:
    """Insert integer ``FieldData`` into a VTU file (meshio 5 does not write field data)."""
    if not field:
        return
    arrays = "".join(
        f'<DataArray type="Int64" Name={quoteattr(name)} NumberOfTuples="{value.size}" '
        f'format="ascii">{" ".join(str(int(v)) for v in value.ravel())}</DataArray>\n'
        for name, value in field.items()
    )
    text = path.read_bytes()
    anchor = b"<UnstructuredGrid>"
    if text.count(anchor) != 1:  # pragma: no cover - guards meshio's output layout
        raise RuntimeError(f"unexpected VTU layout in {str(path)!r}; cannot add field data")
    block = f"<FieldData>\n{arrays}</FieldData>\n".encode()
    path.write_bytes(text.replace(anchor, anchor + b"\n" + block))


def _write_pvd(path: Path, frames: list[str], times: FloatArray) -> None:
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    for name, t in zip(frames, times, strict=True):
        ET.SubElement(collection, "DataSet", timestep=repr(float(t)), group="", part="0", file=name)
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


class _TimeSeriesWriter(meshio.xdmf.TimeSeriesWriter):
    """meshio's writer with the HDF5 file beside the XDMF file (meshio opens it in the cwd)."""

    def __enter__(self) -> _TimeSeriesWriter:
        if self.data_format == "HDF":
            import h5py

            self.h5_filename = self.filename.with_suffix(".h5")
            self.h5_file = h5py.File(self.h5_filename, "w")
        return self


def _xdmf_format() -> str:
    try:
        import h5py  # noqa: F401
    except ImportError:
        return "XML"
    return "HDF"


def _write_xdmf(path: Path, export: _Export) -> list[str]:
    data_format = _xdmf_format()
    with _TimeSeriesWriter(path, data_format=data_format) as writer:
        writer.write_points_cells(export.points, [export.block])
        if export.region_names:
            value = json.dumps(dict(export.region_names))
            ET.SubElement(writer.domain, "Information", Name=_XDMF_INFO, Value=value)
        for n, point, cell_data in export.frames():
            writer.write_data(float(export.times[n]), point_data=point, cell_data=cell_data)
    names = [path.name]
    if data_format == "HDF":
        names.append(path.with_suffix(".h5").name)
    return names


@contextmanager
def _staging(directory: Path, name: str) -> Iterator[Path]:
    remove_stale_temporaries(directory, name)
    tmp = Path(tempfile.mkdtemp(dir=directory, prefix=temporary_prefix(name), suffix=".tmp"))
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _fsync(path: Path) -> None:
    with open(path, "rb+") as fh:
        os.fsync(fh.fileno())


# --- import ------------------------------------------------------------------------------


def read_body_mesh(path: PathLike) -> MeshSpec:
    """Read the reference hexahedral mesh of an export (or any meshio file) for a Body.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.pvd`` collection or ``.xdmf`` time series written by :func:`to_meshio` (the
        mesh of its first frame is read), one of its ``.vtu`` frames, or any file meshio
        reads with ``hexahedron`` or ``hexahedron20`` cells (mm; several blocks of one
        of these kinds are merged in block order).

    Returns
    -------
    MeshSpec
        The corner mesh (``hexahedron20`` files are reduced to their corners, with straight
        edges; ``Body`` with ``element="hex20"`` rebuilds the edge nodes at the edges'
        midpoints), its named regions and boundaries (also carried by the skfem mesh) and
        the fibres from cell data ``fiber``. Regions come from cell data ``region`` (named
        after the stored region names, else ``"region<label>"``), cell sets, named gmsh
        physical groups and ``skfem:s:<name>`` cell data; boundaries from cell sets and
        named gmsh physical groups on face blocks and ``skfem:b:<name>`` cell data (as
        :meth:`Body.to_meshio <harpx.mechanics.body.Body.to_meshio>` writes them).
        ``Body(spec, material, element=...)`` then has the nodes and cells of the exported
        dataset (``body.dof_points == tracked.points``, ``body.cells == tracked.cells``).

    Raises
    ------
    FileNotFoundError
        If the file (or a frame a PVD lists) does not exist.
    ArchiveError
        If the file cannot be parsed (truncated, corrupt, unknown format); names the path.
    SchemaError
        If the file has no hexahedra, has other volume cells besides them (e.g. a
        tetrahedron; blocks of hexahedra are merged), or some hexahedra are inverted or
        degenerate (a non-positive Jacobian at a corner); the message lists their ids.
        Also if a cell set names cells or nodes the file does not have.

    Warns
    -----
    HarpxWarning
        If named sets cannot be mapped (a set on line or vertex cells, an unnamed gmsh tag,
        a face that is no face of the hexahedra, integer cell data without names; each is
        named), or if ``hexahedron20`` edge nodes lie off their edges' midpoints by more
        than :data:`~harpx.mechanics.cells.CURVED_EDGE_TOLERANCE` of the edge length (the
        curved geometry is lost when reducing to the corners).

    See Also
    --------
    to_meshio : writes the files this reads; its example rebuilds a Body.
    """
    _check_path(path)
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"cannot read mesh {str(path)!r}: no such file")
    suffix = path.suffix.lower()
    names: dict[str, int] | None = None  # the region label names: field data in the file
    if suffix == ".pvd":
        path = _first_pvd_frame(path)
    if suffix in _SUFFIXES["xdmf"] and _is_time_series(path):
        mesh, names = _read_xdmf_series(path)
    else:
        mesh = _read(path)
    return _mesh_spec(mesh, names, path)


def read_body(path: PathLike, material: Any, **kwargs: Any) -> Body:
    """Read a finite-element body from a mesh file.

    Parameters
    ----------
    path : str or os.PathLike
        A file meshio reads (format from its suffix), in mm, with ``hexahedron``,
        ``hexahedron20`` (reduced to its corners: straight edges, element ``hex8`` unless
        ``element="hex20"`` is given), ``tetra`` or ``tetra10`` (curved edges kept) cells;
        cell data ``fiber`` (one vector per cell) becomes the fibres. Named regions and
        boundaries are kept: those :meth:`~harpx.mechanics.body.Body.to_meshio` writes
        (``skfem:s:``/``skfem:b:`` cell data), cell sets, named gmsh physical groups and
        the ``region`` labels of a tracked export (as :func:`read_body_mesh` reads them).
    material : object
        The material, e.g. :class:`~harpx.mechanics.materials.NeoHookean`.
    **kwargs
        Further :class:`~harpx.mechanics.body.Body` parameters (``element``, ``fibers``,
        ``regions``, ...).

    Returns
    -------
    Body
        As :meth:`Body.from_meshio <harpx.mechanics.body.Body.from_meshio>` builds it from
        the file's mesh.

    Raises
    ------
    FileNotFoundError
        If ``path`` is not an existing file.
    ArchiveError
        If meshio cannot parse the file; names the path.
    ValueError
        If the file has no hexahedra or tetrahedra (names the path and its cell blocks),
        or volume cells of several kinds (counts each; blocks of one kind are merged), or
        inverted or degenerate cells (names them, with a hint at the node order, e.g.
        ``tetra10`` edge nodes in gmsh's raw order).

    Warns
    -----
    HarpxWarning
        If named sets in the file cannot be mapped to regions or boundaries (each is
        named), or if ``hexahedron20`` edge nodes lie off their edges' midpoints (curved
        geometry that reducing to the corners loses).

    See Also
    --------
    read_body_mesh : the reference mesh of a tracked export, with its named regions.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from harpx.mechanics.materials import NeoHookean
    >>> from harpx.mechanics.mesh import box
    >>> body = Body(box((1.0, 1.0, 1.0), (2, 2, 2)), NeoHookean(c1=1.0, kappa=120.0))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pathlib.Path(tmp) / "box.vtu"
    ...     meshio.write(path, body.to_meshio())
    ...     back = read_body(path, body.material)
    >>> back.ncell, back.ndof == body.ndof
    (8, True)
    """
    mesh = read_meshio(path)
    return Body.from_meshio(mesh, material, source=f"mesh file {os.fspath(path)!r}", **kwargs)


def read_meshio(path: PathLike) -> meshio.Mesh:
    """``meshio.read`` with clear errors: a missing file, or any parse failure.

    Parameters
    ----------
    path : str or os.PathLike
        A mesh file meshio reads (format from its suffix).

    Returns
    -------
    meshio.Mesh
        The mesh as meshio reads it (points in the file's units).

    Raises
    ------
    FileNotFoundError
        If ``path`` is not an existing file (a directory is named as such).
    ArchiveError
        If meshio cannot parse the file (meshio's own ``ReadError`` and the ``sys.exit``
        it calls for unreadable files are turned into this); names the path.
    """
    _check_path(path)
    path = Path(path)
    if path.is_dir():
        raise FileNotFoundError(f"cannot read mesh {str(path)!r}: it is a directory, not a file")
    if not path.is_file():
        raise FileNotFoundError(f"cannot read mesh {str(path)!r}: no such file")
    return _read(path)


def _read(path: Path) -> meshio.Mesh:
    """``meshio.read`` with its failures (including its ``sys.exit``) as ArchiveError."""
    try:
        sink = io.StringIO()  # meshio prints before it exits
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            return meshio.read(path)
    except SystemExit:  # meshio 5 exits the interpreter when no reader can parse the file
        reason = "meshio cannot parse it"
    except Exception as exc:
        reason = f"{type(exc).__name__}: {exc}"
    raise ArchiveError(
        f"cannot read mesh {str(path)!r} ({reason}); the file may be truncated, corrupt or "
        "not a mesh format meshio knows from its suffix"
    )


def _first_pvd_frame(path: Path) -> Path:
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ArchiveError(f"cannot read {str(path)!r} as a PVD collection ({exc})") from exc
    sets = root.findall("./Collection/DataSet")
    if not sets:
        raise SchemaError(f"PVD collection {str(path)!r} lists no DataSet files")
    first = min(sets, key=lambda e: float(e.get("timestep", "0")))
    frame = path.parent / str(first.get("file"))
    if not frame.is_file():
        raise FileNotFoundError(
            f"PVD collection {str(path)!r} lists {str(frame)!r}, which does not exist"
        )
    return frame


def _is_time_series(path: Path) -> bool:
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError:
        return False
    return any(g.get("CollectionType") == "Temporal" for g in root.iter("Grid"))


def _read_xdmf_series(path: Path) -> tuple[meshio.Mesh, dict[str, int]]:
    try:
        with meshio.xdmf.TimeSeriesReader(path) as reader:
            points, cells = reader.read_points_cells()
            cell_data: dict[str, Any] = {}
            if reader.num_steps:
                _, _, cell_data = reader.read_data(0)
    except Exception as exc:
        raise ArchiveError(
            f"cannot read the XDMF time series {str(path)!r} ({type(exc).__name__}: {exc}); "
            "it or its .h5 file may be truncated or corrupt"
        ) from exc
    names: dict[str, int] = {}
    for info in ET.parse(path).getroot().iter("Information"):
        if info.get("Name") == _XDMF_INFO:
            names = {str(k): int(v) for k, v in json.loads(info.get("Value", "{}")).items()}
    static = {k: v for k, v in cell_data.items() if k in ("region", "fiber")}
    return meshio.Mesh(points, cells, cell_data=static), names


def _mesh_spec(mesh: meshio.Mesh, names: Mapping[str, int] | None, path: Path) -> MeshSpec:
    source = f"mesh file {str(path)!r}"
    try:  # blocks of hexahedra merged; other volume cells refused, never dropped
        kind, hexes, data = volume_blocks(mesh, source, ("hexahedron", "hexahedron20"), "hexahedra")
    except ValueError as exc:
        raise SchemaError(str(exc)) from None
    used, inverse = np.unique(hexes[:, :8], return_inverse=True)
    points = np.asarray(mesh.points, dtype=np.float64)[used]
    cells = inverse.reshape(-1, 8)
    if points.ndim != 2 or points.shape[1] != 3:
        raise SchemaError(f"{source} has points of shape {points.shape}; expected (n, 3) in mm")
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        raise SchemaError(
            f"{source} has {bad.size} nodes with a NaN or infinite coordinate "
            f"(nodes {used[bad[:10]].tolist()} of the file); fix or remove them"
        )
    _check_hexahedra(points, cells, path)
    if kind == "hexahedron20":
        warn_dropped_curvature(mesh.points, hexes, source)
    skmesh = hex_mesh(points, cells)
    vertex_of = np.full(len(mesh.points), -1, dtype=np.int64)
    vertex_of[used] = np.arange(used.size)
    try:
        regions, boundaries = read_named_sets(
            mesh, kind, vertex_of, skmesh.facets.T, source, region_names=names
        )
    except ValueError as exc:
        raise SchemaError(str(exc)) from None
    fibers = None
    if "fiber" in data:
        fibers = np.asarray(data["fiber"], dtype=np.float64)
    return labelled_spec(skmesh, regions, boundaries, fibers)


def _check_hexahedra(points: FloatArray, cells: IntArray, path: Path) -> None:
    """SchemaError listing hexahedra with a non-positive corner Jacobian (VTK order)."""
    det, size = vtk_hex_corner_jacobians(points, cells)
    bad = np.flatnonzero(np.any(det <= 1e-12 * size[:, None] ** 3, axis=1))
    if bad.size:
        shown = ", ".join(str(int(c)) for c in bad[:10]) + (", ..." if bad.size > 10 else "")
        raise SchemaError(
            f"mesh file {str(path)!r} has {bad.size} inverted or degenerate hexahedra (corner "
            f"Jacobian <= 0): cells [{shown}]; order each cell's vertices as VTK does (bottom "
            "face 0-1-2-3 counter-clockwise seen from the top face 4-5-6-7) and remove "
            "collapsed cells"
        )
