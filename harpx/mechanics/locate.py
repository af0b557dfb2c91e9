r"""Point location in hexahedral and tetrahedral meshes: containing cell and reference coordinates.

One locator serves every caller that needs "which cell holds this point, and where in it":
evaluating a finite-element field at voxel centres (:mod:`harpx.tracking.resample`), and
mapping spatial points back to the reference through a deformed mesh
(:class:`harpx.scenes.lv.FEMotion`).

Algorithm (no Python loop over cells or points):

1. Candidates are the ``k`` cells with the nearest centroids (KD-tree) whose bounding
   sphere (centred at the centroid, radius the farthest vertex) holds the point. A point of
   a trilinear cell is a convex combination of its vertices, so no containing cell is
   missed this way.
2. The trilinear map of every (point, candidate) pair is inverted at once by Newton's
   method. In monomial form :math:`x(\xi) = \sum_m b_m\,\mu_m(\xi)` with
   :math:`\mu = (1, \xi, \eta, \zeta, \xi\eta, \xi\zeta, \eta\zeta, \xi\eta\zeta)`, each
   step solves the 3 × 3 system :math:`[\partial_\xi x\;\partial_\eta x\;\partial_\zeta x]
   \,\delta = r` by Cramer's rule. Pairs whose step is below 1e-12 stop iterating.
3. Candidates are tried in order of centroid distance; the first whose reference
   coordinates lie in :math:`[0, 1]^3` (to ``tol``) and map back onto the point (Newton
   converged: distance below 1e-6 of the cell's radius) wins. Points in no cell get cell -1,
   never an extrapolated one.

The vertex order of a cell is given by ``corners``, the reference coordinates of its eight
vertices: :data:`VTK_CORNERS` (VTK/meshio ``hexahedron``, :attr:`Body.cells
<harpx.mechanics.body.Body.cells>`) or :data:`SKFEM_CORNERS` (``skfem.MeshHex1.t``, the
order of ``skfem.ElementHex1``'s basis). The reference coordinates returned are those of the
same convention, so they can be fed to the matching shape functions.

Curved hexahedra (``skfem.MeshHex2``) are not supported: :func:`locate` raises
``NotImplementedError``. Tetrahedral meshes (``skfem.MeshTet1``, and ``skfem.MeshTet2``
with curved, quadratic cells) use the same scheme with the linear or quadratic geometry
map, four times as many candidates (about 24 tetrahedra share a vertex where 8 hexahedra
do) and the unit tetrahedron as the reference cell. :func:`displacement_at` evaluates a
body's displacement at points with this locator.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np
import skfem
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.spatial import cKDTree

from harpx._typing import FloatArray, IntArray

__all__ = [
    "SKFEM_CORNERS",
    "VTK_CORNERS",
    "HexLocator",
    "displacement_at",
    "interpolation_matrix",
    "locate",
    "trilinear",
]

#: reference coordinates of the eight vertices in VTK/meshio ``hexahedron`` order
VTK_CORNERS: FloatArray = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
    dtype=np.float64,
)
#: reference coordinates of the eight vertices in scikit-fem ``MeshHex1`` order
SKFEM_CORNERS: FloatArray = np.asarray(skfem.ElementHex1().doflocs, dtype=np.float64)


def _monomial_coefficients(corners: FloatArray) -> FloatArray:
    """Matrix taking vertex values (8,) to the coefficients of 1, ξ, η, ζ, ξη, ξζ, ηζ, ξηζ."""
    a, b, c = corners.T
    return np.linalg.inv(np.stack([np.ones(8), a, b, c, a * b, a * c, b * c, a * b * c], axis=1))


def trilinear(xi: FloatArray, corners: FloatArray = VTK_CORNERS) -> FloatArray:
    """Trilinear shape functions at reference points.

    Parameters
    ----------
    xi : ndarray, shape (m, 3)
        Reference coordinates in [0, 1]³ (dimensionless).
    corners : ndarray, shape (8, 3), default VTK_CORNERS
        Reference coordinates of the vertices, in the cell's vertex order.

    Returns
    -------
    ndarray, shape (m, 8)
        Value of each vertex's shape function; rows sum to 1.

    Examples
    --------
    >>> import numpy as np
    >>> from harpx.mechanics.locate import trilinear
    >>> trilinear(np.array([[0.5, 0.5, 0.5]])).round(3).tolist()
    [[0.125, 0.125, 0.125, 0.125, 0.125, 0.125, 0.125, 0.125]]
    """
    on = corners.astype(bool)
    w = np.where(on[None], xi[:, None, :], 1.0 - xi[:, None, :])  # (m, 8, 3)
    return w[:, :, 0] * w[:, :, 1] * w[:, :, 2]


class HexLocator:
    """Point location in a trilinear hexahedral mesh, vectorised (see the module docstring).

    Parameters
    ----------
    vertices : ndarray, shape (nvertex, 3)
        Vertex positions, mm.
    cells : ndarray of int, shape (ncell, 8)
        Vertex ids per cell (further columns, e.g. hex20 edge nodes, are ignored).
    corners : ndarray, shape (8, 3), default VTK_CORNERS
        Reference coordinates of the eight vertices in the order of ``cells``.

    Examples
    --------
    >>> import numpy as np
    >>> from harpx.mechanics.locate import HexLocator
    >>> from harpx.mechanics.mesh import box
    >>> from harpx.mechanics.body import Body
    >>> from harpx.mechanics.materials import NeoHookean
    >>> body = Body(box((2.0, 1.0, 1.0), (2, 1, 1)), NeoHookean(c1=1.0, kappa=100.0))
    >>> cells, xi = HexLocator(body.nodes, body.cells).locate(np.array([[1.5, 0.5, 0.25]]))
    >>> int(cells[0] >= 0), xi.round(6).tolist()
    (1, [[0.5, 0.5, 0.25]])
    """

    def __init__(
        self, vertices: FloatArray, cells: IntArray, *, corners: FloatArray = VTK_CORNERS
    ) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.cells = np.ascontiguousarray(np.asarray(cells)[:, :8], dtype=np.int64)
        self.corners = np.asarray(corners, dtype=np.float64)
        x = self.vertices[self.cells]  # (ncell, 8, 3)
        centroids = x.mean(axis=1)
        self.cell_radius = np.linalg.norm(x - centroids[:, None], axis=-1).max(axis=1) * 1.001
        self.radius = float(self.cell_radius.max()) if len(x) else 0.0
        self.tree = cKDTree(centroids)
        self.lo = self.vertices.min(axis=0) - 1e-9
        self.hi = self.vertices.max(axis=0) + 1e-9
        # x(ξ) = Σ_m coeffs[:, m] * monomial_m(ξ)
        self.coeffs = np.einsum("ma,cai->cmi", _monomial_coefficients(self.corners), x)

    def invert(self, cells: IntArray, points: FloatArray, *, iterations: int = 25) -> FloatArray:
        """Reference coordinates of points in given trilinear cells.

        Newton's method from the cell centre, clipped to [-1, 2]³; not checked for
        containment (see :meth:`locate`).

        Parameters
        ----------
        cells : ndarray of int, shape (m,)
            Cell of each point.
        points : ndarray, shape (m, 3)
            Physical points, mm.
        iterations : int, default 25
            Newton iterations at most (a point stops once its step is below 1e-12).

        Returns
        -------
        ndarray, shape (m, 3)
            Reference coordinates (dimensionless; [0, 1]³ inside the cell, in the convention
            of ``corners``), whatever the cell; the caller checks containment.
        """
        # rows: coefficient k and component i over the points (m contiguous), so that every
        # step below runs on rows of m (on (m, 3) arrays numpy's inner loops are 3 long)
        b = np.ascontiguousarray(self.coeffs[cells].transpose(1, 2, 0))  # (8, 3, m)
        target = np.ascontiguousarray(np.asarray(points, dtype=np.float64).T)  # (3, m)
        m = target.shape[1]
        xi = np.full((3, m), 0.5)
        active = np.arange(m)
        for _ in range(iterations):  # Newton, quadratic; only pairs that have not converged
            whole = active.size == m
            bb = b if whole else b[:, :, active]
            u, v, w = xi if whole else xi[:, active]
            uv, uw, vw = u * v, u * w, v * w
            x = bb[0] + bb[1] * u + bb[2] * v + bb[3] * w + bb[4] * uv + bb[5] * uw
            x += bb[6] * vw + bb[7] * (uv * w)
            cu = bb[1] + bb[4] * v + bb[5] * w + bb[7] * vw  # dx/dξ
            cv = bb[2] + bb[4] * u + bb[6] * w + bb[7] * uw
            cw = bb[3] + bb[5] * u + bb[6] * v + bb[7] * uv
            r = (target if whole else target[:, active]) - x
            # Cramer's rule for [cu cv cw] δ = r
            cvw, cwu, cuv = _cross_rows(cv, cw), _cross_rows(cw, cu), _cross_rows(cu, cv)
            det = (cu * cvw).sum(axis=0)
            det = np.where(np.abs(det) > 1e-300, det, 1e-300)
            step = np.stack([(r * cvw).sum(axis=0), (r * cwu).sum(axis=0), (r * cuv).sum(axis=0)])
            step /= det
            moved = np.clip((xi if whole else xi[:, active]) + step, -1.0, 2.0)
            if whole:
                xi = moved
            else:
                xi[:, active] = moved
            active = active[np.abs(step).max(axis=0) > 1e-12]
            if active.size == 0:
                break
        return np.ascontiguousarray(xi.T)

    def _residual(self, cells: IntArray, points: FloatArray, xi: FloatArray) -> FloatArray:
        """Distance (m,) mm between ``points`` and the image of ``xi`` in ``cells``."""
        mono = np.stack(
            [
                np.ones(len(xi)),
                xi[:, 0],
                xi[:, 1],
                xi[:, 2],
                xi[:, 0] * xi[:, 1],
                xi[:, 0] * xi[:, 2],
                xi[:, 1] * xi[:, 2],
                xi[:, 0] * xi[:, 1] * xi[:, 2],
            ],
            axis=1,
        )
        x = np.einsum("mk,mki->mi", mono, self.coeffs[cells])
        return np.linalg.norm(x - points, axis=1)

    def locate(
        self,
        points: FloatArray,
        *,
        candidates: int = 8,
        tol: float = 1e-7,
        chunk: int = 262144,
    ) -> tuple[IntArray, FloatArray]:
        """Containing cell and reference coordinates of each point.

        Parameters
        ----------
        points : ndarray, shape (n, 3)
            Physical points, mm.
        candidates : int, default 8
            Nearest cells (by centroid) tried per point.
        tol : float, default 1e-7
            Tolerance on the unit-cube bounds of the reference coordinates (dimensionless).
        chunk : int, default 262144
            Points processed per block (bounds the memory of the candidate arrays).

        Returns
        -------
        cells : ndarray of int, shape (n,)
            Containing cell, or -1 where the point lies in no cell.
        xi : ndarray, shape (n, 3)
            Reference coordinates in [0, 1]³ (0 where ``cells == -1``).
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        cells_out = np.full(len(points), -1, dtype=np.int64)
        xi_out = np.zeros((len(points), 3))
        if len(points) == 0 or self.tree.n == 0:
            return cells_out, xi_out
        near = np.nonzero(np.all((points >= self.lo) & (points <= self.hi), axis=1))[0]
        k = min(candidates, self.tree.n)
        for begin in range(0, near.size, chunk):  # memory-bounded blocks of points
            ids = near[begin : begin + chunk]
            dist, cand = self.tree.query(points[ids], k=k, distance_upper_bound=self.radius)
            dist, cand = dist.reshape(len(ids), k), cand.reshape(len(ids), k)
            ok = np.isfinite(dist)
            ok[ok] = dist[ok] <= self.cell_radius[cand[ok]]
            todo = np.arange(len(ids))
            for rank in range(k):  # candidates by centroid distance; most points stop at 0
                todo = todo[np.any(ok[todo, rank:], axis=1)]
                try_now = todo[ok[todo, rank]]
                if try_now.size == 0:
                    continue
                c = cand[try_now, rank]
                xi = self.invert(c, points[ids[try_now]])
                inside = np.all((xi >= -tol) & (xi <= 1.0 + tol), axis=1)
                # a Newton run that stalled (distorted or degenerate cell) is no hit
                inside &= (
                    self._residual(c, points[ids[try_now]], xi) <= 1e-6 * (self.cell_radius[c])
                )
                cells_out[ids[try_now[inside]]] = c[inside]
                xi_out[ids[try_now[inside]]] = xi[inside]
                todo = np.setdiff1d(todo, try_now[inside], assume_unique=True)
        return cells_out, np.clip(xi_out, 0.0, 1.0)


def _cross_rows(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross products of the columns of ``a`` and ``b`` (3, m), as rows (3, m)."""
    return np.stack(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _tet_geometry(mesh: Any) -> tuple[Any, FloatArray]:
    """Geometry element and its nodes per cell (ncell, nb, 3) of a tetrahedral mesh."""
    if isinstance(mesh, skfem.MeshTet2):
        return skfem.ElementTetP2(), mesh.doflocs.T[mesh.dofs.element_dofs.T]
    return skfem.ElementTetP1(), mesh.p.T[mesh.t.T]


def _shape_values(element: Any, xi: FloatArray, nbasis: int) -> tuple[FloatArray, FloatArray]:
    """Values (n, nb) and reference gradients (n, nb, 3) of an element's basis at ``xi`` (3, n)."""
    vals = np.empty((xi.shape[1], nbasis))
    grads = np.empty((xi.shape[1], nbasis, 3))
    for a in range(nbasis):  # loop over the ≤ 20 basis functions, vectorised over points
        phi, dphi = element.lbasis(xi, a)
        vals[:, a] = phi
        grads[:, a, :] = dphi.T
    return vals, grads


def _locate_tets(
    mesh: Any, points: FloatArray, *, candidates: int, tol: float
) -> tuple[IntArray, FloatArray]:
    """:func:`locate` for ``skfem.MeshTet1`` / ``MeshTet2`` (see the module docstring)."""
    n = points.shape[0]
    cells_out = np.full(n, -1, dtype=np.int64)
    xi_out = np.zeros((n, 3))
    element, vertices = _tet_geometry(mesh)  # (ncell, nb, 3) geometry nodes
    if n == 0 or vertices.shape[0] == 0:
        return cells_out, xi_out
    centroids = vertices.mean(axis=1)
    cell_radius = np.linalg.norm(vertices - centroids[:, None], axis=-1).max(axis=1) * 1.001
    k = min(4 * candidates, centroids.shape[0])
    dist, cand = cKDTree(centroids).query(points, k=k)
    dist = dist.reshape(n, k)
    cand = cand.reshape(n, k)
    unresolved = np.nonzero(dist[:, 0] <= cell_radius.max())[0]
    for rank in range(k):  # candidates in order of centroid distance; most points stop at 0
        if unresolved.size == 0:
            break
        cell = cand[unresolved, rank]
        xi, residual = _invert_map(element, vertices[cell], points[unresolved], True)
        inside = np.all(xi >= -tol, axis=1) & (xi.sum(axis=1) <= 1 + tol)
        # a Newton run that stalled (distorted curved cell) is no hit
        inside &= residual <= 1e-6 * cell_radius[cell]
        cells_out[unresolved[inside]] = cell[inside]
        xi_out[unresolved[inside]] = xi[inside]
        unresolved = unresolved[~inside]
    xi_out = np.clip(xi_out, 0.0, 1.0)
    xi_out /= np.maximum(1.0, xi_out.sum(axis=1))[:, None]  # onto the unit tetrahedron
    return cells_out, xi_out


def _invert_map(
    element: Any, verts: FloatArray, pts: FloatArray, simplex: bool, iterations: int = 25
) -> tuple[FloatArray, FloatArray]:
    """Reference coordinates of ``pts`` (m, 3) in the cells with geometry nodes ``verts``
    (m, nb, 3) of ``element``, and the distance (m,) mm between ``pts`` and their image."""
    xi = np.full((pts.shape[0], 3), 0.25 if simplex else 0.5)
    nb = verts.shape[1]
    active = np.arange(pts.shape[0])
    for _ in range(iterations):  # Newton, only on the pairs that have not converged
        vals, grads = _shape_values(element, xi[active].T, nb)
        x = np.einsum("ma,mai->mi", vals, verts[active])
        jac = np.einsum("mai,maj->mij", verts[active], grads)  # dx_i/dxi_j
        step = np.linalg.solve(jac, (pts[active] - x)[..., None])[..., 0]
        xi[active] = np.clip(xi[active] + step, -1.0, 2.0)
        active = active[np.abs(step).max(axis=1) > 1e-12]
        if active.size == 0:
            break
    vals, _ = _shape_values(element, xi.T, nb)
    residual = np.linalg.norm(np.einsum("ma,mai->mi", vals, verts) - pts, axis=1)
    return xi, residual


def locate(
    mesh: Any, points: FloatArray, *, candidates: int = 8, tol: float = 1e-7
) -> tuple[IntArray, FloatArray]:
    """Find the cell and reference coordinates of each point in a scikit-fem mesh.

    Parameters
    ----------
    mesh : skfem.MeshHex1, skfem.MeshTet1 or skfem.MeshTet2
        Hexahedral (trilinear) or tetrahedral (linear or quadratic) mesh, mm.
    points : ndarray, shape (n, 3)
        Physical points, mm.
    candidates : int, default 8
        Nearest cells (by centroid) tried per point; four times as many for tetrahedra.
    tol : float, default 1e-7
        Tolerance on the reference cell's bounds (dimensionless).

    Returns
    -------
    cells : ndarray of int, shape (n,)
        Containing cell, or -1 where the point lies in no cell.
    xi : ndarray, shape (n, 3)
        Reference coordinates in scikit-fem's convention (the reference element of
        ``skfem.ElementHex1``/``ElementHexS2``: [0, 1]³; of ``ElementTetP1``/``ElementTetP2``:
        the unit tetrahedron); 0 where ``cells == -1``.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return _locator(mesh, candidates, tol)(points)


def _locator(
    mesh: Any, candidates: int = 8, tol: float = 1e-7
) -> Callable[[FloatArray], tuple[IntArray, FloatArray]]:
    """:func:`locate` of one mesh as a function of the points, its search structures built
    once (for calls chunk by chunk)."""
    if isinstance(mesh, skfem.MeshHex2):
        raise NotImplementedError(
            "point location in curved hexahedra (skfem.MeshHex2, 27-node geometry) is not "
            "implemented: the locator inverts the trilinear map of straight cells only. "
            "Evaluate at dof nodes (body.dof_points) instead, or build the body on the "
            "straight mesh (curved=False) to track or sample it"
        )
    if isinstance(mesh, (skfem.MeshTet1, skfem.MeshTet2)):
        return functools.partial(_locate_tets, mesh, candidates=candidates, tol=tol)
    locator = HexLocator(mesh.p.T, mesh.t.T, corners=SKFEM_CORNERS)
    return functools.partial(locator.locate, candidates=candidates, tol=tol)


def displacement_at(body: Any, u: ArrayLike, points: ArrayLike) -> FloatArray:
    """Displacement at arbitrary reference points (apex, landmarks), mm.

    Parameters
    ----------
    body : Body
        The body ``u`` belongs to.
    u : array_like, shape (ndof,) or (ntime, ndof)
        Displacement dofs, mm.
    points : array_like, shape (n, 3) or (3,)
        Reference positions, mm.

    Returns
    -------
    ndarray, shape (n, 3) (or (ntime, n, 3), or (3,) for one point)
        Displacement, mm; NaN for points outside the mesh.

    Raises
    ------
    ValueError
        If ``points`` is not (n, 3) or (3,), or ``u`` is not (ndof,) or (ntime, ndof).

    Examples
    --------
    >>> from harpx.mechanics import Body, NeoHookean, box
    >>> body = Body(box((2.0, 1.0, 1.0), (2, 1, 1)), NeoHookean(c1=1.0, kappa=100.0))
    >>> u = (0.1 * body.dof_points).ravel()  # uniform 10 % dilation
    >>> displacement_at(body, u, [1.5, 0.5, 0.25]).round(6).tolist()
    [0.15, 0.05, 0.025]
    """
    U = np.asarray(u, dtype=np.float64)
    X = np.asarray(points, dtype=np.float64)
    if X.shape[-1:] != (3,) or X.ndim > 2:
        raise ValueError(f"points has shape {X.shape!r}; expected (n, 3) or (3,) positions in mm")
    if U.shape[-1:] != (body.ndof,) or U.ndim > 2:
        raise ValueError(
            f"u has shape {U.shape!r}; expected ({body.ndof},) or (ntime, {body.ndof})"
        )
    inside, interpolate = interpolation_matrix(body, X.reshape(-1, 3))
    Ut = U.reshape(-1, body.ndof)
    out = np.full((Ut.shape[0], inside.size, 3), np.nan)
    if inside.any():
        nnode = body.ndof // 3
        # one sparse interpolation matrix for every frame (no (ntime, m, nb, 3) gather)
        nodal = Ut.reshape(-1, nnode, 3).transpose(1, 0, 2).reshape(nnode, -1)
        values = np.asarray(interpolate @ nodal).reshape(inside.sum(), -1, 3)  # (m, ntime, 3)
        out[:, inside] = values.transpose(1, 0, 2)
    if U.ndim == 1:
        out = out[0]
    return out.reshape(X.shape) if U.ndim == 1 else out.reshape(Ut.shape[0], *X.shape)


def interpolation_matrix(
    body: Any, points: ArrayLike, *, chunk: int = 1 << 14
) -> tuple[np.ndarray, sparse.csr_matrix]:
    """Which reference points lie in the body, and the matrix interpolating nodal values there.

    Parameters
    ----------
    body : Body
        The body whose reference mesh and shape functions are used.
    points : array_like, shape (n, 3)
        Reference positions, mm.
    chunk : int, default 16384
        Points located at once (bounds the locator's temporaries).

    Returns
    -------
    inside : ndarray of bool, shape (n,)
        Points inside the reference mesh.
    matrix : scipy.sparse.csr_matrix, shape (inside.sum(), nnode)
        Row ``i`` holds the shape-function values of the ``i``-th inside point at its
        cell's nodes: ``matrix @ nodal`` (nnode, 3) gives the displacement there.
    """
    X = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nb = body.nbasis
    insides, values, nodes = [], [], []
    find = _locator(body.mesh)
    for a in range(0, len(X), chunk):  # chunks of points, not single points
        cells, xi = find(X[a : a + chunk])
        here = cells >= 0
        vals, _ = _shape_values(body.scalar_element, xi[here].T, nb)
        insides.append(here)
        values.append(vals)
        nodes.append(body.element_dofs[cells[here], :, 0] // 3)  # (m, nb): dof 3 s + i of s
    inside = np.concatenate(insides) if insides else np.zeros(0, dtype=bool)
    nodes_all = np.concatenate(nodes) if nodes else np.zeros((0, nb), dtype=np.int64)
    vals_all = np.concatenate(values) if values else np.zeros((0, nb))
    m = nodes_all.shape[0]
    matrix = sparse.csr_matrix(
        (vals_all.ravel(), nodes_all.ravel(), np.arange(0, m * nb + 1, nb)),
        shape=(m, body.ndof // 3),
    )
    return inside, matrix
