"""Evaluate a finite-element displacement at arbitrary reference points (e.g. voxel centres).

Points are located in the hexahedral or tetrahedral mesh by
:func:`harpx.mechanics.locate.locate` (vectorised, no Python loop over cells). Points in no
cell are reported as outside (NaN displacement), never extrapolated.
"""

from __future__ import annotations

import numpy as np

from harpx._typing import FloatArray
from harpx.mechanics.body import Body
from harpx.mechanics.locate import displacement_at, locate

__all__ = ["interpolate_displacement", "locate"]


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
    out = displacement_at(body, U, np.asarray(points, dtype=float).reshape(-1, 3))
    return out, ~np.isnan(out[0, :, 0]) if out.shape[0] else np.zeros(out.shape[1], bool)
