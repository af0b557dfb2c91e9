"""Where the phase constraint samples the images, and what it finds there.

:func:`constraint_quadrature` places the constraint's own quadrature points in every cell,
dense enough that no voxel of data is skipped; :class:`ConstraintState` holds the wrapped
phase mismatch and the phase gradient of each point at one displacement, from which
:class:`~harpx.tracking.constraint.PhaseConstraint` forms its force, tangent and the
tracking residual ε.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import skfem

from harpx._typing import FloatArray

if TYPE_CHECKING:
    from harpx.mechanics.body import Body

__all__ = ["ConstraintState", "constraint_quadrature", "epsilon_of"]


def constraint_quadrature(body: Body, spacing: float) -> tuple[FloatArray, FloatArray]:
    """Tensor Gauss rule whose points are at most about ``spacing`` mm apart in every cell.

    The number of points along each reference direction of the hexahedron is set by the
    longest cell edge along that direction, so elongated cells (e.g. the circumferential
    cells of an O-grid) get more points only where they need them.

    Parameters
    ----------
    body : Body
        The finite-element body (hexahedral mesh, mm).
    spacing : float
        Largest allowed distance between neighbouring sample points, mm (a voxel).

    Returns
    -------
    points : ndarray, shape (3, nq)
        Reference coordinates in [0, 1]³ (in the unit tetrahedron for tetrahedral meshes).
    weights : ndarray, shape (nq,)
        Weights summing to the reference cell's volume (1, or 1/6 for tetrahedra).

    Notes
    -----
    Tetrahedra get the centroids of a regular subdivision into ``m³`` congruent
    tetrahedra, equal weights (exact for linear integrands), ``m`` set by the longest cell
    edge so that neighbouring points are at most about ``spacing`` apart.
    """
    mesh = body.mesh
    if isinstance(mesh, skfem.MeshTet1):
        return _tet_quadrature(mesh, spacing)
    ref = skfem.ElementHex1().doflocs  # (8, 3) reference coordinates of the local vertices
    rules = []
    for j in range(3):
        diff = np.abs(ref[:, None, :] - ref[None, :, :])
        other = np.delete(diff, j, axis=2).sum(axis=2)
        a, b = np.nonzero(
            (diff[:, :, j] == 1) & (other == 0) & (np.arange(8)[:, None] < np.arange(8))
        )
        edges = mesh.p[:, mesh.t[a]] - mesh.p[:, mesh.t[b]]  # (3, 4 edges, ncell)
        longest = float(np.linalg.norm(edges, axis=0).max())
        # n Gauss points split an edge of length L into gaps of at most about L / n
        n = max(1, int(np.ceil(longest / spacing)))
        x, w = np.polynomial.legendre.leggauss(n)
        rules.append((0.5 * (x + 1.0), 0.5 * w))
    grids = np.meshgrid(*(r[0] for r in rules), indexing="ij")
    weights = np.einsum("i,j,k->ijk", *(r[1] for r in rules)).ravel()
    return np.stack([g.ravel() for g in grids]), weights


def _tet_quadrature(mesh: skfem.MeshTet1, spacing: float) -> tuple[FloatArray, FloatArray]:
    """Centroids of the regular subdivision of the unit tetrahedron into ``m³`` tetrahedra.

    The unit tetrahedron is the image of the Kuhn simplex ``1 >= a >= b >= c >= 0`` under
    ``x = a - b, y = b - c, z = c``; the Freudenthal triangulation of the ``m³`` sub-cubes
    of the unit cube puts ``m³`` congruent simplices in the Kuhn simplex. Their centroids
    are about half a sub-edge apart, so ``m = ceil(longest edge / (1.5 spacing))``.
    """
    p, t = mesh.p, mesh.t
    longest = max(
        float(np.linalg.norm(p[:, t[i]] - p[:, t[j]], axis=0).max())
        for i in range(4)
        for j in range(i + 1, 4)
    )
    m = max(1, int(np.ceil(longest / (1.5 * spacing))))
    i, j, k = (g.ravel() for g in np.meshgrid(*(np.arange(m),) * 3, indexing="ij"))
    corner = np.stack([i, j, k], axis=1)
    perms = np.array([[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]])
    # offset of the centroid of the simplex s_p0 >= s_p1 >= s_p2 in its sub-cube
    offset = np.zeros((6, 3))
    np.put_along_axis(offset, perms, np.array([[0.75, 0.5, 0.25]]), axis=1)
    c = (corner[:, None, :] + offset[None]).reshape(-1, 3) / m  # (a, b, c) of all simplices
    keep = (c[:, 0] >= c[:, 1]) & (c[:, 1] >= c[:, 2])  # simplices inside the Kuhn simplex
    a_, b_, c_ = c[keep].T
    points = np.stack([a_ - b_, b_ - c_, c_])
    return points, np.full(points.shape[1], 1.0 / (6.0 * points.shape[1]))


@dataclass
class ConstraintState:
    """Phase mismatch of every constraint point at one displacement.

    Attributes
    ----------
    residual : ndarray, shape (nq, ntag)
        Wrapped phase mismatch W(φ(x, t) − φ0(X)), rad (0 where not valid).
    gradient : ndarray, shape (nq, ntag, 3)
        Spatial phase gradient ∇φ at the current positions, rad/mm (0 where not valid).
    weight : ndarray, shape (nq,)
        Quadrature weight of points with data for at least one tag, mm³ (0 elsewhere).
    tag_valid : ndarray of bool, shape (nq, ntag)
        Which tags have data at each point (inside that tag's mask and field of view, in
        the reference and the current frame).
    robust_weight : ndarray, shape (nq, ntag), optional
        Weight :math:`w(r) = 1/(1 + (r/r_0)^2)` of each residual in the penalty force and
        tangent (:attr:`PhaseConstraint.robust_scale`); None: 1 everywhere (quadratic).
    """

    residual: FloatArray
    gradient: FloatArray
    weight: FloatArray
    tag_valid: np.ndarray
    robust_weight: FloatArray | None = None

    def penalty_weight(self) -> FloatArray | float:
        """Factor of λ per (point, tag) in the force and the tangent (1 when quadratic).

        Returns
        -------
        ndarray, shape (nq, ntag), or float
            ``robust_weight`` (dimensionless), or 1.0 when it is None.
        """
        return 1.0 if self.robust_weight is None else self.robust_weight

    def epsilon(self) -> float:
        """Tracking residual ε: weighted mean of ``|W(φ − φ0)|`` over valid points and tags.

        Returns
        -------
        float
            ε, rad, weighted by the points' volumes (NaN if no point has data).
        """
        return epsilon_of(self.weight, self.tag_valid, self.residual)


def epsilon_of(weight: FloatArray, tag_valid: np.ndarray, residual: FloatArray) -> float:
    """Weighted mean of |residual| over the valid (point, tag) pairs (NaN if none)."""
    w = weight[:, None] * tag_valid
    total = w.sum()
    if total <= 0:
        return float("nan")
    return float((w * np.abs(residual)).sum() / total)
