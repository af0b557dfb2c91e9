"""How harpx datasets are encoded in NetCDF and decoded again, exactly.

Attribute values NetCDF cannot store as such are encoded with their Python type recorded,
numeric variables get their compression and chunks, and tracked meshes a CF/UGRID
description that is dropped again on reading: the conventions of
:mod:`harpx.io.netcdf` (see its docstring), used by
:func:`~harpx.io.netcdf.to_netcdf` and :func:`~harpx.io.netcdf.open_dataset`.
"""

from __future__ import annotations

import json
import numbers
from collections.abc import Hashable, Mapping
from typing import Any

import numpy as np
import xarray as xr

from harpx.errors import ArchiveError

__all__ = ["COMPRESSION_LEVEL", "CONVENTIONS", "MESH", "UGRID_CONVENTIONS"]

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
            # netCDF attributes are 1-D numbers (bool as int8): record the shape and kind
            element = ":bool" if value.dtype == bool else ""
            shape = f"{value.shape}" if value.ndim != 1 or value.size == 1 else ""
            out[key] = value.ravel().astype(np.int8) if element else value.ravel()
            if element or shape:
                types[key] = f"ndarray{shape}{element}"
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
        elif kind.startswith("ndarray"):  # "ndarray(2, 3)", "ndarray:bool", "ndarray(2, 1):bool"
            shape, _, element = kind[len("ndarray") :].partition(":")
            if element == "bool":
                value = value.astype(bool)
            if shape:
                value = value.reshape(tuple(json.loads("[" + shape[1:-1].rstrip(",") + "]")))
            out[key] = value
        else:
            container, _, element = kind.partition(":")
            items = value.astype(bool).tolist() if element == "bool" else value.tolist()
            out[key] = tuple(items) if container == "tuple" else list(items)
    return out
