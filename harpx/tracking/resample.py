"""Evaluate a finite-element displacement at arbitrary reference points (e.g. voxel centres).

Points are located in the hexahedral mesh by :func:`harpx.mechanics.locate.locate`
(vectorised, no Python loop over cells). Points in no cell are reported as outside (NaN
displacement), never extrapolated.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from harpx._typing import FloatArray
from harpx.mechanics.body import Body
from harpx.mechanics.locate import locate

__all__ = ["interpolate_displacement", "locate"]


def _shape_values(element: Any, xi: FloatArray, nbasis: int) -> tuple[FloatArray, FloatArray]:
    """Values (n, nb) and reference gradients (n, nb, 3) of an element's basis at ``xi`` (3, n)."""
    vals = np.empty((xi.shape[1], nbasis))
    grads = np.empty((xi.shape[1], nbasis, 3))
    for a in range(nbasis):  # loop over the ≤ 20 basis functions, vectorised over points
        phi, dphi = element.lbasis(xi, a)
        vals[:, a] = phi
        grads[:, a, :] = dphi.T
    return vals, grads


def interpolate_displacement(
    body: Body, displacements: FloatArray, points: FloatArray
) -> tuple[FloatArray, np.ndarray]:
    """Displacement of material points given by reference positions.

    Parameters
    ----------
    body : Body
        The body whose dofs ``displacements`` refer to.
    displacements : ndarray, shape (ntime, ndof)
        Displacement vectors, mm.
    points : ndarray, shape (n, 3)
        Reference positions, mm.

    Returns
    -------
    values : ndarray, shape (ntime, n, 3)
        Displacement at the points, mm (NaN outside the mesh).
    inside : ndarray of bool, shape (n,)
        Points inside the mesh.
    """
    U = np.atleast_2d(np.asarray(displacements, dtype=float))
    cells, xi = locate(body.mesh, points)
    inside = cells >= 0
    out = np.full((U.shape[0], points.shape[0], 3), np.nan)
    if inside.any():
        vals, _ = _shape_values(body.scalar_element, xi[inside].T, body.nbasis)
        dofs = body.element_dofs[cells[inside]]  # (m, nb, 3)
        out[:, inside] = np.einsum("ma,tmai->tmi", vals, U[:, dofs])
    return out, inside
