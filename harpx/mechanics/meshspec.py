"""The mesh a :class:`~harpx.mechanics.body.Body` is built from, and its checks.

A :class:`MeshSpec` is a scikit-fem :class:`skfem.MeshHex1` plus named cell regions,
optional per-cell fibre directions and named boundary facets; the skfem mesh carries the
same names (``mesh.boundaries`` / ``mesh.subdomains``) so that ``skfem.io.meshio`` round trips
keep them. Hexahedra are given in VTK/meshio vertex order (bottom quad counter-clockwise
seen from +z, then the top quad) and converted to scikit-fem's local order
(:func:`hex_mesh`), so every element has a positive Jacobian. The checks name the nodes and
cells that are unusable (non-finite, unused, coincident, inverted). Units: mm.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import skfem
from numpy.typing import NDArray
from skfem.io.meshio import HEX_MAPPING

__all__ = [
    "MeshSpec",
    "check_hexahedra",
    "check_nodes",
    "check_unused_nodes",
    "coincident_nodes",
    "facets_where",
    "hex_mesh",
    "labelled_spec",
]

#: skfem local vertex k of a hexahedron is VTK vertex ``_VTK_TO_SKFEM[k]``.
_VTK_TO_SKFEM = np.array([HEX_MAPPING[:8].index(i) for i in range(8)])


@dataclass(frozen=True)
class MeshSpec:
    """A hexahedral mesh with named regions, boundaries and optional fibres.

    Attributes
    ----------
    mesh : skfem.MeshHex1
        Vertex coordinates in mm.
    regions : dict of str to ndarray of int
        Cell ids of each named region.
    fibers : ndarray, shape (ncell, 3), or None
        Unit fibre direction per cell.
    boundaries : dict of str to ndarray of int
        Facet ids (``mesh.facets`` columns) of each named boundary.
    """

    mesh: Any
    regions: dict[str, NDArray[np.int64]] = field(default_factory=dict)
    fibers: NDArray[np.float64] | None = None
    boundaries: dict[str, NDArray[np.int64]] = field(default_factory=dict)

    def __iter__(self):  # allows ``mesh, regions, fibers, boundaries = box(...)``
        return iter((self.mesh, self.regions, self.fibers, self.boundaries))


def hex_mesh(points: NDArray[np.float64], cells_vtk: NDArray[np.int64]) -> skfem.MeshHex1:
    """Build a :class:`skfem.MeshHex1` from VTK-ordered hexahedra.

    Parameters
    ----------
    points : ndarray, shape (npoint, 3)
        Vertex coordinates in mm.
    cells_vtk : ndarray, shape (ncell, 8)
        Vertex ids per cell in VTK (meshio ``hexahedron``) order.

    Returns
    -------
    skfem.MeshHex1
        The same cells and vertices (mm), vertex ids reordered per cell to scikit-fem's
        local order; vertex ``i`` of ``points`` is ``mesh.p[:, i]``.

    Raises
    ------
    ValueError
        If the mesh is empty, a node coordinate is not finite, a cell refers to a node that
        does not exist (:func:`check_nodes`), a node is used by no cell
        (:func:`check_unused_nodes`), or a cell is inverted, twisted (bow-tie) or collapsed: its
        corner Jacobian det[e1, e2, e3] (edges to the three neighbouring corners) is not
        positive.
    """
    points = np.asarray(points, dtype=np.float64)
    cells_vtk = np.asarray(cells_vtk)
    check_nodes(points, cells_vtk, nvertex=8)
    check_hexahedra(points, cells_vtk)
    check_unused_nodes(points.shape[0], cells_vtk)
    p = np.ascontiguousarray(points.T)
    t = np.ascontiguousarray(cells_vtk[:, _VTK_TO_SKFEM].T.astype(np.int32))
    return skfem.MeshHex1(p, t)


def _ids(ids: NDArray[np.int64]) -> str:
    shown = ", ".join(str(int(i)) for i in ids[:10])
    return f"[{shown}{', ...' if ids.size > 10 else ''}]"


def check_nodes(
    points: NDArray[np.float64], cells: NDArray[np.int64], *, nvertex: int | None = None
) -> None:
    """Raise a ValueError if a mesh is empty, has non-finite nodes or dangling cells.

    A mesh must have at least one cell; every node coordinate must be finite; every cell
    must refer to existing nodes. Each message names the offending node or
    cell ids and how to fix them. Coincident nodes are allowed here (a cut body has them
    on purpose); :func:`coincident_nodes` finds them.

    Parameters
    ----------
    points : ndarray, shape (npoint, 3)
        Node coordinates in mm.
    cells : ndarray, shape (ncell, nvertex)
        Node ids of each cell (any vertex order).
    nvertex : int, optional
        Expected number of vertices per cell.

    Raises
    ------
    ValueError
        If the nodes are not finite float (npoint, 3), or the cells are not a non-empty integer
        array whose ids lie in [0, npoint); the message names the nodes or cells.

    Examples
    --------
    >>> import numpy as np
    >>> from harpx.mechanics.mesh import box
    >>> spec = box((1.0, 1.0, 1.0), (1, 1, 1))
    >>> points = spec.mesh.p.T.copy()
    >>> points[3, 0] = np.nan
    >>> try:
    ...     check_nodes(points, spec.mesh.t.T)
    ... except ValueError as err:
    ...     print(str(err)[:48])
    mesh has 1 nodes with a NaN or infinite coordina
    """
    points = np.asarray(points)
    cells = np.asarray(cells)
    if points.ndim != 2 or points.shape[1:] != (3,):
        raise ValueError(f"mesh nodes have shape {points.shape!r}; expected (npoint, 3) in mm")
    if cells.ndim != 2 or (nvertex is not None and cells.shape[1] != nvertex) or cells.size == 0:
        raise ValueError(
            f"mesh cells have shape {cells.shape!r}; expected (ncell >= 1, "
            f"{nvertex or 'nvertex'}) node ids; an empty mesh cannot be tracked (check the "
            "mesh file or the builder's arguments)"
        )
    if points.dtype.kind not in "fiu":
        raise ValueError(f"mesh nodes have dtype {str(points.dtype)!r}; expected float mm")
    if cells.dtype.kind not in "iu":
        raise ValueError(f"mesh cells have dtype {str(cells.dtype)!r}; expected integer node ids")
    bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
    if bad.size:
        raise ValueError(
            f"mesh has {bad.size} nodes with a NaN or infinite coordinate: nodes {_ids(bad)}; "
            "fix or remove them"
        )
    npoint = points.shape[0]
    if cells.min() < 0 or cells.max() >= npoint:
        wrong = np.flatnonzero(np.any((cells < 0) | (cells >= npoint), axis=1))
        raise ValueError(
            f"mesh cells {_ids(wrong)} refer to node ids outside [0, {npoint}); fix the "
            "connectivity"
        )


def check_unused_nodes(npoint: int, cells: NDArray[np.int64]) -> None:
    """Raise a ValueError naming nodes that no cell uses (they make the tangent singular).

    Parameters
    ----------
    npoint : int
        Number of nodes.
    cells : ndarray of int, shape (ncell, nvertex)
        Valid node ids of each cell.

    Raises
    ------
    ValueError
        If a node is used by no cell; the message lists the first ones.
    """
    unused = np.flatnonzero(np.bincount(np.asarray(cells).ravel(), minlength=npoint) == 0)
    if unused.size:
        raise ValueError(
            f"mesh has {unused.size} nodes that no cell uses: nodes {_ids(unused)}; remove them "
            "(e.g. mesh = mesh.remove_unused_nodes() for a skfem mesh)"
        )


def coincident_nodes(points: NDArray[np.float64]) -> NDArray[np.int64]:
    """Pairs of nodes closer than 1e-9 of the mesh extent (unmerged duplicates).

    Parameters
    ----------
    points : ndarray, shape (npoint, 3)
        Finite node coordinates in mm.

    Returns
    -------
    ndarray of int, shape (npair, 2)
        Node id pairs, each ``i < j``.
    """
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64)
    extent = float(np.ptp(points, axis=0).max()) if points.size else 0.0
    tree = cKDTree(points)
    return tree.query_pairs(r=1e-9 * max(extent, 1e-300), output_type="ndarray").astype(np.int64)


# neighbours of each VTK hexahedron corner along its three edges, right-handed for a valid cell
_CORNER_EDGES = np.array(
    [[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7], [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]]
)


def check_hexahedra(points: NDArray[np.float64], cells_vtk: NDArray[np.int64]) -> None:
    """Raise a ValueError naming VTK-ordered hexahedra with a non-positive corner Jacobian.

    Parameters
    ----------
    points : ndarray, shape (npoint, 3)
        Vertex coordinates in mm.
    cells_vtk : ndarray, shape (ncell, 8)
        Vertex ids per cell in VTK order.

    Raises
    ------
    ValueError
        If a cell has a corner Jacobian that is not positive (inverted or degenerate); the
        message lists the first cells.
    """
    xyz = points[cells_vtk]  # (ncell, 8, 3)
    edges = xyz[:, _CORNER_EDGES] - xyz[:, :, None, :]  # (ncell, 8 corners, 3 edges, 3)
    det = np.linalg.det(edges)  # (ncell, 8), mm³
    scale = max(float(np.abs(det).max()), np.finfo(float).tiny)
    bad = np.nonzero(np.any(det <= 1e-10 * scale, axis=1))[0]
    if bad.size:
        raise ValueError(
            f"mesh has {bad.size} inverted or degenerate hexahedra: cells {bad[:10].tolist()} "
            "(a corner Jacobian is not positive); fix the vertex order (VTK hexahedron) or "
            "the geometry of those cells"
        )


def facets_where(
    mesh: skfem.Mesh,
    predicate: Callable[[NDArray[np.float64]], NDArray[np.bool_]],
    *,
    boundary_only: bool = True,
) -> NDArray[np.int64]:
    """Facets whose vertices all satisfy ``predicate``.

    Parameters
    ----------
    mesh : skfem.Mesh
        The mesh.
    predicate : callable
        Maps points (n, 3) in mm to a boolean array (n,).
    boundary_only : bool, default True
        Restrict to facets on the boundary of the mesh.

    Returns
    -------
    ndarray of int
        Facet ids, sorted.
    """
    candidates = mesh.boundary_facets() if boundary_only else np.arange(mesh.facets.shape[1])
    ok = np.asarray(predicate(mesh.p.T), dtype=bool)
    keep = np.all(ok[mesh.facets[:, candidates]], axis=0)
    return np.sort(candidates[keep]).astype(np.int64)


def _finish(
    points: NDArray[np.float64],
    cells_vtk: NDArray[np.int64],
    regions: Mapping[str, NDArray[np.int64]],
    boundary_tests: Mapping[str, tuple[Callable[[NDArray[np.float64]], NDArray[np.bool_]], bool]],
) -> MeshSpec:
    mesh = hex_mesh(points, cells_vtk)
    boundaries = {
        name: facets_where(mesh, test, boundary_only=only)
        for name, (test, only) in boundary_tests.items()
    }
    regions = {k: np.asarray(v, dtype=np.int64) for k, v in regions.items()}
    return labelled_spec(mesh, regions, boundaries)


def labelled_spec(
    mesh: skfem.MeshHex1,
    regions: Mapping[str, NDArray[np.int64]],
    boundaries: Mapping[str, NDArray[np.int64]],
    fibers: NDArray[np.float64] | None = None,
) -> MeshSpec:
    """A :class:`MeshSpec` whose skfem mesh also carries the named facets and cell regions.

    Parameters
    ----------
    mesh : skfem.MeshHex1
        The hexahedral mesh (mm).
    regions : mapping of str to int arrays
        Cell indices per named region.
    boundaries : mapping of str to int arrays
        Facet indices per named boundary.
    fibers : ndarray, shape (ncell, 3), optional
        Unit fibre direction per cell.

    Returns
    -------
    MeshSpec
        A copy of ``mesh`` with ``regions`` as its subdomains and ``boundaries`` as its
        boundaries, together with the same ``regions``, ``boundaries`` and ``fibers``.
    """
    labelled = skfem.MeshHex1(
        mesh.p,
        mesh.t,
        _boundaries={k: np.asarray(v).astype(np.int32) for k, v in boundaries.items()},
        _subdomains={k: np.asarray(v).astype(np.int32) for k, v in regions.items()} or None,
    )
    return MeshSpec(mesh=labelled, regions=dict(regions), fibers=fibers,
                    boundaries=dict(boundaries))  # fmt: skip
