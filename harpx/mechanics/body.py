"""A deformable body: mesh, element, material, fibres, regions and quadrature data.

:class:`Body` ties a scikit-fem hexahedral or tetrahedral mesh to a material and precomputes
everything the
vectorised assembly (:mod:`harpx.mechanics.assembly`) needs: reference gradients of the shape
functions at every quadrature point, quadrature weights, element-to-dof maps, per-point fibre
directions, active-stress levels and growth tensors.

Elements (``ELEMENTS``): ``hex8`` (trilinear, 2x2x2 Gauss), ``hex20`` (serendipity,
3x3x3 Gauss), ``tet4`` (linear tetrahedron, 1 point) and ``tet10`` (quadratic tetrahedron,
14-point rule of degree 5 with positive weights). A ``skfem.MeshTet2`` carries curved
(isoparametric) tetrahedra: its edge nodes may lie on a curved surface. A ``skfem.MeshHex2``
(27-node triquadratic geometry, :func:`~harpx.mechanics.mesh.curved_hex_mesh`; ``tube`` and
``ventricle`` with ``curved=True``) carries curved hexahedra for hex20: the displacement is
the 20-node serendipity field on the curved cells (its dofs are the vertices and the edge
nodes; the face and cell geometry nodes carry no dofs). Point location
(:func:`~harpx.mechanics.locate.locate`, ``Body.displacement_at``, tracking) handles
straight hexahedra only and refuses curved ones.

Degrees of freedom: scalar dof ``n`` of the scalar element (mesh vertices first, then, for
hex20 and tet10, one node per mesh edge) carries the displacement components ``3n, 3n+1, 3n+2``
(x, y, z). This is the ordering of ``skfem.ElementVector`` on the same mesh (``body.basis``).
Units: mm, kPa.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, TypeAlias, TypeVar, cast

import meshio
import numpy as np
import skfem
from numpy.typing import ArrayLike
from scipy import sparse
from skfem.io.meshio import HEX_MAPPING

from harpx._typing import FloatArray, IntArray
from harpx.errors import CoincidentNodesWarning, SchemaError
from harpx.mechanics import kinematics
from harpx.mechanics.mesh import MeshSpec, check_nodes, check_unused_nodes, coincident_nodes

__all__ = [
    "Body",
    "ELEMENTS",
    "ElementKind",
    "check_fits_image",
    "curved_tet_mesh",
    "default_element",
]

if TYPE_CHECKING:
    from harpx.mechanics.segmentation import MeshQuality

_T = TypeVar("_T")
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
_EDGES_BY_DIRECTION = np.array(
    [[[0, 1], [3, 2], [4, 5], [7, 6]], [[0, 3], [1, 2], [4, 7], [5, 6]],
     [[0, 4], [1, 5], [2, 6], [3, 7]]]
)  # fmt: skip
# bytes held per constraint quadrature point and basis function (values, gradients, work
# arrays), plus per point (positions, weights, phase samples): a generous estimate
_BYTES_PER_POINT_BASIS = 64
_BYTES_PER_POINT = 400


def check_fits_image(body: Body, grid: Any, *, max_points: int = 10_000_000) -> None:
    """Raise before tracking if a body's size or position cannot match an image grid.

    Cheap checks (a pass over nodes and cells) that catch a mesh in the wrong units or
    with stray nodes before the tracker allocates its constraint quadrature, whose point
    count grows with (cell size / voxel size)³:

    * every node lies within one field of view (the largest extent of the grid) of the
      image's field of view;
    * the mesh is larger than one voxel;
    * the constraint quadrature, points at most one acquired voxel apart as the tracker
      places them, has at most ``max_points`` points.

    Parameters
    ----------
    body : Body
        The tracking body (mm).
    grid : xarray.Dataset
        A ``tagged/1`` or ``phase/1`` dataset: coordinates ``z``, ``y``, ``x`` (mm) and,
        for phase images, the ``upsample`` attribute (the acquired voxel is ``upsample``
        grid steps).
    max_points : int, default 10_000_000
        Largest constraint quadrature allowed (about 1 kB of memory per point).

    Raises
    ------
    NotImplementedError
        For a body on curved hexahedra (``skfem.MeshHex2``): tracking samples the body
        through the straight-cell point locator.
    ValueError
        Naming the nodes far outside the field of view, the mesh and field-of-view sizes,
        the estimated point count and memory, and a likely unit mix-up (µm or m instead
        of mm) when the size ratio suggests one.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from harpx.mechanics.mesh import box
    >>> from harpx.mechanics.materials import NeoHookean
    >>> grid = xr.Dataset(coords={d: np.arange(16.0) for d in "zyx"})
    >>> body = Body(box((8.0, 8.0, 8.0), (2, 2, 2), origin=(4.0, 4.0, 4.0)), NeoHookean(1, 120))
    >>> check_fits_image(body, grid)  # inside, in mm: nothing to say
    >>> far = Body(box((8e3, 8e3, 8e3), (2, 2, 2)), NeoHookean(1, 120))  # micrometres
    >>> try:
    ...     check_fits_image(far, grid)
    ... except ValueError as err:
    ...     print(str(err).split(": ")[-1])
    are its coordinates in micrometres (divide by 1000)?
    """
    if isinstance(body.mesh, skfem.MeshHex2):
        raise NotImplementedError(
            "tracking a body on curved hexahedra (skfem.MeshHex2) is not implemented: the "
            "tracker locates points with the straight (trilinear) cell map; track with the "
            "straight mesh (curved=False)"
        )
    low, high, step = [], [], []
    for axis in ("x", "y", "z"):
        if axis not in grid.coords:
            raise SchemaError(f"grid has no coordinate {axis!r} (voxel centres in mm)")
        values = np.asarray(grid[axis].values, dtype=np.float64)
        if values.size == 0 or not np.all(np.isfinite(values)):
            raise SchemaError(f"grid coordinate {axis!r} is empty or not finite")
        d = float((values[-1] - values[0]) / (values.size - 1)) if values.size > 1 else 0.0
        low.append(values[0] - d / 2)
        high.append(values[-1] + d / 2)
        if values.size > 1:
            step.append(abs(d))
    lo, hi = np.array(low), np.array(high)
    fov = float((hi - lo).max())
    voxel = float(grid.attrs.get("upsample", 1)) * min(step) if step else fov
    nodes = np.asarray(body.nodes)
    size = float(np.ptp(nodes, axis=0).max())
    ratio = size / fov if fov > 0 else np.inf
    hint = ""
    if ratio > 20:
        hint = (
            f"; the mesh is {ratio:.3g} times larger than the image: are its coordinates in "
            "micrometres (divide by 1000)?"
        )
    elif size < voxel:
        hint = (
            "; the mesh is smaller than one voxel: are its coordinates in metres (multiply "
            "by 1000)?"
        )
    outside = np.maximum(lo - nodes, nodes - hi).max(axis=1)  # mm beyond the field of view
    far = np.flatnonzero(outside > fov)
    if far.size:
        shown = ", ".join(str(int(i)) for i in far[:10]) + (", ..." if far.size > 10 else "")
        raise SchemaError(
            f"mesh nodes [{shown}] lie up to {outside.max():.4g} mm outside the image field "
            f"of view ({lo.round(3).tolist()} to {hi.round(3).tolist()} mm, x/y/z); the mesh "
            f"spans {size:.4g} mm, the field of view {fov:.4g} mm"
            f"{hint if 2 * far.size > len(nodes) else '; move or fix those nodes'}"
        )
    if size < voxel:
        raise SchemaError(
            f"the mesh spans {size:.4g} mm but one acquired voxel is {voxel:.4g} mm{hint}"
        )
    count = 1
    if body.element.startswith("tet"):  # the tracker's rule: m³ points, m from the longest edge
        corners = nodes[body.cells[:, :4]]  # (ncell, 4, 3)
        pairs = _VTK_TET_EDGES
        length = np.linalg.norm(corners[:, pairs[:, 0]] - corners[:, pairs[:, 1]], axis=-1)
        m = max(1, int(np.ceil(float(length.max()) / (1.5 * voxel))))
        count = m**3
        longest = (
            f"its longest tetrahedron edge is {float(length.max()):.4g} mm, {m} points per "
            f"edge at most 1.5 voxels ({1.5 * voxel:.4g} mm) apart, {count} points per cell"
        )
    else:
        corners = nodes[body.cells[:, :8]]  # (ncell, 8, 3)
        for edges in _EDGES_BY_DIRECTION:  # n points along the longest edge per direction
            length = np.linalg.norm(corners[:, edges[:, 0]] - corners[:, edges[:, 1]], axis=-1)
            count *= max(1, int(np.ceil(float(length.max()) / voxel)))
        longest = f"its longest cells are {count ** (1 / 3):.3g} voxels ({voxel:.4g} mm) across"
    points = count * body.ncell
    if points > max_points:
        gib = points * (_BYTES_PER_POINT + _BYTES_PER_POINT_BASIS * body.nbasis) / 2**30
        raise SchemaError(
            f"tracking this mesh would place {points:.3g} constraint points (~{gib:.3g} GiB; "
            f"limit max_points={max_points:.3g}): {longest}{hint or ''}; refine the "
            "mesh (smaller cells) or check its units (mm)"
        )


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


class Body:
    """A hyperelastic body discretised with hexahedral or tetrahedral finite elements.

    Parameters
    ----------
    mesh : skfem.MeshHex1, skfem.MeshHex2, skfem.MeshTet1, skfem.MeshTet2 or MeshSpec
        The reference configuration (mm): a scikit-fem hexahedral or tetrahedral mesh
        (``MeshHex2``: curved hexahedra for hex20, ``MeshTet2``: curved quadratic
        tetrahedra) or a
        :class:`~harpx.mechanics.mesh.MeshSpec` from the builders in
        :mod:`harpx.mechanics.mesh`. A :class:`meshio.Mesh` goes through
        :meth:`from_meshio`; a mesh file through :func:`harpx.io.mesh.read_body`.
    material : object
        Material with ``isochoric_response(F, fiber)``, ``volumetric(J)``, ``kappa`` and
        ``needs_fibers`` (e.g. :class:`~harpx.mechanics.materials.NeoHookean`).
    fibers : array_like of shape (ncell, 3) or (ncell, nqp, 3), or callable, optional
        Reference fibre directions, normalised here: per cell, per quadrature point, or a
        function ``fibers(X) -> (n, 3)`` of reference positions ``X`` (n, 3) in mm,
        evaluated at the body's quadrature points. Needed by fibre materials, active
        contraction and fibre growth.
    regions : dict of str to array of int, optional
        Named cell sets. Defaults to the mesh's regions/subdomains or ``{"body": all}``.
    element : {"hex8", "hex20", "tet4", "tet10"}, optional
        Trilinear hexahedron (2x2x2 Gauss points), 20-node serendipity hexahedron (3x3x3),
        linear tetrahedron (1 point) or quadratic tetrahedron (14 points). Default: what the
        mesh implies (hex8 for ``MeshHex1``, hex20 for ``MeshHex2``, tet4 for ``MeshTet1``,
        tet10 for ``MeshTet2``).
    active : ActiveContraction, optional
        Active fibre stress law (``response(F, fiber, t_max)``).
    t_max : float or dict of str to float, optional
        Activation level in kPa: a scalar, or per region (cells outside every named
        region get 0). Defaults to ``active.t_max``.
    growth : FiberGrowth or array_like of shape (ncell,), optional
        Growth along the fibres, ``F = Fe Fg`` with ``Fg = I + (θ - 1) f0 ⊗ f0``: a uniform
        law or one stretch θ per cell (dimensionless).
    boundaries : dict of str to array of int, optional
        Named facet sets (columns of ``mesh.facets``). Defaults to the mesh's boundaries.
    volumetric : {"mean-dilatation", "linear-dilatation", "nodal-dilatation", "pointwise"}, optional
        Treatment of the volumetric energy:

        * mean dilatation: element-constant dilatation and pressure (three-field,
          locking-free; Q1/P0, Q2/P0, and P2/P0 for tet10);
        * linear dilatation: element-linear dilatation and pressure (Q2/P1-disc, hex20
          only, locking-free and optimal order). Switch to it for hex20 in bending with
          fewer than about six cells through the thickness, where Q2/P0 is too soft: on the
          Land et al. 2015 beam (10 x 1 x 1 mm, 2 cells thick) Q2/P0 is 14 % and Q2/P1
          0.7 % off the reference deflection. Q2/P0 stays the default: it is cheaper and
          the tracking scenes were tuned with it;
        * nodal dilatation (tetrahedra): the volume change averaged over the cells around
          each vertex, weighted by the vertex's linear shape function, with a continuous
          linear pressure: tet4 P1/P1 (Bonet & Burton 1998) and tet10 P2/P1 (Taylor–Hood
          with a lumped pressure mass), locking-free. For tet10 it is the accurate choice in
          bending: on the Land et al. 2015 beam -2.1 % / -0.56 % with 60 / 480 tetrahedra,
          where P2/P0 (``"mean-dilatation"``) is +38 % / +5.1 % (first order, too soft).
          P2/P0 has about 5 times fewer stiffness entries (the vertex pressure couples the
          dofs of all cells around a vertex): switch to it only on fine meshes without
          bending (many cells through every wall), or for compressible materials, where the
          lumping limits P2/P1 to the same L2 rate (1.6);
        * pointwise: the plain displacement formulation; locks for nearly incompressible
          materials.

        Default: the element's first locking-free one (nodal dilatation for tet4 and tet10,
        mean dilatation for the hexahedra).

    Attributes
    ----------
    ndof : int
        Number of displacement dofs (3 per dof node).
    ncell, nqp : int
        Number of cells and of quadrature points per cell (8 for hex8, 27 for hex20, 1 for
        tet4, 14 for tet10).
    nodes : ndarray, shape (nvertex, 3)
        Mesh vertices, mm.
    dof_points : ndarray, shape (n_dof_nodes, 3)
        Positions of all dof nodes (vertices, then edge nodes for hex20 and tet10), mm.
    node_dofs : ndarray, shape (n_dof_nodes, 3)
        Dof ids of the x, y, z displacement of each dof node.
    cells : ndarray, shape (ncell, 8), (ncell, 20), (ncell, 4) or (ncell, 10)
        Dof-node ids per cell in VTK/meshio ``hexahedron``/``hexahedron20``/``tetra``/
        ``tetra10`` order.
    element_dofs : ndarray, shape (ncell, nbasis, 3)
        Dof ids per cell, basis function and component (assembly order).
    grad_N : ndarray, shape (ncell, nqp, nbasis, 3)
        Reference gradients ``dN_a/dX_J`` (1/mm).
    dV : ndarray, shape (ncell, nqp)
        Reference volume of each quadrature point, mm³.
    cell_volume : ndarray, shape (ncell,)
        Reference cell volumes, mm³.
    fibers_qp : ndarray, shape (ncell, nqp, 3) or None
        Unit fibres at the quadrature points.
    t_max : ndarray, shape (ncell,) or None
        Active-stress level per cell, kPa.
    growth_tensor : ndarray, shape (ncell, nqp, 3, 3) or None
        ``Fg`` at the quadrature points.
    growth_jacobian : ndarray, shape (ncell,) or None
        Volume average of ``det Fg`` per cell.
    mesh_quality : MeshQuality or None
        Quality report of a mesh made from a segmentation
        (:func:`~harpx.mechanics.segmentation.body_from_segmentation`), else None.

    Examples
    --------
    >>> from harpx.mechanics.body import Body
    >>> from harpx.mechanics.mesh import box
    >>> from harpx.mechanics.materials import NeoHookean
    >>> body = Body(box((1.0, 1.0, 1.0), (2, 2, 2)), NeoHookean(c1=1.0, kappa=120.0))
    >>> body.ndof, body.nqp, float(body.cell_volume.sum())
    (81, 8, 1.0)
    """

    def __init__(
        self,
        mesh: Any,
        material: Any,
        *,
        fibers: ArrayLike | Callable[[FloatArray], ArrayLike] | None = None,
        regions: Mapping[str, ArrayLike] | None = None,
        element: ElementName | None = None,
        active: Any = None,
        t_max: float | Mapping[str, float] | None = None,
        growth: Any = None,
        boundaries: Mapping[str, ArrayLike] | None = None,
        volumetric: Volumetric | None = None,
    ) -> None:
        spec_regions: Mapping[str, ArrayLike] = {}
        spec_boundaries: Mapping[str, ArrayLike] = {}
        if isinstance(mesh, MeshSpec):
            spec_regions, spec_boundaries = mesh.regions, mesh.boundaries
            if fibers is None:
                fibers = mesh.fibers
            mesh = mesh.mesh
        elif isinstance(mesh, str | os.PathLike):
            raise TypeError(
                f"mesh is a file path ({os.fspath(mesh)!r}); read it with "
                "harpx.io.mesh.read_body(path, material, ...), which returns the Body"
            )
        elif isinstance(mesh, meshio.Mesh):
            raise TypeError("mesh is a meshio.Mesh; build the body with Body.from_meshio(mesh)")
        if isinstance(mesh, skfem.MeshTet1):
            mesh = _orient_tets(mesh)
        if not isinstance(mesh, (skfem.MeshHex1, skfem.MeshTet1)) or (
            isinstance(mesh, skfem.MeshHex1) and type(mesh) not in _HEX20_MESHES
        ):
            raise TypeError(
                f"mesh must be a skfem.MeshHex1, MeshHex2, MeshTet1 or MeshTet2 or a MeshSpec, got "
                f"{type(mesh).__name__!r}; build one with harpx.mechanics.mesh.box/cylinder "
                "(and tetrahedralize for tetrahedra), or read a mesh file with "
                "harpx.io.mesh.read_body"
            )
        if element is None:
            element = default_element(mesh)
        if element not in ELEMENTS:
            raise ValueError(f"element={element!r} is not one of {sorted(ELEMENTS)!r}")
        kind = ELEMENTS[element]
        if not isinstance(mesh, kind.meshes) or (
            isinstance(mesh, skfem.MeshHex2) and element != "hex20"
        ):
            raise ValueError(
                f"element={element!r} needs a {' or '.join(m.__name__ for m in kind.meshes)} "
                f"mesh, got {type(mesh).__name__!r}; pick the element that matches the cells "
                f"(or omit element= to use {default_element(mesh)!r})"
            )
        if volumetric is None:
            volumetric = kind.volumetric[0]
        if volumetric not in _VOLUMETRIC:
            raise ValueError(f"volumetric={volumetric!r} must be one of {list(_VOLUMETRIC)!r}")
        if volumetric not in kind.volumetric:
            raise ValueError(
                f"volumetric={volumetric!r} is not available for element={element!r}; "
                f"choose one of {list(kind.volumetric)!r} (Q1/P1 and P1/P0 are not inf-sup "
                "stable and lock, tet10 P2/P1-disc too; linear dilatation needs hex20, nodal "
                "dilatation tetrahedra)"
            )
        mesh = cast(Any, mesh)  # skfem meshes are untyped
        self._caches: dict[str, Any] = {}
        self.mesh_quality: MeshQuality | None = None
        self.mesh = mesh
        self.material = material
        self.element = element
        self.volumetric = volumetric
        self.active = active
        self.ncell = int(mesh.nelements)

        # the cells' vertices (a MeshTet2 / MeshHex2 also holds its geometry nodes in mesh.p)
        curved = isinstance(mesh, (skfem.MeshTet2, skfem.MeshHex2))
        nvert = int(mesh.nvertices) if curved else mesh.p.shape[1]
        vertices = np.asarray(mesh.p)[:, :nvert]
        check_nodes(vertices.T, np.asarray(mesh.t).T, nvertex=int(mesh.t.shape[0]))
        pairs = coincident_nodes(vertices.T)
        if pairs.size:
            warnings.warn(
                f"mesh has {pairs.shape[0]} pairs of coincident nodes, e.g. nodes "
                f"{pairs[0].tolist()} at {vertices[:, pairs[0, 0]].tolist()} mm: the "
                "cells on either side are not connected and move independently; if that is "
                "not a deliberate cut, merge them (mesh = mesh.remove_duplicate_nodes())",
                CoincidentNodesWarning,
                stacklevel=2,
            )
        _check_cells(mesh)
        check_unused_nodes(vertices.shape[1], np.asarray(mesh.t).T)
        factory, intorder, nqp = kind.factory, kind.intorder, kind.nqp
        self.kind = kind
        self._scalar_element = factory()
        self._intorder = intorder
        sb = skfem.CellBasis(mesh, self._scalar_element, intorder=intorder)
        if sb.X.shape[1] != nqp:  # pragma: no cover - guards the Gauss rule choice
            raise RuntimeError(f"expected {nqp} quadrature points, skfem gave {sb.X.shape[1]}")
        self.scalar_basis = sb
        self.nqp = nqp
        self.nbasis = int(sb.Nbfun)
        grads = np.stack([sb.basis[j][0].grad for j in range(self.nbasis)])  # (nb,3,nel,nq)
        self.grad_N: FloatArray = np.ascontiguousarray(grads.transpose(2, 3, 0, 1))
        self.dV: FloatArray = np.ascontiguousarray(sb.dx)
        self.cell_volume: FloatArray = self.dV.sum(axis=1)
        self._N_values = np.stack(
            [np.asarray(sb.basis[j][0])[0] for j in range(self.nbasis)]
        )  # (nb,nq)
        cell_sdofs = np.ascontiguousarray(sb.element_dofs.T.astype(np.int64))  # (nel, nb)
        self.cell_scalar_dofs: IntArray = cell_sdofs
        self.element_dofs: IntArray = 3 * cell_sdofs[:, :, None] + np.arange(3)
        self.n_dof_nodes = int(sb.N)
        self.ndof = 3 * self.n_dof_nodes
        # a MeshHex2's face and cell geometry nodes carry no dofs: vertices only
        self.nodes: FloatArray = np.ascontiguousarray(
            vertices.T if isinstance(mesh, skfem.MeshHex2) else mesh.p.T
        )
        self.dof_points: FloatArray = np.ascontiguousarray(sb.doflocs.T)
        self.node_dofs: IntArray = 3 * np.arange(self.n_dof_nodes)[:, None] + np.arange(3)
        self.cells: IntArray = self._vtk_cells()
        # linear (P1) shape functions of the cell's vertices at the Gauss points: the
        # weights of the nodal dilatation (tetrahedra; skfem's reference vertices 0, e1, e2, e3)
        Xr = np.asarray(sb.X)  # (3, nqp) reference coordinates
        self.vertex_weights: FloatArray = np.ascontiguousarray(
            np.vstack([1.0 - Xr.sum(axis=0), Xr]).T
        )

        # regions and boundaries
        if regions is None:
            regions = spec_regions or (mesh.subdomains or {})
        self.regions: dict[str, IntArray] = {
            k: np.asarray(v, dtype=np.int64) for k, v in regions.items()
        } or {"body": np.arange(self.ncell)}
        for name, ids in self.regions.items():
            if ids.size and (ids.min() < 0 or ids.max() >= self.ncell):
                raise ValueError(
                    f"region {name!r} has cell ids outside [0, {self.ncell}); check the mesh"
                )
        if boundaries is None:
            boundaries = spec_boundaries or (mesh.boundaries or {})
        self.boundaries: dict[str, IntArray] = {
            k: np.asarray(v, dtype=np.int64) for k, v in boundaries.items()
        }

        # fibres
        self.fibers: FloatArray | None = None
        self.fibers_qp: FloatArray | None = None
        if callable(fibers):
            X = self.quadrature_points
            fibers = np.asarray(fibers(X.reshape(-1, 3)), dtype=np.float64)
            if fibers.shape != (self.ncell * nqp, 3):
                raise ValueError(
                    f"the fibers function returned shape {fibers.shape!r} for "
                    f"{self.ncell * nqp} points; expected ({self.ncell * nqp}, 3), one "
                    "direction per reference point"
                )
            fibers = fibers.reshape(self.ncell, nqp, 3)
        if fibers is not None:
            f = kinematics.unit_fibers(fibers)
            if f.shape == (self.ncell, 3):
                fq = np.broadcast_to(f[:, None, :], (self.ncell, nqp, 3))
            elif f.shape == (self.ncell, nqp, 3):
                fq = f
            else:
                raise ValueError(
                    f"fibers has shape {f.shape!r}; expected ({self.ncell}, 3) per cell or "
                    f"({self.ncell}, {nqp}, 3) per quadrature point"
                )
            self.fibers = f
            self.fibers_qp = np.ascontiguousarray(fq)
        needs = bool(getattr(material, "needs_fibers", False))
        for what, needed in (
            (f"material {type(material).__name__}", needs),
            ("active contraction", active is not None),
            ("fibre growth", growth is not None),
        ):
            if needed and self.fibers_qp is None:
                raise ValueError(
                    f"{what} needs 'fibers' but none were given; pass fibers=(ncell, 3) "
                    "unit vectors (or use a mesh builder that provides them)"
                )

        # active stress level per cell
        self.t_max: FloatArray | None = None
        if active is not None:
            self.set_t_max(getattr(active, "t_max", 0.0) if t_max is None else t_max)
        elif t_max is not None:
            raise ValueError("t_max was given without an active contraction law (active=None)")

        # growth
        self.growth: Any = None
        self.growth_tensor: FloatArray | None = None
        self.growth_jacobian: FloatArray | None = None
        self.set_growth(growth)

    # ------------------------------------------------------------------ set-up helpers
    def set_t_max(self, t_max: float | Mapping[str, float] | ArrayLike) -> None:
        """Set the active-stress level.

        Parameters
        ----------
        t_max : float, dict of str to float, or array_like of shape (ncell,)
            Activation in kPa: uniform, per region (other cells 0), or per cell.
        """
        if self.active is None:
            raise ValueError("this body has no active contraction law; pass active=... to Body")
        if isinstance(t_max, Mapping):
            values = np.zeros(self.ncell)
            for name, value in t_max.items():
                if name not in self.regions:
                    raise ValueError(
                        f"t_max names region {name!r}, which is not one of {sorted(self.regions)!r}"
                    )
                values[self.regions[name]] = float(value)
        else:
            values = np.broadcast_to(np.asarray(t_max, dtype=np.float64), (self.ncell,)).copy()
        self.t_max = values

    def set_growth(self, growth: Any) -> None:
        """Set the growth (``F = Fe Fg``), or remove it with ``None``.

        Parameters
        ----------
        growth : FiberGrowth, GrowthField, array_like of shape (ncell,), or None
            A law or field with ``tensor(fibers_qp) -> Fg`` (e.g.
            :class:`~harpx.mechanics.materials.FiberGrowth`,
            :class:`~harpx.mechanics.growth.GrowthField`), or one fibre stretch θ per cell
            (``Fg = I + (θ - 1) f0 ⊗ f0``, dimensionless, > 0).

        Notes
        -----
        Sets ``growth``, ``growth_tensor`` (ncell, nqp, 3, 3) and ``growth_jacobian``, the
        volume average of ``det Fg`` per cell (the growth Jacobian is computed here only).
        """
        if growth is None:
            self.growth, self.growth_tensor, self.growth_jacobian = None, None, None
            return
        fibers = self.fibers_qp
        if fibers is None:
            if not hasattr(growth, "tensors"):
                raise ValueError(
                    "fibre growth needs 'fibers' but none were given; pass fibers=(ncell, 3) "
                    "unit vectors (or use a mesh builder that provides them)"
                )
            fibers = np.zeros((self.ncell, self.nqp, 3))  # a tensor field needs no fibres
        if hasattr(growth, "tensor"):
            Fg = np.asarray(growth.tensor(fibers), dtype=np.float64)
            Fg = np.broadcast_to(Fg, (self.ncell, self.nqp, 3, 3))
        else:
            theta = np.asarray(growth, dtype=np.float64)
            if theta.shape != (self.ncell,) or np.any(theta <= 0):
                raise ValueError(
                    f"growth stretch array has shape {theta.shape!r}; expected "
                    f"({self.ncell},) positive values, or a FiberGrowth"
                )
            Fg = kinematics.growth_tensor(fibers, theta[:, None])
        self.growth = growth
        self.growth_tensor = np.ascontiguousarray(Fg)
        Jg = np.linalg.det(self.growth_tensor)
        self.growth_jacobian = (Jg * self.dV).sum(axis=1) / self.cell_volume

    def _vtk_cells(self) -> IntArray:
        if isinstance(self.mesh, skfem.MeshTet1):
            corners = self.mesh.t.T.astype(np.int64)  # skfem and VTK agree on tetrahedra
        else:
            corners = self.mesh.t.T[:, HEX_MAPPING[:8]].astype(np.int64)  # VTK corner order
        vtk_edges = self.kind.vtk_edges
        nc = corners.shape[1]
        if vtk_edges.shape[0] == 0:
            return corners
        # match each VTK edge to the element's edge dofs by the edge's end vertices
        edge_dofs = self.cell_scalar_dofs[:, nc:]  # (nel, nedge)
        if isinstance(self.mesh, (skfem.MeshTet2, skfem.MeshHex2)):  # edge dofs follow vertices
            ends = self.mesh.edges[:, edge_dofs - int(self.mesh.nvertices)]  # (2, nel, nedge)
            mid = 0.5 * (self.nodes[ends[0]] + self.nodes[ends[1]])
        else:
            mid = self.dof_points[edge_dofs]
        want = 0.5 * (
            self.nodes[corners[:, vtk_edges[:, 0]]] + self.nodes[corners[:, vtk_edges[:, 1]]]
        )
        d = np.linalg.norm(want[:, :, None, :] - mid[:, None, :, :], axis=-1)
        order = np.argmin(d, axis=2)
        edges = np.take_along_axis(edge_dofs, order, axis=1)
        return np.concatenate([corners, edges], axis=1)

    # ------------------------------------------------------------ read-only accessors
    @property
    def scalar_element(self) -> skfem.Element:
        """The scalar scikit-fem element (``ElementHex1`` for hex8, ``ElementHexS2`` hex20)."""
        return self._scalar_element

    @property
    def basis_values(self) -> FloatArray:
        """Shape-function values at the reference Gauss points, shape (nbasis, nqp)."""
        return self._N_values

    def cell_average(self, q: FloatArray) -> FloatArray:
        """Volume average per cell of a quadrature-point field ``q`` (ncell, nqp, ...)."""
        return self._cell_average(q)

    def cached(self, key: str, build: Callable[[], _T]) -> _T:
        """Derived data kept with the body (sparsity pattern, pressure space), built once.

        Parameters
        ----------
        key : str
            Name of the cached item.
        build : callable
            ``build()`` computes it the first time.

        Returns
        -------
        object
            The cached item.
        """
        if key not in self._caches:
            self._caches[key] = build()
        return self._caches[key]

    @functools.cached_property
    def basis(self) -> skfem.CellBasis:
        """``skfem.CellBasis`` of ``ElementVector`` on the body's Gauss rule (built on demand)."""
        return skfem.CellBasis(
            self.mesh, skfem.ElementVector(self._scalar_element), intorder=self._intorder
        )

    @property
    def quadrature_points(self) -> FloatArray:
        """Reference positions of the quadrature points, shape (ncell, nqp, 3), mm."""
        return np.ascontiguousarray(
            np.asarray(self.scalar_basis.global_coordinates()).transpose(1, 2, 0)
        )

    # ------------------------------------------------------------------ field helpers
    def _check_u(self, u: ArrayLike) -> FloatArray:
        u = np.asarray(u, dtype=np.float64)
        if u.shape != (self.ndof,):
            raise ValueError(f"u has shape {u.shape!r}; expected ({self.ndof},) dofs")
        return u

    def nodal_displacement(self, u: ArrayLike) -> FloatArray:
        """Displacement of every dof node, shape (n_dof_nodes, 3), mm."""
        return self._check_u(u).reshape(-1, 3)

    def facet_dofs(self, name: str | ArrayLike, components: Sequence[int] = (0, 1, 2)) -> IntArray:
        """Dof ids on a named boundary (or on given facet ids).

        Parameters
        ----------
        name : str or array_like of int
            Boundary name from ``body.boundaries`` or facet ids.
        components : sequence of int, default (0, 1, 2)
            Displacement components (0 = x, 1 = y, 2 = z).

        Returns
        -------
        ndarray of int
            Sorted dof ids.
        """
        facets = self.facets(name)
        sd = np.unique(self.scalar_basis.get_dofs(facets=facets).all())
        comps = np.asarray(components, dtype=np.int64)
        if comps.size == 0 or comps.min() < 0 or comps.max() > 2:
            raise ValueError(f"components={components!r} must be a non-empty subset of (0, 1, 2)")
        return np.sort((3 * sd[:, None] + comps[None, :]).ravel())

    def facets(self, name: str | ArrayLike) -> IntArray:
        """Facet ids of a named boundary (or the given ids, checked)."""
        if isinstance(name, str):
            if name not in self.boundaries:
                raise KeyError(
                    f"no boundary named {name!r}; this body has {sorted(self.boundaries)!r}"
                )
            return self.boundaries[name]
        ids = np.asarray(name, dtype=np.int64)
        if ids.ndim != 1 or (
            ids.size and (ids.min() < 0 or ids.max() >= self.mesh.facets.shape[1])
        ):
            raise ValueError("facet ids must be a 1-D array of valid mesh facet indices")
        return ids

    def element_displacement(self, u: ArrayLike) -> FloatArray:
        """Displacement of each cell's dof nodes, shape (ncell, nbasis, 3), mm."""
        return self._check_u(u)[self.element_dofs]

    def deformation_gradient(self, u: ArrayLike) -> FloatArray:
        """``F = I + Grad u`` at every quadrature point, shape (ncell, nqp, 3, 3)."""
        ue = self.element_displacement(u)
        F = np.einsum("eai,eqaJ->eqiJ", ue, self.grad_N, optimize=True)
        F += np.eye(3)
        return F

    def jacobian(self, u: ArrayLike) -> FloatArray:
        """``J = det F`` at every quadrature point, shape (ncell, nqp)."""
        return np.linalg.det(self.deformation_gradient(u))

    def displacement_at(self, u: ArrayLike, points: ArrayLike) -> FloatArray:
        """Displacement (mm) at arbitrary reference points (mm), NaN outside the mesh.

        See :func:`harpx.mechanics.locate.displacement_at`.
        """
        from harpx.mechanics.locate import displacement_at

        return displacement_at(self, u, points)

    def _cell_average(self, q: FloatArray) -> FloatArray:
        w = self.dV / self.cell_volume[:, None]
        return np.einsum("eq,eq...->e...", w, q)

    def green_strain(self, u: ArrayLike) -> FloatArray:
        """Volume-averaged Green--Lagrange strain per cell, shape (ncell, 3, 3)."""
        return self._cell_average(kinematics.green_strain(self.deformation_gradient(u)))

    def fiber_stretch(self, u: ArrayLike) -> FloatArray:
        """Volume-averaged fibre stretch ``|F f0|`` per cell, shape (ncell,)."""
        if self.fibers_qp is None:
            raise ValueError("fiber_stretch needs 'fibers'; pass fibers=... to Body")
        lam = kinematics.fiber_stretch(self.deformation_gradient(u), self.fibers_qp)
        return self._cell_average(lam)

    def interpolation_operator(
        self, intorder: int
    ) -> tuple[FloatArray, FloatArray, sparse.csr_matrix]:
        """Quadrature points, weights and the displacement interpolation matrix.

        Parameters
        ----------
        intorder : int
            skfem integration order (polynomial degree integrated exactly); Gauss rules
            with ``n`` points per direction have order ``2n - 1``.

        Returns
        -------
        X_q : ndarray, shape (nq, 3)
            Reference positions of the points, cell-major (all points of cell 0 first), mm.
        w_q : ndarray, shape (nq,)
            Reference volume of each point, mm³ (sums to the body volume).
        N : scipy.sparse.csr_matrix, shape (3 nq, ndof)
            ``(N @ u).reshape(nq, 3)`` is the displacement at ``X_q``, mm.
        """
        b = skfem.CellBasis(self.mesh, self._scalar_element, intorder=int(intorder))
        npt = b.X.shape[1]
        X_q = np.asarray(b.global_coordinates()).transpose(1, 2, 0).reshape(-1, 3)
        w_q = np.asarray(b.dx, dtype=np.float64).ravel()
        phi = np.stack(
            [np.asarray(b.basis[j][0]) for j in range(self.nbasis)], axis=-1
        )  # (nel,nq,nb)
        nq = self.ncell * npt
        rows = (
            3 * np.arange(nq).reshape(self.ncell, npt)[:, :, None, None]
            + np.arange(3)[None, None, None, :]
        )
        cols = 3 * self.cell_scalar_dofs[:, None, :, None] + np.arange(3)[None, None, None, :]
        rows, cols = np.broadcast_arrays(rows, cols)
        vals = np.broadcast_to(phi[..., None], rows.shape)
        N = sparse.csr_matrix(
            (vals.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * nq, self.ndof)
        )
        return np.ascontiguousarray(X_q), w_q, N

    # ------------------------------------------------------------------ I/O
    def to_meshio(
        self, u: ArrayLike | None = None, *, point_data: Mapping[str, ArrayLike] | None = None
    ) -> meshio.Mesh:
        """The mesh (hexahedron or tetra cells) as a :class:`meshio.Mesh`.

        Parameters
        ----------
        u : array_like, shape (ndof,), optional
            Displacement (mm), written as point data ``"displacement"`` at the vertices.
        point_data : dict, optional
            Extra point data (one row per vertex).

        Returns
        -------
        meshio.Mesh
            Named boundaries and regions are encoded as skfem cell data; fibres (per cell) as
            cell data ``"fiber"``. Curved hexahedra (``MeshHex2``) are written by their
            vertices (``hexahedron``): the curved geometry is not kept.
        """
        pdata = dict(point_data or {})
        if u is not None:
            pdata["displacement"] = self.nodal_displacement(u)[: self.nodes.shape[0]]
        cdata: dict[str, list[Any]] = {}
        if self.fibers is not None and self.fibers.shape == (self.ncell, 3):
            cdata["fiber"] = [self.fibers]
        mesh = self.mesh
        if isinstance(mesh, skfem.MeshHex2):  # the vertices only: straight hexahedra
            mesh = skfem.MeshHex1(np.ascontiguousarray(self.nodes.T), mesh.t)
        if self.regions or self.boundaries:
            mesh = dataclasses.replace(
                mesh,
                _boundaries={k: v.astype(np.int32) for k, v in self.boundaries.items()} or None,
                _subdomains={k: v.astype(np.int32) for k, v in self.regions.items()} or None,
            )
        return skfem.io.meshio.to_meshio(mesh, point_data=pdata or None, cell_data=cdata)

    @classmethod
    def from_meshio(
        cls, mesh: meshio.Mesh, material: Any, *, source: str = "the meshio mesh", **kwargs: Any
    ) -> Body:
        """Build a body from a :class:`meshio.Mesh` (the inverse of :meth:`to_meshio`).

        Parameters
        ----------
        mesh : meshio.Mesh
            Reference configuration (mm) with one block of ``hexahedron``,
            ``hexahedron20`` (reduced to its corners: straight edges), ``tetra`` or
            ``tetra10`` (curved edges kept) cells; the first such block is used, other
            blocks and points no cell uses are dropped. Cell data ``fiber`` (one vector per
            cell) becomes the fibres unless ``fibers=`` is given; named boundaries and
            regions written by :meth:`to_meshio` are kept.
        material : object
            The material (see :class:`Body`).
        source : str, default "the meshio mesh"
            What the mesh is called in error messages (e.g. its file name).
        **kwargs
            Further :class:`Body` parameters (``element``, ``fibers``, ...).

        Returns
        -------
        Body

        Raises
        ------
        ValueError
            If the mesh has no hexahedra or tetrahedra.

        See Also
        --------
        harpx.io.mesh.read_body : reads a mesh file into a Body.

        Examples
        --------
        >>> from harpx.mechanics.mesh import box
        >>> from harpx.mechanics.materials import NeoHookean
        >>> body = Body(box((1.0, 1.0, 1.0), (2, 2, 2)), NeoHookean(c1=1.0, kappa=120.0))
        >>> back = Body.from_meshio(body.to_meshio(), body.material)
        >>> bool((back.nodes == body.nodes).all()), back.ncell
        (True, 8)
        """
        skmesh, fibers = _skfem_mesh(mesh, source)
        if kwargs.get("fibers") is None:
            kwargs["fibers"] = fibers
        return cls(skmesh, material, **kwargs)

    def __repr__(self) -> str:
        return (
            f"Body({self.element}, ncell={self.ncell}, ndof={self.ndof}, "
            f"material={type(self.material).__name__}, volumetric={self.volumetric!r})"
        )
