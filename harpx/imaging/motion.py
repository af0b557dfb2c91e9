r"""Known motions for synthetic images: inverting a displacement, interpolating a gridded one.

A synthetic image samples the material pattern at :math:`X = \chi_t^{-1}(x)`, the reference
position of the tissue now at :math:`x = X + u(X, t)`. :func:`invert_motion` solves for it by
the vectorised fixed point :math:`X \leftarrow x - u(X, t)` (warm-started from the previous
frame) with a Newton polish for points where it stalls; a
:class:`~harpx.errors.ConvergenceError` says when the motion cannot be inverted (e.g. it
folds). :func:`gridded_displacement` makes a callable :math:`u(X, t)` of a displacement
given on a grid (time, axis, z, y, x).

Units: mm and ms.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from harpx.errors import ConvergenceError
from harpx.schema import AXES, GRID_DIMS

__all__ = ["Motion", "gridded_displacement", "invert_motion"]

#: A displacement ``u(X, t)`` (n, 3) mm of reference points ``X`` (n, 3) mm at time ``t`` ms.
Motion = Callable[[NDArray[np.float64], float], NDArray[np.float64]]


def _jacobian_inverse(
    displacement: Motion, X: NDArray[np.float64], t: float, h: float
) -> NDArray[np.float64]:
    """Inverse of ``I + grad u`` at ``X`` by forward differences; identity where singular."""
    base = displacement(X, t)
    jac = np.empty((X.shape[0], 3, 3))
    for k in range(3):
        shifted = X.copy()
        shifted[:, k] += h
        jac[:, :, k] = (displacement(shifted, t) - base) / h
        jac[:, k, k] += 1.0
    det = np.linalg.det(jac)
    singular = ~(np.abs(det) > 1e-8)
    jac[singular] = np.eye(3)
    return np.linalg.inv(jac)  # type: ignore[return-value]  # numpy stub: float64 in, out


def invert_motion(
    displacement: Motion,
    x: ArrayLike,
    t: float,
    *,
    start: ArrayLike | None = None,
    tol: float = 1e-9,
    max_iter: int = 100,
) -> NDArray[np.float64]:
    r"""Reference positions :math:`X` with :math:`X + u(X, t) = x` (vectorised over points).

    Parameters
    ----------
    displacement : callable
        ``u(X, t)``: Lagrangian displacement in mm of points ``X`` (n, 3) mm at time ``t`` ms.
    x : array_like, shape (n, 3)
        Spatial positions in mm, columns (x, y, z).
    t : float
        Time in ms.
    start : array_like, shape (n, 3), optional
        Initial guess (default ``x``), e.g. the solution of the previous frame.
    tol : float, default 1e-9
        Convergence tolerance on :math:`|X + u(X) - x|_\infty` per point, mm.
    max_iter : int, default 100
        Maximum number of iterations.

    Returns
    -------
    ndarray, shape (n, 3)
        :math:`X = \chi_t^{-1}(x)` in mm.

    Raises
    ------
    ConvergenceError
        If some points do not converge (the motion folds, or is too large for the
        iteration); ``history`` holds the largest residual of every iteration.

    Notes
    -----
    Fixed-point iteration :math:`X \leftarrow x - u(X, t) = X - r` started at ``start``
    (or :math:`X = x`). It contracts with rate :math:`|\nabla u|`; when the residual falls by
    less than 4× per step the update is preconditioned with :math:`(I + \nabla u)^{-1}`
    (forward differences, refreshed whenever progress slows again), which turns it into a
    chord/Newton iteration. Only points not yet converged are iterated.

    Examples
    --------
    >>> from harpx.imaging.synth import invert_motion
    >>> shift = lambda X, t: np.full_like(X, 0.5 * np.sin(X[:, :1]))
    >>> x = np.array([[1.0, 2.0, 3.0]])
    >>> X = invert_motion(shift, x, 0.0)
    >>> bool(np.allclose(X + shift(X, 0.0), x, atol=1e-9))
    True
    """
    x = np.asarray(x, dtype=np.float64)
    X = x.copy() if start is None else np.array(start, dtype=np.float64)
    h = 1e-7 * max(1.0, float(np.max(np.abs(x)))) if x.size else 1e-7
    history: list[float] = []
    # compact working set: points still iterating, written back to X as they converge
    index = np.arange(x.shape[0])
    Xa, xa = X.copy(), x
    precond: NDArray[np.float64] | None = None
    previous = np.inf
    for _ in range(max_iter):
        if index.size == 0:
            return X
        r = Xa + displacement(Xa, t) - xa
        err2 = np.einsum("ij,ij->i", r, r)
        worst = float(np.sqrt(err2.max()))
        history.append(worst)
        done = err2 < tol * tol
        if done.any():
            X[index[done]] = Xa[done]
            keep = ~done
            index, Xa, xa, r = index[keep], Xa[keep], xa[keep], r[keep]
            if precond is not None:
                precond = precond[keep]
            if index.size == 0:
                return X
        if worst > 0.25 * previous:  # slow contraction: (re)build the preconditioner here
            precond = _jacobian_inverse(displacement, Xa, t, h)
        previous = worst
        Xa -= r if precond is None else np.einsum("nij,nj->ni", precond, r)
    X[index] = Xa
    raise ConvergenceError(
        f"inverting the motion at t={t!r} ms failed for {index.size} of {x.shape[0]} points "
        f"after {max_iter} iterations (max |X + u(X) - x| = {history[-1]:.3g} mm > "
        f"tol={tol:g} mm); the motion may fold (det(I + grad u) <= 0) or be too large for "
        "the iteration; pass inverse=callable(x, t) with the exact inverse",
        history,
    )


def gridded_displacement(field: xr.DataArray) -> Motion:
    """Turn a gridded displacement (time, axis, z, y, x) into a callable ``u(X, t)``.

    Trilinear in space (constant beyond the grid) and linear in time (constant beyond the
    first and last frame). NaNs (outside the body) are filled from the nearest finite voxel.

    Parameters
    ----------
    field : xarray.DataArray
        Dims (time, axis, z, y, x) with coords ``time`` (ms), ``axis`` (x, y, z) and evenly
        spaced ``z``, ``y``, ``x`` (mm); values in mm.

    Returns
    -------
    callable
        ``u(X, t)`` for points ``X`` (n, 3) in mm, returning (n, 3) mm.

    Raises
    ------
    ValueError
        If ``field`` does not have the dims (time, axis, z, y, x).
    """
    dims = ("time", "axis", *GRID_DIMS)
    if set(field.dims) != set(dims):
        raise ValueError(f"gridded displacement needs dims {dims!r}, got {field.dims!r}")
    field = field.transpose(*dims).sel(axis=list(AXES))
    data = np.asarray(field.values, dtype=np.float64)
    bad = ~np.isfinite(data)
    if bad.any():
        for n in range(data.shape[0]):
            for a in range(3):
                values = data[n, a]
                missing = ~np.isfinite(values)
                if missing.all():
                    values[...] = 0.0
                elif missing.any():
                    idx = ndimage.distance_transform_edt(
                        missing, return_distances=False, return_indices=True
                    )
                    values[...] = values[tuple(idx)]
    times = np.asarray(field["time"].values, dtype=np.float64)
    origin = np.array([float(field[d].values[0]) for d in GRID_DIMS])
    step = np.array(
        [float(np.diff(field[d].values).mean()) if field.sizes[d] > 1 else 1.0 for d in GRID_DIMS]
    )

    def u(X: NDArray[np.float64], t: float) -> NDArray[np.float64]:
        X = np.asarray(X, dtype=np.float64)
        index = ((X[:, [2, 1, 0]] - origin) / step).T
        if times.size == 1:
            frames, weights = [0], [1.0]
        else:
            k = int(np.clip(np.searchsorted(times, t) - 1, 0, times.size - 2))
            w = float(np.clip((t - times[k]) / (times[k + 1] - times[k]), 0.0, 1.0))
            frames, weights = [k, k + 1], [1.0 - w, w]
        out = np.zeros((X.shape[0], 3))
        for n, w in zip(frames, weights, strict=True):
            if w == 0.0:
                continue
            for a in range(3):
                out[:, a] += w * ndimage.map_coordinates(data[n, a], index, order=1, mode="nearest")
        return out

    return u
