"""Quality of hexahedral meshes: the scaled Jacobian and a mesh quality report.

Units: mm for coordinates; the scaled Jacobian is dimensionless (1 for a cube, ≤ 0 for an
inverted or degenerate cell).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from harpx._typing import FloatArray
from harpx.mechanics.meshspec import _CORNER_EDGES

__all__ = ["MeshQuality", "scaled_jacobian"]


@dataclass(frozen=True)
class MeshQuality:
    """Quality report of a hexahedral mesh.

    Attributes
    ----------
    cells : int
        Number of hexahedra.
    min_scaled_jacobian, mean_scaled_jacobian : float
        Smallest and mean per-cell scaled Jacobian (1 for a cube, dimensionless).
    inverted : int
        Cells with a non-positive corner Jacobian (0 for every mesh this module returns).
    dropped_cells : int
        Cubes of the voxel mesh that were not face-connected to its largest part.
    max_boundary_offset : float
        Largest distance of a boundary vertex from the smoothed iso-surface after
        projection, first-order estimate :math:`|\\phi - 1/2| / |\\nabla\\phi|`, mm.
    restored_vertices : int
        Vertices moved back towards their voxel position to keep every cell valid.
    """

    cells: int
    min_scaled_jacobian: float
    mean_scaled_jacobian: float
    inverted: int
    dropped_cells: int
    max_boundary_offset: float
    restored_vertices: int


def scaled_jacobian(points: ArrayLike, cells_vtk: ArrayLike) -> FloatArray:
    """Per-cell scaled Jacobian of VTK-ordered hexahedra (dimensionless).

    Parameters
    ----------
    points : array_like, shape (npoint, 3)
        Vertex coordinates, mm.
    cells_vtk : array_like, shape (ncell, 8)
        Vertex ids per cell in VTK order.

    Returns
    -------
    ndarray, shape (ncell,)
        Minimum over the eight corners of ``det[e1, e2, e3] / (|e1| |e2| |e3|)``; 1 for a
        cube, ≤ 0 for an inverted or degenerate cell.

    Examples
    --------
    >>> import numpy as np
    >>> from harpx.mechanics.quality import scaled_jacobian
    >>> cube = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
    ...                  [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float)
    >>> scaled_jacobian(cube, np.arange(8)[None]).round(12).tolist()
    [1.0]
    """
    xyz = np.asarray(points, dtype=np.float64)[np.asarray(cells_vtk)]
    edges = xyz[:, _CORNER_EDGES] - xyz[:, :, None, :]  # (ncell, 8, 3, 3)
    lengths = np.linalg.norm(edges, axis=-1).prod(axis=-1)
    det = np.linalg.det(edges) / np.maximum(lengths, np.finfo(float).tiny)
    return det.min(axis=1)
