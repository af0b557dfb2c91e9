"""Mesh builders: boxes, cylinders, tubes, curved hexahedra, tetrahedra, all named.

Every builder returns a :class:`~harpx.mechanics.meshspec.MeshSpec`: a scikit-fem
:class:`skfem.MeshHex1` plus named cell regions, optional per-cell fibre directions and
named boundary facets. The skfem mesh carries the same names (``mesh.boundaries`` /
``mesh.subdomains``) so that ``skfem.io.meshio`` round trips keep them.

Hexahedra are built in VTK/meshio vertex order (bottom quad counter-clockwise seen from +z,
then the top quad) and converted to scikit-fem's local order, so every element has a
positive Jacobian. Units: mm.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import skfem
from numpy.typing import ArrayLike, NDArray

from harpx.mechanics.cells import _orient_tets, vtk_corners
from harpx.mechanics.meshspec import (
    _VTK_TO_SKFEM,  # noqa: F401  (older code imports it from here)
    MeshSpec,
    _finish,
    check_nodes,
    check_unused_nodes,
    coincident_nodes,
    facets_where,
    hex_mesh,
    labelled_spec,
)

__all__ = [
    "MeshSpec",
    "box",
    "check_nodes",
    "check_unused_nodes",
    "coincident_nodes",
    "curved_hex_mesh",
    "cylinder",
    "tube",
    "hex_mesh",
    "facets_where",
    "labelled_spec",
    "tetrahedralize",
]


def curved_hex_mesh(
    mesh: skfem.MeshHex1,
    centre: Callable[[NDArray[np.int64]], ArrayLike] | None = None,
) -> skfem.MeshHex2:
    """A curved (isoparametric) hexahedral mesh: triquadratic 27-node geometry.

    The geometry of every cell is the triquadratic map through its 8 vertices and one
    node per edge, face and cell; a hex20 :class:`~harpx.mechanics.body.Body` on it is
    isoparametric (serendipity displacement on curved cells), so edge nodes placed on a
    curved surface (a cylinder, an ellipsoid) make the cell faces follow that surface to
    third order in the cell size instead of cutting it with flat faces.

    Parameters
    ----------
    mesh : skfem.MeshHex1
        Vertices (mm), cells, boundaries and subdomains.
    centre : callable, optional
        ``centre(vertices) -> (n, 3)``: the position (mm) of the geometry node at the
        parametric centre of ``n`` entities given by their vertex ids ``vertices``
        (n, k): ``k = 2`` the ends of each edge of ``mesh.edges``, ``k = 4`` the corners
        of each face of ``mesh.facets``, ``k = 8`` the corners of each cell. Builders that
        know the analytic map of their parameter space put the nodes there (see
        :func:`tube` and :func:`~harpx.anatomy.ventricle.ventricle` with
        ``curved=True``). Default: the vertex mean (straight edges, flat faces).

    Returns
    -------
    skfem.MeshHex2
        Same vertices, cells, facets, boundaries and subdomains as ``mesh``.

    Raises
    ------
    ValueError
        If ``centre`` does not return one point (3,) per edge, face or cell.

    Examples
    --------
    >>> from harpx.mechanics.mesh import box, curved_hex_mesh
    >>> m = curved_hex_mesh(box((1.0, 1.0, 1.0), (2, 1, 1)).mesh)
    >>> m.p.shape[1], int(m.nvertices)  # 12 vertices, 20 edges, 11 faces, 2 cells
    (45, 12)
    """
    p = np.asarray(mesh.p, dtype=np.float64)

    def nodes(vertices: NDArray[np.int64]) -> NDArray[np.float64]:
        vertices = np.ascontiguousarray(np.asarray(vertices, dtype=np.int64).T)  # (n, k)
        if centre is None:
            return p[:, vertices].mean(axis=-1)
        x = np.asarray(centre(vertices), dtype=np.float64)
        if x.shape != (vertices.shape[0], 3):
            raise ValueError(
                f"centre returned shape {x.shape!r} for {vertices.shape[0]} entities of "
                f"{vertices.shape[1]} vertices; expected ({vertices.shape[0]}, 3) mm"
            )
        return x.T

    # skfem's ElementHex2 dof order: vertices, edges, facets, cells
    doflocs = np.hstack([p, nodes(mesh.edges), nodes(mesh.facets), nodes(mesh.t)])
    return skfem.MeshHex2(
        doflocs, mesh.t, _boundaries=mesh._boundaries, _subdomains=mesh._subdomains
    )


def _extrude(
    points2d: NDArray[np.float64], quads: NDArray[np.int64], z: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Extrude counter-clockwise quads along z into VTK-ordered hexahedra (layer-major)."""
    n2 = len(points2d)
    nz = len(z)
    pts = np.empty((nz, n2, 3))
    pts[:, :, :2] = points2d[None]
    pts[:, :, 2] = z[:, None]
    layer = np.arange(nz - 1)[:, None, None] * n2
    cells = np.concatenate([quads[None] + layer, quads[None] + layer + n2], axis=2)
    return pts.reshape(-1, 3), cells.reshape(-1, 8)


def box(
    lengths: tuple[float, float, float] = (1.0, 1.0, 1.0),
    divisions: tuple[int, int, int] = (2, 2, 2),
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> MeshSpec:
    """A rectangular box of hexahedra.

    Parameters
    ----------
    lengths : tuple of 3 float, default (1, 1, 1)
        Edge lengths (Lx, Ly, Lz) in mm.
    divisions : tuple of 3 int, default (2, 2, 2)
        Number of elements along x, y, z.
    origin : tuple of 3 float, default (0, 0, 0)
        Corner with the smallest coordinates, mm.

    Returns
    -------
    MeshSpec
        Region ``"body"`` (all cells); facets ``left``/``right`` (x = min/max),
        ``front``/``back`` (y = min/max), ``bottom``/``top`` (z = min/max).

    Raises
    ------
    ValueError
        If a length is not positive or a division count is below 1.

    Examples
    --------
    >>> from harpx.mechanics.mesh import box
    >>> spec = box((2.0, 1.0, 1.0), (2, 1, 1))
    >>> spec.mesh.nelements, sorted(spec.boundaries)[:2], len(spec.boundaries["left"])
    (2, ['back', 'bottom'], 1)
    """
    nx, ny, nz = (int(d) for d in divisions)
    if min(nx, ny, nz) < 1:
        raise ValueError(f"divisions={divisions!r} must all be >= 1")
    L = np.asarray(lengths, dtype=np.float64)
    o = np.asarray(origin, dtype=np.float64)
    if L.shape != (3,) or np.any(L <= 0):
        raise ValueError(f"lengths={lengths!r} must be 3 positive numbers (mm)")
    x = o[0] + np.linspace(0.0, L[0], nx + 1)
    y = o[1] + np.linspace(0.0, L[1], ny + 1)
    z = o[2] + np.linspace(0.0, L[2], nz + 1)
    X, Y = np.meshgrid(x, y, indexing="xy")  # (ny+1, nx+1)
    pts2 = np.column_stack([X.ravel(), Y.ravel()])
    idx = np.arange((ny + 1) * (nx + 1)).reshape(ny + 1, nx + 1)
    quads = np.column_stack(
        [idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()]
    )
    points, cells = _extrude(pts2, quads, z)
    tol = 1e-9 * float(L.max())
    hi = o + L

    def near(d: int, v: float) -> Callable[[NDArray[np.float64]], NDArray[np.bool_]]:
        return lambda p: np.abs(p[:, d] - v) < tol

    tests = {
        "left": (near(0, o[0]), True),
        "right": (near(0, hi[0]), True),
        "front": (near(1, o[1]), True),
        "back": (near(1, hi[1]), True),
        "bottom": (near(2, o[2]), True),
        "top": (near(2, hi[2]), True),
    }
    return _finish(points, cells, {"body": np.arange(len(cells))}, tests)


def _ogrid_2d(
    radius: float, n_radial: int, n_circumferential: int, rings: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """2-D O-grid: square core plus rings; returns points, ccw quads and ring index per quad.

    ``rings`` are the radii of extra rings outside ``radius`` (for the container wall).
    """
    m = n_circumferential // 4
    a = 0.5 * radius / np.sqrt(2.0) * 1.2  # core half-width: corners at 0.6 R
    s = np.linspace(-1.0, 1.0, m + 1)
    # core nodes, slightly rounded towards a circle for better-shaped ring elements
    SX, SY = np.meshgrid(s, s, indexing="xy")
    core = a * np.stack([SX, SY], axis=-1)
    cidx = np.arange((m + 1) ** 2).reshape(m + 1, m + 1)
    cquads = np.column_stack(
        [cidx[:-1, :-1].ravel(), cidx[:-1, 1:].ravel(), cidx[1:, 1:].ravel(), cidx[1:, :-1].ravel()]
    )
    # square boundary, counter-clockwise, starting at the corner (a, -a)
    right = cidx[:, m]  # x = +a, y from -a to +a
    top = cidx[m, ::-1]  # y = +a, x from +a to -a
    left = cidx[::-1, 0]  # x = -a, y from +a to -a
    bottom = cidx[0, :]  # y = -a, x from -a to +a
    loop = np.concatenate([right[:-1], top[:-1], left[:-1], bottom[:-1]])  # 4m ids
    nc = 4 * m
    theta = -0.25 * np.pi + 2.0 * np.pi * np.arange(nc) / nc
    circle = np.column_stack([np.cos(theta), np.sin(theta)])
    sq = core.reshape(-1, 2)[loop]
    radii = np.concatenate([[radius], rings])
    pts = [core.reshape(-1, 2)]
    ring_ids = [loop]
    nxt = (m + 1) ** 2
    for k in range(1, n_radial + 1):  # rings from the square to the circle
        t = k / n_radial
        pts.append((1.0 - t) * sq + t * radius * circle)
        ring_ids.append(nxt + np.arange(nc))
        nxt += nc
    for r in radii[1:]:
        pts.append(r * circle)
        ring_ids.append(nxt + np.arange(nc))
        nxt += nc
    quads = [cquads]
    layer = [np.zeros(len(cquads), dtype=np.int64)]
    j = np.arange(nc)
    for k in range(1, len(ring_ids)):
        inner, outer = ring_ids[k - 1], ring_ids[k]
        quads.append(
            np.column_stack([inner[j], outer[j], outer[(j + 1) % nc], inner[(j + 1) % nc]])
        )
        layer.append(np.full(nc, k, dtype=np.int64))
    return np.concatenate(pts), np.concatenate(quads), np.concatenate(layer)


def cylinder(
    radius: float,
    height: float,
    *,
    n_radial: int = 2,
    n_circumferential: int = 8,
    n_axial: int = 2,
    center: tuple[float, float, float] = (0.0, 0.0, 0.0),
    wall_thickness: float | None = None,
    n_wall: int = 1,
) -> MeshSpec:
    """A solid circular cylinder along z as an O-grid (square core plus rings).

    Parameters
    ----------
    radius : float
        Cylinder radius, mm.
    height : float
        Length along z, mm; the cylinder spans ``center[2]`` to ``center[2] + height``.
    n_radial : int, default 2
        Element rings between the square core and the circle.
    n_circumferential : int, default 8
        Elements around the circumference; a multiple of 4 (the core has
        ``n_circumferential/4`` elements per side).
    n_axial : int, default 2
        Elements along z.
    center : tuple of 3 float, default (0, 0, 0)
        Centre of the bottom face, mm.
    wall_thickness : float, optional
        If given, adds a container wall of this thickness (mm) outside ``radius``: region
        ``"wall"``, facet ``"wall_outer"``; ``"outer"`` is then the (interior) interface.
    n_wall : int, default 1
        Element rings across the wall.

    Returns
    -------
    MeshSpec
        Regions ``"tissue"`` (inside ``radius``) and, with a wall, ``"wall"``; facets
        ``"outer"`` (r = radius), ``"bottom"``, ``"top"`` (and ``"wall_outer"``).

    Raises
    ------
    ValueError
        If ``radius``, ``height`` or ``wall_thickness`` is not positive, or
        ``n_circumferential`` is not a multiple of 4.

    Examples
    --------
    >>> from harpx.mechanics.mesh import cylinder
    >>> spec = cylinder(1.0, 2.0, n_radial=1, n_circumferential=8, n_axial=1)
    >>> spec.mesh.nelements, len(spec.boundaries["outer"])
    (12, 8)
    """
    if n_circumferential % 4 or n_circumferential < 4:
        raise ValueError(f"n_circumferential={n_circumferential!r} must be a multiple of 4")
    if radius <= 0 or height <= 0:
        raise ValueError(f"radius={radius!r} and height={height!r} must be positive (mm)")
    rings = np.array([], dtype=np.float64)
    if wall_thickness is not None:
        if wall_thickness <= 0:
            raise ValueError(f"wall_thickness={wall_thickness!r} must be positive (mm)")
        rings = radius + wall_thickness * np.arange(1, n_wall + 1) / n_wall
    pts2, quads, layer = _ogrid_2d(radius, int(n_radial), int(n_circumferential), rings)
    c = np.asarray(center, dtype=np.float64)
    pts2 = pts2 + c[:2]
    z = c[2] + np.linspace(0.0, height, int(n_axial) + 1)
    points, cells = _extrude(pts2, quads, z)
    cell_layer = np.tile(layer, int(n_axial))
    n_inner = int(n_radial)
    regions = {"tissue": np.nonzero(cell_layer <= n_inner)[0]}
    tol = 1e-9 * max(radius, height)

    def r_of(p: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.hypot(p[:, 0] - c[0], p[:, 1] - c[1])

    tests: dict[str, tuple[Callable[[NDArray[np.float64]], NDArray[np.bool_]], bool]] = {
        "outer": (lambda p: np.abs(r_of(p) - radius) < tol * 10, wall_thickness is None),
        "bottom": (lambda p: np.abs(p[:, 2] - z[0]) < tol, True),
        "top": (lambda p: np.abs(p[:, 2] - z[-1]) < tol, True),
    }
    if wall_thickness is not None:
        regions["wall"] = np.nonzero(cell_layer > n_inner)[0]
        r_out = radius + wall_thickness
        tests["wall_outer"] = (lambda p: np.abs(r_of(p) - r_out) < tol * 10, True)
    return _finish(points, cells, regions, tests)


def tube(
    inner_radius: float,
    outer_radius: float,
    height: float,
    *,
    n_radial: int = 2,
    n_circumferential: int = 8,
    n_axial: int = 1,
    angle: float = 2.0 * np.pi,
    center: tuple[float, float, float] = (0.0, 0.0, 0.0),
    curved: bool = False,
) -> MeshSpec:
    """A thick-walled tube (or a sector of it) along z, structured in (r, θ, z).

    Parameters
    ----------
    inner_radius, outer_radius : float
        Radii A < B, mm.
    height : float
        Length along z, mm.
    n_radial, n_circumferential, n_axial : int
        Elements across the wall, around the sector and along z.
    angle : float, default 2π
        Opening angle of the sector in rad, starting at θ = 0 (the +x axis).
    center : tuple of 3 float, default (0, 0, 0)
        Centre of the bottom face, mm.
    curved : bool, default False
        Return a curved :class:`skfem.MeshHex2` (:func:`curved_hex_mesh`) whose edge,
        face and cell nodes are the images of the parametric midpoints in (r, θ, z), so
        the inner and outer faces lie on the circles; a :class:`~harpx.mechanics.body.Body`
        on it is hex20 (isoparametric). Off: straight-edged ``MeshHex1``.

    Returns
    -------
    MeshSpec
        Region ``"tissue"``; facets ``"inner"``, ``"outer"``, ``"bottom"``, ``"top"`` and,
        for a sector (angle < 2π), ``"start"`` (θ = 0) and ``"end"`` (θ = angle).

    Raises
    ------
    ValueError
        Unless ``0 < inner_radius < outer_radius``.

    Examples
    --------
    >>> from harpx.mechanics.mesh import tube
    >>> spec = tube(1.0, 2.0, 0.5, n_radial=2, n_circumferential=4, angle=np.pi / 2)
    >>> spec.mesh.nelements, len(spec.boundaries["start"])
    (8, 2)
    """
    if not 0 < inner_radius < outer_radius:
        raise ValueError(
            f"need 0 < inner_radius < outer_radius, got {inner_radius!r}, {outer_radius!r} (mm)"
        )
    closed = angle >= 2.0 * np.pi - 1e-12
    nr, nt = int(n_radial), int(n_circumferential)
    r = np.linspace(inner_radius, outer_radius, nr + 1)
    ntheta = nt if closed else nt + 1
    th = angle * np.arange(ntheta) / nt
    R, TH = np.meshgrid(r, th, indexing="xy")  # (ntheta, nr+1)
    c = np.asarray(center, dtype=np.float64)
    pts2 = np.column_stack([R.ravel() * np.cos(TH.ravel()), R.ravel() * np.sin(TH.ravel())]) + c[:2]
    idx = np.arange(ntheta * (nr + 1)).reshape(ntheta, nr + 1)
    j = np.arange(nt)
    jn = (j + 1) % ntheta
    i = np.arange(nr)
    J, I_ = np.meshgrid(j, i, indexing="ij")
    JN = jn[J]
    # counter-clockwise in (x, y): (r_i, θ_j) → (r_i+1, θ_j) → (r_i+1, θ_j+1) → (r_i, θ_j+1)
    quads = np.column_stack(
        [idx[J, I_].ravel(), idx[J, I_ + 1].ravel(), idx[JN, I_ + 1].ravel(), idx[JN, I_].ravel()]
    )
    z = c[2] + np.linspace(0.0, height, int(n_axial) + 1)
    points, cells = _extrude(pts2, quads, z)
    tol = 1e-9 * max(outer_radius, height)

    def r_of(p: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.hypot(p[:, 0] - c[0], p[:, 1] - c[1])

    tests: dict[str, tuple[Callable[[NDArray[np.float64]], NDArray[np.bool_]], bool]] = {
        "inner": (lambda p: np.abs(r_of(p) - inner_radius) < 10 * tol, True),
        "outer": (lambda p: np.abs(r_of(p) - outer_radius) < 10 * tol, True),
        "bottom": (lambda p: np.abs(p[:, 2] - z[0]) < tol, True),
        "top": (lambda p: np.abs(p[:, 2] - z[-1]) < tol, True),
    }
    if not closed:
        n_end = np.array([-np.sin(angle), np.cos(angle)])
        t_end = np.array([np.cos(angle), np.sin(angle)])

        def on_start(p: NDArray[np.float64]) -> NDArray[np.bool_]:
            return (np.abs(p[:, 1] - c[1]) < 10 * tol) & (p[:, 0] - c[0] > 0)

        def on_end(p: NDArray[np.float64]) -> NDArray[np.bool_]:
            q = p[:, :2] - c[:2]
            return (np.abs(q @ n_end) < 10 * tol) & (q @ t_end > 0)

        tests["start"] = (on_start, True)
        tests["end"] = (on_end, True)
    spec = _finish(points, cells, {"tissue": np.arange(len(cells))}, tests)
    if not curved:
        return spec
    # (r, θ, z) of every vertex (the extrusion repeats the 2-D points layer by layer)
    n2 = len(pts2)
    params = np.column_stack([np.tile(R.ravel(), len(z)), np.tile(TH.ravel(), len(z)),
                              np.repeat(z, n2)])  # fmt: skip

    def centre(vertices: NDArray[np.int64]) -> NDArray[np.float64]:
        q = params[vertices]  # (n, k, 3)
        th0 = q[:, :1, 1]
        th = th0 + np.mod(q[:, :, 1] - th0 + np.pi, 2.0 * np.pi) - np.pi  # unwrapped
        r, t, h = q[:, :, 0].mean(axis=1), th.mean(axis=1), q[:, :, 2].mean(axis=1)
        return np.column_stack([c[0] + r * np.cos(t), c[1] + r * np.sin(t), h])

    return dataclasses.replace(spec, mesh=curved_hex_mesh(spec.mesh, centre))


# Kuhn split of a VTK-ordered hexahedron into six tetrahedra around its diagonal 0-6: on a
# consistently oriented grid, neighbouring cells split their shared face along the same
# diagonal, so the tetrahedra are conforming.
_KUHN = np.array(
    [[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]]
)
# the six faces of a VTK hexahedron, each counter-clockwise seen from outside
_HEX_FACES = np.array(
    [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
)


def _keys(triples: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    t = np.sort(triples, axis=-1).astype(np.int64)
    return (t[..., 0] * n + t[..., 1]) * n + t[..., 2]


def tetrahedralize(spec: MeshSpec) -> MeshSpec:
    """Split a hexahedral :class:`MeshSpec` into conforming tetrahedra.

    Each hexahedron becomes six tetrahedra (Kuhn split around one main diagonal) when that
    is conforming across all shared faces (structured, consistently oriented grids such as
    the builders' boxes and tubes); otherwise twelve: every face is split along the
    diagonal through its lowest-numbered vertex (the same choice from both sides, so always
    conforming) and each triangle is joined to a new point at the cell centre (e.g. the
    O-grid core of :func:`cylinder` or the ventricle's apex). Regions, fibres (per cell)
    and named boundaries carry over.

    Parameters
    ----------
    spec : MeshSpec
        Hexahedral mesh (mm).

    Returns
    -------
    MeshSpec
        A :class:`skfem.MeshTet1` with positively oriented cells. Use
        :func:`harpx.mechanics.cells.curved_tet_mesh` (or ``Body(..., element="tet10")``)
        for quadratic tetrahedra.

    Raises
    ------
    TypeError
        If ``spec`` is not a hexahedral mesh.

    Examples
    --------
    >>> from harpx.mechanics.mesh import box, tetrahedralize
    >>> tets = tetrahedralize(box((1.0, 1.0, 1.0), (2, 2, 2)))
    >>> tets.mesh.nelements, sorted(tets.boundaries)[:2]
    (48, ['back', 'bottom'])
    """
    mesh = spec.mesh
    if not isinstance(mesh, skfem.MeshHex1):
        raise TypeError(f"tetrahedralize needs a hexahedral MeshSpec, got {type(mesh).__name__!r}")
    cells = vtk_corners(mesh)
    points = mesh.p.T
    n_hex = cells.shape[0]
    nv = points.shape[0]
    tets = cells[:, _KUHN].reshape(-1, 4)
    parent = np.repeat(np.arange(n_hex), len(_KUHN))
    # conforming iff every interior face keys exactly two tetrahedron faces
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]],
                            tets[:, [0, 1, 2]]])  # fmt: skip
    _, counts = np.unique(_keys(faces, nv), return_counts=True)
    n_boundary_quads = len(mesh.boundary_facets())
    centred = np.count_nonzero(counts == 1) != 2 * n_boundary_quads or np.any(counts > 2)
    if centred:
        # every face split along the diagonal through its lowest-numbered vertex (the same
        # choice from both sides), each triangle joined to a new point at the cell centre
        quads = cells[:, _HEX_FACES]  # (nhex, 6, 4), cyclic
        first = np.argmin(quads, axis=2)
        q = np.take_along_axis(quads, (first[..., None] + np.arange(4)) % 4, axis=2)
        tri = np.stack([q[..., [0, 1, 2]], q[..., [0, 2, 3]]], axis=2)  # (nhex, 6, 2, 3)
        cc = np.broadcast_to((nv + np.arange(n_hex))[:, None, None, None], (n_hex, 6, 2, 1))
        tets = np.concatenate([cc, tri], axis=-1).reshape(-1, 4)
        points = np.concatenate([points, points[cells].mean(axis=1)], axis=0)
        parent = np.repeat(np.arange(n_hex), 12)
    tmesh = skfem.MeshTet1(np.ascontiguousarray(points.T), np.ascontiguousarray(tets.T))

    tmesh = _orient_tets(tmesh)
    npt = points.shape[0]
    bfacets = tmesh.boundary_facets()
    bkeys = _keys(tmesh.facets[:, bfacets].T, npt)
    boundaries = {}
    for name, ids in spec.boundaries.items():
        quad = np.sort(mesh.facets[:, ids].T.astype(np.int64), axis=1)  # (nq, 4)
        # the triangles of a boundary quad are the facets with three of its vertices
        tri = np.concatenate([np.delete(quad, i, axis=1) for i in range(4)])
        boundaries[name] = np.sort(bfacets[np.isin(bkeys, _keys(tri, npt))]).astype(np.int64)
    npc = len(tets) // n_hex
    regions = {k: (npc * np.asarray(v)[:, None] + np.arange(npc)).ravel() for k, v in
               spec.regions.items()}  # fmt: skip
    fibers = None if spec.fibers is None else np.asarray(spec.fibers)[parent]
    labelled = dataclasses.replace(
        tmesh,
        _boundaries={k: v.astype(np.int32) for k, v in boundaries.items()},
        _subdomains={k: np.asarray(v).astype(np.int32) for k, v in regions.items()} or None,
    )
    return MeshSpec(mesh=labelled, regions=regions, fibers=fibers, boundaries=boundaries)
