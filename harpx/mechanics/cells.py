"""Element kinds and cell geometry: what a :class:`~harpx.mechanics.body.Body` is built on.

The element table (``ELEMENTS``: hex8, hex20, tet4, tet10 with their quadrature orders and
volumetric formulations), conversion of meshio meshes to scikit-fem meshes, positive
orientation of tetrahedra, curved (isoparametric) tetrahedra from linear ones, and the
validity check of the cell maps (no inverted, twisted or collapsed cells). Units: mm.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from typing import Any, Literal, TypeAlias

import meshio
import numpy as np
import skfem
from numpy.typing import ArrayLike
from skfem.io.meshio import HEX_MAPPING

from harpx._typing import FloatArray, IntArray
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.mechanics._mesh_file_sets import read_named_sets

__all__ = [
    "CURVED_EDGE_TOLERANCE",
    "ELEMENTS",
    "ElementKind",
    "ElementName",
    "Volumetric",
    "curved_tet_mesh",
    "default_element",
    "volume_blocks",
    "vtk_cells",
    "vtk_corners",
    "vtk_hex_corner_jacobians",
    "warn_dropped_curvature",
]

#: Element names a :class:`Body` accepts.
ElementName: TypeAlias = Literal["hex8", "hex20", "tet4", "tet10"]
#: Volumetric (incompressibility) formulations.
Volumetric: TypeAlias = Literal[
    "mean-dilatation", "linear-dilatation", "nodal-dilatation", "pointwise"
]


@dataclass(frozen=True)
class ElementKind:
    """What a :class:`Body` needs to know about one element type.

    Attributes
    ----------
    factory : callable
        The scalar scikit-fem element class.
    intorder : int
        skfem integration order of the cell quadrature.
    nqp : int
        Number of quadrature points per cell that order gives.
    facet_intorder : int
        Integration order on boundary facets (follower pressure, cavity volume).
    meshes : tuple of type
        skfem mesh classes the element accepts.
    volumetric : tuple of str
        Volumetric formulations offered; the first is the default.
    vtk_edges : ndarray of int, shape (nedge, 2)
        Corner pairs (VTK order) of the edge nodes, in VTK order (empty for linear cells).
    """

    factory: Any
    intorder: int
    nqp: int
    facet_intorder: int
    meshes: tuple[type, ...]
    volumetric: tuple[Volumetric, ...]
    vtk_edges: IntArray


_NO_EDGES = np.zeros((0, 2), dtype=np.int64)
# VTK hexahedron20 and tetra10 edges as pairs of VTK corner ids.
_VTK_HEX_EDGES = np.array(
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
     [0, 4], [1, 5], [2, 6], [3, 7]]
)  # fmt: skip
_VTK_TET_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
_HEX_MESHES = (skfem.MeshHex1,)
_HEX20_MESHES = (skfem.MeshHex1, skfem.MeshHex2)
_TET_MESHES = (skfem.MeshTet1, skfem.MeshTet2)

#: element name -> :class:`ElementKind`
ELEMENTS: dict[str, ElementKind] = {
    "hex8": ElementKind(
        skfem.ElementHex1, 3, 8, 3, _HEX_MESHES, ("mean-dilatation", "pointwise"), _NO_EDGES
    ),
    "hex20": ElementKind(
        skfem.ElementHexS2, 5, 27, 5, _HEX20_MESHES,
        ("mean-dilatation", "linear-dilatation", "pointwise"), _VTK_HEX_EDGES,
    ),
    "tet4": ElementKind(
        skfem.ElementTetP1, 1, 1, 2, (skfem.MeshTet1,), ("nodal-dilatation", "pointwise"),
        _NO_EDGES,
    ),
    "tet10": ElementKind(
        skfem.ElementTetP2, 5, 14, 4, _TET_MESHES,
        ("nodal-dilatation", "mean-dilatation", "pointwise"),
        _VTK_TET_EDGES,
    ),
}  # fmt: skip

_VOLUMETRIC = ("mean-dilatation", "linear-dilatation", "nodal-dilatation", "pointwise")


def default_element(mesh: Any) -> ElementName:
    """The element a mesh implies.

    Parameters
    ----------
    mesh : skfem.MeshHex1, skfem.MeshHex2, skfem.MeshTet1 or skfem.MeshTet2
        The mesh.

    Returns
    -------
    {"hex8", "hex20", "tet4", "tet10"}
        hex8 / hex20 for straight / curved (``MeshHex2``) hexahedra, tet4 / tet10 for
        linear / quadratic (``MeshTet2``) tetrahedra; hex8 for any other mesh.
    """
    if isinstance(mesh, skfem.MeshHex2):
        return "hex20"
    if isinstance(mesh, skfem.MeshTet2):
        return "tet10"
    if isinstance(mesh, skfem.MeshTet1):
        return "tet4"
    return "hex8"


#: meshio cell types of 3D cells (prefixes): a block of one of them is part of the body.
_VOLUME_TYPES = ("tetra", "hexahedron", "wedge", "pyramid", "polyhedron")


def volume_blocks(
    m: meshio.Mesh, source: str, kinds: tuple[str, ...], what: str
) -> tuple[str, IntArray, dict[str, np.ndarray]]:
    """The volume cells of a meshio mesh: one kind, its blocks merged, and their cell data.

    Parameters
    ----------
    m : meshio.Mesh
        The mesh; blocks of surface, line and vertex cells (boundaries) are ignored.
    source : str
        What the mesh is called in errors (e.g. its file name).
    kinds : tuple of str
        The meshio cell types accepted, e.g. ``("hexahedron", "hexahedron20")``.
    what : str
        Those cells in words, for errors (e.g. ``"hexahedra"``).

    Returns
    -------
    kind : str
        The one accepted type the mesh's volume cells have.
    cells : ndarray of int, shape (ncell, nvertex)
        Every block of that type, in block order.
    cell_data : dict of str to ndarray
        Each cell data field over those cells (blocks concatenated in the same order).

    Raises
    ------
    TypeError
        If ``m`` is not a :class:`meshio.Mesh`.
    ValueError
        If the mesh has no cells of an accepted type, or volume cells of more than one type
        (e.g. hexahedra and tetrahedra, or wedges harpx has no element for): the message
        gives the count of each, so no cell is dropped silently. Also if a cell names a node
        the mesh does not have, or repeats another cell's nodes.
    """
    if not isinstance(m, meshio.Mesh):
        raise TypeError(
            f"expected a meshio.Mesh for {source}, got {type(m).__name__!r}; read a file "
            "with harpx.io.mesh.read_body(path, material)"
        )
    counts: dict[str, int] = {}
    for block in m.cells:
        if len(block.data) and block.type.startswith(_VOLUME_TYPES):
            counts[block.type] = counts.get(block.type, 0) + len(block.data)
    present = [k for k in kinds if counts.get(k)]
    if not present:
        every: dict[str, int] = {}
        for block in m.cells:
            every[block.type] = every.get(block.type, 0) + len(block.data)
        raise ValueError(
            f"{source} has no {what} (cell blocks {every!r}); expected "
            f"{' or '.join(repr(k) for k in kinds)} cells"
        )
    if len(counts) > 1:
        raise ValueError(
            f"{source} mixes volume cells of several kinds {counts!r}; a body is built from "
            f"one kind ({', '.join(repr(k) for k in kinds)}), so some cells would be dropped. "
            "Mesh it with one kind (e.g. split hexahedra into tetrahedra with "
            "harpx.mechanics.mesh.tetrahedralize) or remove the blocks you do not want"
        )
    kind = present[0]
    blocks = [i for i, c in enumerate(m.cells) if c.type == kind and len(c.data)]
    cells = np.concatenate([np.asarray(m.cells[i].data, dtype=np.int64) for i in blocks])
    npoint = len(m.points)
    outside = np.flatnonzero(((cells < 0) | (cells >= npoint)).any(axis=1))
    if outside.size:
        raise ValueError(
            f"{source} has {outside.size} {kind!r} cells that name nodes it does not have "
            f"(cells {outside[:10].tolist()}; node ids must lie in [0, {npoint - 1}]); the file "
            "is truncated or its points and cells do not belong together"
        )
    corners = np.sort(cells[:, : 4 if kind.startswith("tetra") else 8], axis=1)
    _, first, repeats = np.unique(corners, axis=0, return_index=True, return_counts=True)
    if np.any(repeats > 1):
        twice = np.setdiff1d(np.arange(len(cells)), first)
        raise ValueError(
            f"{source} has {twice.size} {kind!r} cells that repeat another cell's nodes "
            f"(e.g. cells {twice[:10].tolist()}, counted over its blocks in order): the same "
            "volume would count twice. Remove the repeats (a mesh exported with its cells "
            "in several groups lists them once per group)"
        )
    cell_data: dict[str, np.ndarray] = {}
    for name, per_block in m.cell_data.items():
        parts = [np.asarray(per_block[i]) for i in blocks]
        if len({p.shape[1:] for p in parts}) > 1:
            raise ValueError(
                f"cell data {name!r} of {source} has shapes {[p.shape for p in parts]} in its "
                f"{kind!r} blocks; each block needs the same per-cell shape"
            )
        cell_data[name] = np.concatenate(parts)
    return kind, cells, cell_data


def vtk_corners(mesh: Any) -> IntArray:
    """Vertex ids of every cell in VTK corner order (``hexahedron`` or ``tetra``).

    Parameters
    ----------
    mesh : skfem.MeshHex1, skfem.MeshHex2, skfem.MeshTet1 or skfem.MeshTet2
        A scikit-fem mesh.

    Returns
    -------
    ndarray of int64, shape (ncell, 8) or (ncell, 4)
        Columns of ``mesh.t`` in VTK order (scikit-fem and VTK agree on tetrahedra).
    """
    if isinstance(mesh, skfem.MeshTet1):
        return np.asarray(mesh.t.T, dtype=np.int64)
    return np.asarray(mesh.t.T[:, HEX_MAPPING[:8]], dtype=np.int64)


def vtk_cells(
    mesh: Any, kind: ElementKind, cell_dofs: IntArray, nodes: FloatArray, dof_points: FloatArray
) -> IntArray:
    """Dof-node ids of every cell in VTK/meshio order, edge nodes after the corners.

    Parameters
    ----------
    mesh : skfem.MeshHex1, skfem.MeshHex2, skfem.MeshTet1 or skfem.MeshTet2
        The body's mesh.
    kind : ElementKind
        The element; its ``vtk_edges`` give the VTK order of the edge nodes (none for hex8
        and tet4).
    cell_dofs : ndarray of int, shape (ncell, nbasis)
        Scalar dof ids per cell (vertex dofs first, then edge dofs, in scikit-fem order).
    nodes : ndarray, shape (nvertex, 3)
        Mesh vertices, mm.
    dof_points : ndarray, shape (n_dof_nodes, 3)
        Positions of all dof nodes, mm.

    Returns
    -------
    ndarray of int64, shape (ncell, 8), (ncell, 20), (ncell, 4) or (ncell, 10)
        ``hexahedron``, ``hexahedron20``, ``tetra`` or ``tetra10`` connectivity. Each VTK
        edge is matched to the cell's edge dof at its midpoint (for curved cells, the
        midpoint of the straight edge between its end vertices).
    """
    corners = vtk_corners(mesh)
    vtk_edges = kind.vtk_edges
    nc = corners.shape[1]
    if vtk_edges.shape[0] == 0:
        return corners
    edge_dofs = cell_dofs[:, nc:]  # (nel, nedge)
    if isinstance(mesh, (skfem.MeshTet2, skfem.MeshHex2)):  # edge dofs follow vertices
        ends = mesh.edges[:, edge_dofs - int(mesh.nvertices)]  # (2, nel, nedge)
        mid = 0.5 * (nodes[ends[0]] + nodes[ends[1]])
    else:
        mid = dof_points[edge_dofs]
    want = 0.5 * (nodes[corners[:, vtk_edges[:, 0]]] + nodes[corners[:, vtk_edges[:, 1]]])
    d = np.linalg.norm(want[:, :, None, :] - mid[:, None, :, :], axis=-1)
    order = np.argmin(d, axis=2)
    edges = np.take_along_axis(edge_dofs, order, axis=1)
    return np.concatenate([corners, edges], axis=1)


#: The 8 corners of the reference hexahedron in VTK order, as (xi, eta, zeta) in {-1, 1}.
VTK_HEX_CORNERS = np.array(
    [[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
     [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64
)  # fmt: skip


def hex8_shape(xi: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Trilinear shape functions of the VTK-ordered hexahedron and their gradients.

    Parameters
    ----------
    xi : array_like, shape (q, 3)
        Reference points in [-1, 1]³ (dimensionless; the corners are
        :data:`VTK_HEX_CORNERS`).

    Returns
    -------
    N : ndarray, shape (q, 8)
        ``N_a(xi_q) = prod_k (1 + xi_qk c_ak) / 8`` with ``c_a`` corner ``a``.
    dN : ndarray, shape (q, 8, 3)
        ``dN_a/dxi_k`` at the points.

    Examples
    --------
    >>> from harpx.mechanics.cells import hex8_shape
    >>> N, dN = hex8_shape([[0.0, 0.0, 0.0]])
    >>> N.round(3).tolist()[0] == [0.125] * 8, float(dN.sum())
    (True, 0.0)
    """
    x = np.asarray(xi, dtype=np.float64).reshape(-1, 3)
    c = VTK_HEX_CORNERS
    f = 1.0 + x[:, None, :] * c[None, :, :]  # (q, a, k): 1 + xi_qk c_ak
    dN = np.empty((len(x), 8, 3))
    for k in range(3):  # loop over the 3 reference axes
        others = [j for j in range(3) if j != k]
        dN[:, :, k] = c[None, :, k] * f[:, :, others[0]] * f[:, :, others[1]] / 8.0
    return f.prod(axis=2) / 8.0, dN


_DN_CORNERS = hex8_shape(VTK_HEX_CORNERS)[1]


def vtk_hex_corner_jacobians(points: FloatArray, cells: IntArray) -> tuple[FloatArray, FloatArray]:
    """Jacobian determinants at the corners of hexahedra given in VTK vertex order.

    Parameters
    ----------
    points : ndarray, shape (npoint, 3)
        Node positions, mm.
    cells : ndarray of int, shape (ncell, 8)
        Corner node ids per cell, VTK order (bottom face 0-1-2-3 counter-clockwise seen
        from the top face 4-5-6-7).

    Returns
    -------
    det : ndarray, shape (ncell, 8)
        ``det(dx/dxi)`` at each corner, mm³: all positive for a valid cell in VTK order,
        all negative for a mirrored one, of both signs for a twisted one, ~0 if collapsed.
    size : ndarray, shape (ncell,)
        Largest extent of each cell along x, y or z, mm (``size**3`` scales ``det``).
    """
    X = np.asarray(points, dtype=np.float64)[np.asarray(cells)[:, :8]]  # (ncell, 8, 3)
    J = np.einsum("cak,eai->ecik", _DN_CORNERS, X)  # dx_i/dxi_k at each corner
    return np.linalg.det(J), np.ptp(X, axis=1).max(axis=1)


def _skfem_mesh(m: meshio.Mesh, source: str) -> tuple[Any, FloatArray | None]:
    """The scikit-fem mesh and cell fibres of a hexahedral or tetrahedral meshio mesh.

    ``hexahedron``, ``hexahedron20`` (straight-edged geometry from the corners; the edge
    nodes become element dofs again; a HarpxWarning if the file's edges are curved),
    ``tetra`` and ``tetra10`` (curved: the edge nodes are kept as geometry, a
    ``skfem.MeshTet2``) cells are accepted; several blocks of one kind are merged
    (:func:`volume_blocks`), volume cells of several kinds are refused. Cell data ``fiber``
    (one vector per cell) becomes the fibres; named regions and boundaries (cell sets, named
    gmsh physical groups, ``region`` labels, skfem cell data) become the mesh's subdomains
    and boundaries. ``source`` names the mesh in errors.
    """
    kinds = ("hexahedron", "hexahedron20", "tetra", "tetra10")
    kind, cells, data = volume_blocks(m, source, kinds, "hexahedra or tetrahedra")
    fibers = None
    if "fiber" in data:
        fibers = np.asarray(data["fiber"], dtype=np.float64)
    points = np.asarray(m.points)
    if kind.startswith("hexahedron"):
        _check_vtk_hexahedra(np.asarray(points, dtype=np.float64), cells, source)
    if kind == "hexahedron20":
        warn_dropped_curvature(points, cells, source)
    ncorner = 8 if kind.startswith("hexahedron") else 4
    # keep the corners of these cells (drop boundary blocks, stray points and edge nodes)
    used, inv = np.unique(cells[:, :ncorner], return_inverse=True)
    vertex_of = np.full(len(points), -1, dtype=np.int64)
    vertex_of[used] = np.arange(used.size)
    corners = inv.reshape(-1, ncorner)
    if kind == "tetra10":  # skfem numbers the vertices first; the file's edge nodes are kept
        base = skfem.MeshTet1(np.ascontiguousarray(points[used].T), np.ascontiguousarray(corners.T))
        base = _orient_tets(base)
        edge_points = _edge_points(base, corners, points[cells[:, 4:]])
    else:
        linear = "hexahedron" if ncorner == 8 else "tetra"
        base = skfem.io.meshio.from_meshio(meshio.Mesh(points[used], [(linear, corners)]))
        if isinstance(base, skfem.MeshTet1):
            base = _orient_tets(base)
    regions, boundaries = read_named_sets(m, kind, vertex_of, base.facets.T, source)
    if regions or boundaries:
        base = dataclasses.replace(
            base,
            _boundaries={k: v.astype(np.int32) for k, v in boundaries.items()} or None,
            _subdomains={k: v.astype(np.int32) for k, v in regions.items()} or None,
        )
    if kind == "tetra10":
        return curved_tet_mesh(base, edge_points), fibers
    return base, fibers


#: Edge nodes farther than this fraction of their edge's length from its midpoint make a
#: quadratic cell curved (or unevenly parametrised): reducing it to its corners changes it.
CURVED_EDGE_TOLERANCE = 1e-3


def warn_dropped_curvature(points: ArrayLike, cells: IntArray, source: str) -> float:
    """Warn if the edge nodes of ``hexahedron20`` cells are not at their edges' midpoints.

    A ``hexahedron20`` mesh is reduced to its corners (straight edges; ``element="hex20"``
    puts the edge nodes back at the midpoints), so edge nodes off the midpoints, e.g. on
    the arcs of a curved wall, are geometry that is lost.

    Parameters
    ----------
    points : array_like, shape (npoint, 3)
        Node positions, mm.
    cells : ndarray of int, shape (ncell, 20)
        VTK ``hexahedron20`` connectivity (8 corners, then the 12 edge nodes).
    source : str
        What the mesh is called in the warning (e.g. its file name).

    Returns
    -------
    float
        Largest distance of an edge node from its edge's midpoint over the edge's length
        (dimensionless; 0 for straight, evenly parametrised edges).

    Warns
    -----
    HarpxWarning
        If that ratio exceeds :data:`CURVED_EDGE_TOLERANCE`; names the distance (mm), the
        ratio and the number of cells.
    """
    x = np.asarray(points, dtype=np.float64)
    a = x[cells[:, _VTK_HEX_EDGES[:, 0]]]  # (ncell, 12, 3)
    b = x[cells[:, _VTK_HEX_EDGES[:, 1]]]
    off = np.linalg.norm(x[cells[:, 8:20]] - 0.5 * (a + b), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = off / np.linalg.norm(b - a, axis=-1)
    ratio = np.where(np.isfinite(ratio), ratio, 0.0)
    worst = float(ratio.max(initial=0.0))
    if worst > CURVED_EDGE_TOLERANCE:
        curved = np.flatnonzero((ratio > CURVED_EDGE_TOLERANCE).any(axis=1))
        cell, edge = np.unravel_index(np.argmax(ratio), ratio.shape)
        warnings.warn(
            f"{source} has {curved.size} 'hexahedron20' cells whose edge nodes are off their "
            f"edges' midpoints, up to {off[cell, edge]:.4g} mm ({worst:.2%} of the edge length, "
            f"cell {int(cell)}): the cells are read by their 8 corners with straight edges, so "
            "that curved geometry is lost (the volume changes). Mesh with finer straight cells, "
            "or with curved 'tetra10' cells, whose edge nodes are kept",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return worst


def _check_vtk_hexahedra(points: FloatArray, cells: IntArray, source: str) -> None:
    """ValueError naming twisted or collapsed hexahedra (VTK order) before skfem maps them.

    A mirrored cell (every corner Jacobian negative) is a valid cell that scikit-fem
    reorders; a twisted one (both signs) or a collapsed one (a vanishing Jacobian) is not.
    Cells with a non-finite node are left to the Body's own check, which names the node.
    """
    if points.ndim != 2 or points.shape[1] != 3:
        return  # the Body names the shape
    finite = np.isfinite(points[cells[:, :8]]).all(axis=(1, 2))
    det, size = vtk_hex_corner_jacobians(points, cells[finite])
    small = np.abs(det) <= 1e-12 * size[:, None] ** 3
    bad = np.flatnonzero(finite)[
        np.any(small, axis=1) | ((det > 0).any(axis=1) & (det < 0).any(axis=1))
    ]
    if bad.size:
        raise ValueError(
            f"{source} has {bad.size} twisted or collapsed hexahedra (the corner Jacobian "
            f"changes sign or vanishes): cells {bad[:10].tolist()}; order each cell's vertices "
            "as VTK does (bottom face 0-1-2-3 counter-clockwise seen from the top face "
            "4-5-6-7) and remove collapsed cells"
        )


# VTK hexahedron edges grouped by the reference direction they run along (xi, eta, zeta)


def _orient_tets(mesh: skfem.MeshTet1) -> skfem.MeshTet1:
    """The same tetrahedra, each with a positive (right-handed) vertex order.

    Swapping two vertices of a cell leaves ``mesh.edges`` (sorted vertex pairs) unchanged,
    so the edge nodes of a ``MeshTet2`` stay where they are.
    """
    p, t = mesh.p, mesh.t
    a, b, c, d = (p[:, t[i]] for i in range(4))
    vol = np.einsum("ie,ie->e", np.cross(b - a, c - a, axis=0), d - a)
    if np.all(vol > 0):
        return mesh
    t = t.copy()
    neg = vol < 0
    t[1, neg], t[2, neg] = mesh.t[2, neg], mesh.t[1, neg]
    return dataclasses.replace(mesh, t=t)


def _edge_points(mesh: skfem.MeshTet1, t: IntArray, nodes: FloatArray) -> FloatArray:
    """Positions of the mesh edges' nodes from per-cell VTK tetra10 edge nodes.

    ``t`` (ncell, 4) are the cells' corners as given (before orientation), ``nodes``
    (ncell, 6, 3) their edge nodes in VTK order; returns (3, nedge) ordered like
    ``mesh.edges``.
    """
    pairs = np.sort(t[:, _VTK_TET_EDGES], axis=-1).reshape(-1, 2)
    n = mesh.p.shape[1]
    keys = pairs[:, 0] * n + pairs[:, 1]
    edges = np.sort(mesh.edges, axis=0)
    ekeys = edges[0] * n + edges[1]
    order = np.argsort(keys)
    pos = order[np.searchsorted(keys[order], ekeys)]
    return np.ascontiguousarray(nodes.reshape(-1, 3)[pos].T)


def curved_tet_mesh(mesh: skfem.MeshTet1, edge_points: ArrayLike | None = None) -> skfem.MeshTet2:
    """A quadratic (isoparametric) tetrahedral mesh from a linear one.

    Parameters
    ----------
    mesh : skfem.MeshTet1
        Vertices (mm) and cells.
    edge_points : array_like, shape (3, nedge), optional
        Position of the node of every edge of ``mesh.edges`` (mm), e.g. projected onto a
        curved surface; the edge midpoints by default (straight edges).

    Returns
    -------
    skfem.MeshTet2
        Carries the boundaries and subdomains of ``mesh``.

    Raises
    ------
    ValueError
        If ``edge_points`` is not (3, nedge), one point per column of ``mesh.edges``.
    """
    mid = 0.5 * (mesh.p[:, mesh.edges[0]] + mesh.p[:, mesh.edges[1]])
    pts = mid if edge_points is None else np.asarray(edge_points, dtype=np.float64)
    if pts.shape != mid.shape:
        raise ValueError(
            f"edge_points has shape {pts.shape!r}; expected {mid.shape!r} (3, nedge), one "
            "point per column of mesh.edges"
        )
    doflocs = np.hstack([mesh.p, pts])
    mesh = _orient_tets(mesh)
    return skfem.MeshTet2(
        doflocs,
        mesh.t,
        _boundaries=mesh._boundaries,
        _subdomains=mesh._subdomains,
    )


# reference corners and centre of the unit hexahedron / tetrahedron, where the geometry
# Jacobian is checked
_CHECK_POINTS = np.array(
    [
        [0, 0, 0],
        [1, 0, 0],
        [0, 1, 0],
        [0, 0, 1],
        [1, 1, 0],
        [1, 0, 1],
        [0, 1, 1],
        [1, 1, 1],
        [0.5, 0.5, 0.5],
    ],
    dtype=np.float64,
).T
_TET_CHECK_POINTS = np.array(
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.25, 0.25, 0.25]], dtype=np.float64
).T


def _check_cells(mesh: Any) -> None:
    """Raise if any cell is inverted, twisted or collapsed.

    The Jacobian determinant of the cell map is evaluated at the corners and the centre of
    every cell; a valid mesh has one sign everywhere (skfem's reference orientation makes
    it negative for positively ordered hexahedra; tetrahedra are oriented positively on
    input). A cell with the opposite sign somewhere (inverted or bow-tie) or with a
    vanishing determinant (collapsed) is named, with a hint at the vertex order. The
    determinant is computed from ``DF`` here (skfem's ``detDF`` raises a bare
    ``Exception`` where it is exactly zero).
    """
    tet = isinstance(mesh, skfem.MeshTet1)
    points = _TET_CHECK_POINTS if tet else _CHECK_POINTS
    with np.errstate(divide="ignore", invalid="ignore"):  # an affine map inverts A
        DF = np.asarray(mesh._mapping().DF(points))  # (3, 3, ncell, k), mm
    DF = np.broadcast_to(DF, (3, 3, mesh.nelements, points.shape[1]))
    det = np.linalg.det(np.moveaxis(DF, (0, 1), (-2, -1)))  # (ncell, k), mm³
    scale = np.abs(det[np.isfinite(det)]).max(initial=0.0)
    negative = np.count_nonzero(det.mean(axis=1) < 0)
    sign = -1.0 if 2 * negative >= det.shape[0] else 1.0  # the majority orientation
    bad = np.flatnonzero(~np.all(det * sign > 1e-10 * scale, axis=1))
    if bad.size:
        what = "tetrahedra" if tet else "hexahedra"
        raise ValueError(
            f"mesh has {bad.size} inverted or degenerate {what}: cells {bad[:10].tolist()} "
            f"(the Jacobian of the cell map changes sign or vanishes; cell {int(bad[0])} has "
            f"vertices {np.asarray(mesh.t)[:, bad[0]].tolist()}); {_order_hint(mesh)}"
        )


def _order_hint(mesh: Any) -> str:
    """What to check in the cells of ``mesh`` when a cell map is inverted or collapsed."""
    if isinstance(mesh, skfem.MeshTet2):
        return (
            "check the order of the edge nodes: 'tetra10' cells list them as VTK does (edges "
            "0-1, 1-2, 0-2, 0-3, 1-3, 2-3), while gmsh's raw .msh order swaps the last two "
            "(2-3 before 1-3); an edge node far off its edge also folds the cell"
        )
    if isinstance(mesh, skfem.MeshTet1):
        return "remove flat (zero-volume) tetrahedra or fix their geometry"
    return (
        "a skfem hexahedral mesh needs mesh.t in scikit-fem's local vertex order, not VTK's: "
        "build it from VTK/meshio-ordered cells with harpx.mechanics.mesh.hex_mesh or "
        "Body.from_meshio; a hexahedron with coincident corners (collapsed, e.g. at an apex) "
        "has no valid map: split it into tetrahedra or re-mesh it"
    )
