"""Element kinds and cell geometry: what a :class:`~harpx.mechanics.body.Body` is built on.

The element table (``ELEMENTS``: hex8, hex20, tet4, tet10 with their quadrature orders and
volumetric formulations), conversion of meshio meshes to scikit-fem meshes, positive
orientation of tetrahedra, curved (isoparametric) tetrahedra from linear ones, and the
validity check of the cell maps (no inverted, twisted or collapsed cells). Units: mm.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal, TypeAlias

import meshio
import numpy as np
import skfem
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray

__all__ = [
    "ELEMENTS",
    "ElementKind",
    "ElementName",
    "Volumetric",
    "curved_tet_mesh",
    "default_element",
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
    """The element a mesh implies: hex8 / hex20 for straight / curved (``MeshHex2``)
    hexahedra, tet4 / tet10 for linear / quadratic tetrahedra."""
    if isinstance(mesh, skfem.MeshHex2):
        return "hex20"
    if isinstance(mesh, skfem.MeshTet2):
        return "tet10"
    if isinstance(mesh, skfem.MeshTet1):
        return "tet4"
    return "hex8"


def _skfem_mesh(m: meshio.Mesh, source: str) -> tuple[Any, FloatArray | None]:
    """The scikit-fem mesh and cell fibres of a hexahedral or tetrahedral meshio mesh.

    ``hexahedron``, ``hexahedron20`` (straight-edged geometry from the corners; the edge
    nodes become element dofs again), ``tetra`` and ``tetra10`` (curved: the edge nodes
    are kept as geometry, a ``skfem.MeshTet2``) cells are accepted; cell data ``fiber``
    (one vector per cell) becomes the fibres. ``source`` names the mesh in errors.
    """
    kinds = m.cells_dict
    known = ("hexahedron", "hexahedron20", "tetra", "tetra10")
    present = [k for k in known if len(kinds.get(k, ()))]
    if not present:
        raise ValueError(
            f"{source} has no hexahedra or tetrahedra (cell blocks "
            f"{ {k: len(v) for k, v in kinds.items()}!r}); expected 'hexahedron', "
            "'hexahedron20', 'tetra' or 'tetra10' cells"
        )
    kind = present[0]
    k = [i for i, c in enumerate(m.cells) if c.type == kind][0]
    fibers = None
    if "fiber" in m.cell_data:
        fibers = np.asarray(m.cell_data["fiber"][k], dtype=np.float64)
    cell_data = {name: [np.asarray(v[k])] for name, v in m.cell_data.items()}
    if kind == "hexahedron20":
        corners = m.cells[k].data[:, :8]
        used, inv = np.unique(corners, return_inverse=True)
        m = meshio.Mesh(m.points[used], [("hexahedron", inv.reshape(-1, 8))], cell_data=cell_data)
    elif kind == "tetra10":
        # skfem numbers the vertices first; keep the corner points, rebuild the edge nodes
        # from the file (so curved edges stay curved)
        cells = m.cells[k].data
        used, inv = np.unique(cells[:, :4], return_inverse=True)
        t = inv.reshape(-1, 4)
        base = skfem.MeshTet1(np.ascontiguousarray(m.points[used].T), np.ascontiguousarray(t.T))
        base = _orient_tets(base)
        return curved_tet_mesh(base, _edge_points(base, t, m.points[cells[:, 4:]])), fibers
    else:  # keep these cells and their nodes (drop other cell blocks and stray points)
        used, inv = np.unique(m.cells[k].data, return_inverse=True)
        nv = m.cells[k].data.shape[1]
        m = meshio.Mesh(m.points[used], [(kind, inv.reshape(-1, nv))], cell_data=cell_data)
    mesh = skfem.io.meshio.from_meshio(m)
    if isinstance(mesh, skfem.MeshTet1):
        mesh = _orient_tets(mesh)
    return mesh, fibers


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
    vanishing determinant (collapsed) is named.
    """
    tet = isinstance(mesh, skfem.MeshTet1)
    det = mesh._mapping().detDF(_TET_CHECK_POINTS if tet else _CHECK_POINTS)  # (ncell, k), mm³
    det = np.broadcast_to(det, (mesh.nelements, det.shape[-1]))
    scale = np.abs(det).max()
    negative = np.count_nonzero(det.mean(axis=1) < 0)
    sign = -1.0 if 2 * negative >= det.shape[0] else 1.0  # the majority orientation
    bad = np.nonzero(np.any(det * sign <= 1e-10 * scale, axis=1))[0]
    if bad.size:
        what = "tetrahedra" if tet else "hexahedra"
        raise ValueError(
            f"mesh has {bad.size} inverted or degenerate {what}: cells {bad[:10].tolist()} "
            "(the Jacobian of the cell map changes sign or vanishes at a corner); fix the "
            "vertex order or the geometry of those cells"
        )
