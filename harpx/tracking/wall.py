"""A tracked motion smoothed along a wall, for predicting the band-pass blur from it.

The blur correction (:mod:`harpx.tracking.blur`) predicts the phase the band-pass adds
from a tracked motion. The motion's detail finer than the band-pass enters that prediction
directly: the unblurred signal carries it, the band-passed one does not. So a correction
pass is pulled back towards the previous fit's detail, errors included, and nothing in the
images contradicts it. Across a thin wall that detail is real and is what the correction
is for: the endocardium moves more than the epicardium, and the prediction of the wall's
thickening rests on it. Along the wall it is mostly the fit's error. With
``TrackingSettings(wall_smoothing=L)`` the correction is predicted from the tracked motion
averaged along the wall (a Gaussian of ``L`` mm over the points of the same transmural
depth), and the motion itself is left as tracked.

The transmural depth of a point is :math:`d_e / (d_e + d_p)`, with :math:`d_e, d_p` its
distances to the nearest node of the body's ``"endo"`` and ``"epi"`` boundaries (0 on the
endocardium, 1 on the epicardium; on a ventricle template's mesh it follows the template's
own transmural layers). Two points count as the same depth with weight
:math:`\\exp(-(\\Delta e / 0.1)^2)`, so points one transmural cell apart on a mesh with a few
cells across the wall hardly mix. A wall less than ``MIN_CELLS_ACROSS`` cells thick
(:func:`cells_across_wall`) has too little profile to keep: the tracker warns.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from harpx._typing import FloatArray

__all__ = [
    "DEPTH_WIDTH",
    "MIN_CELLS_ACROSS",
    "REACH",
    "cells_across_wall",
    "smooth_along_wall",
    "transmural_depth",
    "wall_smoother",
]

#: Width of the transmural-depth weight (fraction of the wall)
DEPTH_WIDTH = 0.1
#: The Gaussian along the wall is cut at this many ``length``
REACH = 2.5
#: Fewer cells than this across the wall leave the depth little thickening profile to keep
MIN_CELLS_ACROSS = 2.0


def transmural_depth(body: Any) -> FloatArray:
    """Transmural depth (0 endocardium, 1 epicardium) of every displacement node.

    Parameters
    ----------
    body : Body
        A body with named ``"endo"`` and ``"epi"`` boundaries (e.g. one meshed from a
        :class:`~harpx.anatomy.ventricle_template.VentricleTemplate`).

    Returns
    -------
    ndarray, shape (n_dof_nodes,)
        At ``body.dof_points``, dimensionless.

    Raises
    ------
    ValueError
        If the body has no ``"endo"`` or ``"epi"`` boundary, or one of them is empty.
    """
    distances = [
        cKDTree(_surface_nodes(body, name)).query(body.dof_points)[0] for name in ("endo", "epi")
    ]
    d_endo, d_epi = distances
    total = d_endo + d_epi
    return np.divide(d_endo, total, out=np.zeros_like(total), where=total > 0)


def _surface_nodes(body: Any, name: str) -> FloatArray:
    """Reference positions (n, 3) of the nodes of the named boundary, mm."""
    if name not in body.boundaries or len(body.boundaries[name]) == 0:
        raise ValueError(
            f"wall smoothing needs the body's {name!r} boundary; this body has "
            f"{sorted(body.boundaries)!r} (mesh it from a ventricle template, or name "
            "its endocardial and epicardial facets)"
        )
    return body.mesh.p[:, np.unique(body.mesh.facets[:, body.boundaries[name]])].T


def cells_across_wall(body: Any, depth: FloatArray | None = None) -> float:
    """About how many cells the wall is thick: 1 over the median transmural depth that a cell
    spans (its corners' largest minus smallest :func:`transmural_depth`).

    Parameters
    ----------
    body : Body
        As for :func:`transmural_depth`.
    depth : ndarray, shape (n_dof_nodes,), optional
        The body's :func:`transmural_depth`, if already computed.

    Returns
    -------
    float
        Cells across the wall (dimensionless); inf if the median cell spans no depth.

    Raises
    ------
    ValueError
        As :func:`transmural_depth`.
    """
    depth = transmural_depth(body) if depth is None else depth
    corners = depth[np.asarray(body.mesh.t)]  # (corner, cell)
    span = float(np.median(corners.max(axis=0) - corners.min(axis=0)))
    return 1.0 / span if span > 0 else float("inf")


def wall_smoother(body: Any, length: float, depth: FloatArray | None = None) -> sparse.csr_matrix:
    """Row-stochastic averaging along the wall: a Gaussian of ``length`` mm in the
    reference positions, times the transmural-depth weight (module notes).

    Parameters
    ----------
    body : Body
        As for :func:`transmural_depth`.
    length : float
        Standard deviation of the Gaussian along the wall, mm (> 0).
    depth : ndarray, shape (n_dof_nodes,), optional
        The body's :func:`transmural_depth`, if already computed.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n_dof_nodes, n_dof_nodes)
        Rows sum to 1; every node weighs itself with 1 before normalising.

    Raises
    ------
    ValueError
        If ``length`` is not positive, or as :func:`transmural_depth`.
    """
    if not (np.isfinite(length) and length > 0):
        raise ValueError(f"wall_smoothing={length!r} must be a positive length in mm")
    depth = transmural_depth(body) if depth is None else depth
    tree = cKDTree(body.dof_points)
    pairs = tree.sparse_distance_matrix(tree, REACH * length, output_type="coo_matrix")
    off = pairs.row != pairs.col  # each node's own weight is added once, below
    i, j, d = pairs.row[off], pairs.col[off], pairs.data[off]
    w = np.exp(-0.5 * (d / length) ** 2 - ((depth[i] - depth[j]) / DEPTH_WIDTH) ** 2)
    n = depth.size
    W = sparse.coo_matrix((w, (i, j)), shape=(n, n)).tocsr() + sparse.identity(n, format="csr")
    rows = np.asarray(W.sum(axis=1)).ravel()
    return sparse.diags(1.0 / rows) @ W


def smooth_along_wall(body: Any, U: FloatArray, smoother: sparse.csr_matrix) -> FloatArray:
    """The displacements ``U`` averaged along the wall by ``smoother``.

    Parameters
    ----------
    body : Body
        The body ``U`` belongs to (its ``node_dofs`` order the dofs by node).
    U : ndarray, shape (ntime, ndof)
        Displacement per frame, mm.
    smoother : scipy.sparse.csr_matrix, shape (n_dof_nodes, n_dof_nodes)
        Averaging over the dof nodes, as from :func:`wall_smoother`.

    Returns
    -------
    ndarray, shape (ntime, ndof)
        The averaged displacements, mm, in a new array; ``U`` is not changed.
    """
    nodes = np.asarray(U)[:, body.node_dofs]  # (time, node, 3)
    ntime, nnode, _ = nodes.shape
    moved = smoother @ nodes.transpose(1, 0, 2).reshape(nnode, -1)
    out = np.array(U, dtype=np.float64, copy=True)
    out[:, body.node_dofs] = moved.reshape(nnode, ntime, 3).transpose(1, 0, 2)
    return out
