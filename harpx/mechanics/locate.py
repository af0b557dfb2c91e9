"""Point location in hexahedral and tetrahedral meshes, and point evaluation of fields.

Points are located without Python loops over cells: the ``k`` cells with the nearest
centroids are candidates, the geometry map of each candidate (trilinear, linear or, for
curved ``MeshTet2`` cells, quadratic) is inverted by Newton's method for all (point,
candidate) pairs at once, and the first candidate whose reference coordinates fall in the
reference cell (unit cube or unit tetrahedron) wins. Points in no cell are reported as
outside, never extrapolated.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import skfem
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from harpx._typing import FloatArray, IntArray

__all__ = ["displacement_at", "locate"]

_GEOMETRY = skfem.ElementHex1()


def _geometry(mesh: Any) -> tuple[Any, FloatArray, bool]:
    """Geometry element, its nodes per cell (ncell, nb, 3) and whether cells are simplices."""
    if isinstance(mesh, skfem.MeshTet2):
        return skfem.ElementTetP2(), mesh.doflocs.T[mesh.dofs.element_dofs.T], True
    if isinstance(mesh, skfem.MeshTet1):
        return skfem.ElementTetP1(), mesh.p.T[mesh.t.T], True
    return _GEOMETRY, mesh.p.T[mesh.t.T], False


def _shape_values(element: Any, xi: FloatArray, nbasis: int) -> tuple[FloatArray, FloatArray]:
    """Values (n, nb) and reference gradients (n, nb, 3) of an element's basis at ``xi`` (3, n)."""
    vals = np.empty((xi.shape[1], nbasis))
    grads = np.empty((xi.shape[1], nbasis, 3))
    for a in range(nbasis):  # loop over the ≤ 20 basis functions, vectorised over points
        phi, dphi = element.lbasis(xi, a)
        vals[:, a] = phi
        grads[:, a, :] = dphi.T
    return vals, grads


def locate(
    mesh: skfem.MeshHex1, points: FloatArray, *, candidates: int = 8, tol: float = 1e-7
) -> tuple[IntArray, FloatArray]:
    """Find the cell and reference coordinates of each point.

    Parameters
    ----------
    mesh : skfem.MeshHex1, skfem.MeshTet1 or skfem.MeshTet2
        Hexahedral (trilinear) or tetrahedral (linear or quadratic) mesh, mm.
    points : ndarray, shape (n, 3)
        Physical points, mm.
    candidates : int, default 8
        Nearest cells (by centroid) tried per point; four times as many for tetrahedra
        (about 24 tetrahedra share a vertex where 8 hexahedra do).
    tol : float, default 1e-7
        Tolerance on the reference cell's bounds (dimensionless).

    Returns
    -------
    cells : ndarray of int, shape (n,)
        Containing cell, or -1 where the point lies in no cell.
    xi : ndarray, shape (n, 3)
        Reference coordinates in [0, 1]³ or the unit tetrahedron (meaningless where
        ``cells == -1``).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    n = points.shape[0]
    cells_out = np.full(n, -1, dtype=np.int64)
    xi_out = np.zeros((n, 3))
    if n == 0:
        return cells_out, xi_out
    element, vertices, simplex = _geometry(mesh)  # (ncell, nb, 3) geometry nodes
    centroids = vertices.mean(axis=1)
    radius = np.linalg.norm(vertices - centroids[:, None], axis=-1).max()
    k = min(candidates * (4 if simplex else 1), centroids.shape[0])
    dist, cand = cKDTree(centroids).query(points, k=k)
    dist = dist.reshape(n, k)
    cand = cand.reshape(n, k)
    unresolved = np.nonzero(dist[:, 0] <= radius * (1 + 1e-9))[0]
    for rank in range(k):  # candidates in order of centroid distance; most points stop at 0
        if unresolved.size == 0:
            break
        cell = cand[unresolved, rank]
        xi = _invert_map(element, vertices[cell], points[unresolved], simplex)
        if simplex:
            inside = np.all(xi >= -tol, axis=1) & (xi.sum(axis=1) <= 1 + tol)
        else:
            inside = np.all((xi >= -tol) & (xi <= 1 + tol), axis=1)
        cells_out[unresolved[inside]] = cell[inside]
        xi_out[unresolved[inside]] = xi[inside]
        unresolved = unresolved[~inside]
    xi_out = np.clip(xi_out, 0.0, 1.0)
    if simplex:  # onto the unit tetrahedron
        xi_out /= np.maximum(1.0, xi_out.sum(axis=1))[:, None]
    return cells_out, xi_out


def _invert_map(
    element: Any, verts: FloatArray, pts: FloatArray, simplex: bool, iterations: int = 25
) -> FloatArray:
    """Reference coordinates of ``pts`` (m, 3) in the cells with geometry nodes ``verts``
    (m, nb, 3) of ``element``."""
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
    return xi


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
    cells, xi = locate(body.mesh, X.reshape(-1, 3))
    inside = cells >= 0
    Ut = U.reshape(-1, body.ndof)
    out = np.full((Ut.shape[0], cells.size, 3), np.nan)
    if inside.any():
        vals, _ = _shape_values(body._scalar_element, xi[inside].T, body.nbasis)
        dofs = body.element_dofs[cells[inside]]  # (m, nb, 3)
        out[:, inside] = np.einsum("ma,tmai->tmi", vals, Ut[:, dofs])
    if U.ndim == 1:
        out = out[0]
    return out.reshape(X.shape) if U.ndim == 1 else out.reshape(Ut.shape[0], *X.shape)
