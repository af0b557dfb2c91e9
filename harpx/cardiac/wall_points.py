"""The wall points a tracked result gives the cardiac measures (:mod:`harpx.cardiac.strain`).

For trilinear (hex8) cells the 2 × 2 × 2 Gauss points of every cell, each with the Green
strain, current position and volume it carries there; for other elements one point per cell
(its centre, with the cell's volume); for a result on the image grid the voxel centres, with
the strain from central differences. And, per cell, the fraction of each direction the tags
observed (``observed_fraction``), where the tracker recorded it.

Units: mm, mm³; strain dimensionless.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from harpx._typing import BoolArray, FloatArray, IntArray
from harpx.conventions import ELEMENT_CORNERS
from harpx.mechanics.cells import VTK_HEX_CORNERS, hex8_shape

__all__: list[str] = []


def _cell_weights(points: FloatArray, cells: IntArray, element: str) -> FloatArray:
    """Cell volumes from the corner vertices, mm³: exact for straight tetrahedra; for
    hexahedra the estimate |det J(centre)|·8."""
    if ELEMENT_CORNERS.get(element, 8) == 4:
        x = points[cells[:, :4]]
        return np.abs(np.linalg.det(x[:, 1:] - x[:, :1])) / 6.0
    x = points[cells[:, :8]]
    d = np.einsum("nai,aj->nij", x, VTK_HEX_CORNERS) / 4.0
    return np.abs(np.linalg.det(d))


def _hex8_gauss_points(
    points: FloatArray, cells: IntArray, displacement: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Reference positions (8 ncell, 3), Green strain (time, 8 ncell, 3, 3), current
    positions (time, 8 ncell, 3) and volumes (8 ncell,) mm³ of the 2 × 2 × 2 Gauss points
    of trilinear hexahedra (in the order of their VTK corners), cell by cell, from the nodal
    ``displacement`` (time, node, 3) mm: the field the tracker's hex8 cells carry."""
    shape, dshape = hex8_shape(VTK_HEX_CORNERS / np.sqrt(3.0))  # N_a(ξ_q), ∂N_a/∂ξ_k
    x = points[cells[:, :8]]  # (e, a, i)
    jac = np.einsum("eai,qak->eqik", x, dshape)  # ∂X_i/∂ξ_k
    inverse = np.linalg.inv(jac)
    grad = np.einsum("qak,eqkj->eqaj", dshape, inverse)  # ∂N_a/∂X_j
    weights = np.abs(np.linalg.det(jac)).reshape(-1)  # Gauss weights 1
    ue = displacement[:, cells[:, :8]]  # (t, e, a, i)
    F = np.einsum("teai,eqaj->teqij", ue, grad) + np.eye(3)
    E = 0.5 * (np.einsum("teqki,teqkj->teqij", F, F) - np.eye(3))
    X = np.einsum("qa,eai->eqi", shape, x)
    current = X[None] + np.einsum("qa,teai->teqi", shape, ue)
    nt, ne = ue.shape[:2]
    return X.reshape(-1, 3), E.reshape(nt, ne * 8, 3, 3), current.reshape(nt, ne * 8, 3), weights


def _grid_strain(u: xr.DataArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Voxel centres (n, 3), Green strain (time, n, 3, 3), current positions (time, n, 3)."""
    u = u.transpose("time", "axis", "z", "y", "x")
    data = np.asarray(u.values, dtype=np.float64)
    z, y, x = (np.asarray(u[d].values, dtype=np.float64) for d in ("z", "y", "x"))
    # du_i/dX_j by central differences on the grid (NaN next to missing voxels)
    d = np.gradient(data, z, y, x, axis=(2, 3, 4))  # list over (z, y, x)
    grad = np.stack([d[2], d[1], d[0]], axis=2)  # (time, i, j=x,y,z, z, y, x)
    nt = data.shape[0]
    grad = grad.reshape(nt, 3, 3, -1).transpose(0, 3, 1, 2)  # (time, n, i, j)
    F = grad + np.eye(3)
    E = 0.5 * (np.einsum("tnki,tnkj->tnij", F, F) - np.eye(3))
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    disp = data.reshape(nt, 3, -1).transpose(0, 2, 1)
    return pts, E, pts[None] + disp


def _observation(tracked: xr.Dataset) -> tuple[FloatArray | None, BoolArray | None]:
    """Per-cell seen fraction of x, y, z and cells with data of a finite-element result."""
    if "observed_fraction" not in tracked:
        return None, None
    f = tracked["observed_fraction"].transpose("cell", "axis")
    if "axis" in f.coords:
        f = f.sel(axis=["x", "y", "z"])
    observed = np.asarray(f.values, dtype=np.float64)
    if "observed_directions" in tracked:
        has = np.asarray(tracked["observed_directions"].values).reshape(-1) >= 1
    else:
        has = observed.sum(axis=1) > 0.0
    return observed, has
