r"""Finite-strain kinematics on batches of deformation gradients.

Every function takes arrays with leading batch dimensions ``(...)`` -- typically
``(n_cells, n_qp)`` -- followed by the tensor dimensions, so that a material can be
evaluated at every quadrature point of a mesh at once. Indices follow the usual
continuum-mechanics convention: lower-case letters for the current configuration,
upper-case for the reference configuration, ``F[..., i, J] = dx_i/dX_J``.

Growth (Rodriguez, Hoger & McCulloch 1994) splits ``F = Fe Fg``. For a stored energy per
unit *grown* volume ``W_e(Fe)`` the energy per unit reference volume is

.. math::

    W(F) = J_g\, W_e(F F_g^{-1}), \qquad J_g = \det F_g ,

and with :math:`G = F_g^{-1}` the chain rule gives

.. math::

    P_{iJ} = J_g\, P^e_{iM} G_{JM}, \qquad
    \mathbb{A}_{iJkL} = J_g\, \mathbb{A}^e_{iMkN}\, G_{JM}\, G_{LN},

which :func:`push_growth_response` evaluates.

For a volumetric energy :math:`U(J)`,
:math:`\partial J/\partial F = J F^{-T} = \operatorname{cof} F` and
:math:`\partial H_{iJ}/\partial F_{kL} = -H_{iL} H_{kJ}` for :math:`H = F^{-T}`, so

.. math::

    P = U'(J)\, J\, H, \qquad
    \mathbb{A}_{iJkL} = (U'' J^2 + U' J)\, H_{iJ} H_{kL} - U' J\, H_{iL} H_{kJ},

which :func:`volumetric_response` evaluates.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from harpx._typing import FloatArray

__all__ = [
    "cofactor",
    "fiber_basis",
    "fiber_stretch",
    "green_strain",
    "growth_tensor",
    "push_growth_response",
    "right_cauchy_green",
    "split_growth",
    "unit_fibers",
    "volumetric_response",
]

_EYE = np.eye(3)


def _as_tensor(F: ArrayLike, name: str = "F") -> FloatArray:
    F = np.asarray(F, dtype=np.float64)
    if F.ndim < 2 or F.shape[-2:] != (3, 3):
        raise ValueError(
            f"{name!r} must have shape (..., 3, 3), got {F.shape!r}; "
            "pass one 3x3 tensor per point in the trailing dimensions"
        )
    return F


def unit_fibers(fiber: ArrayLike) -> FloatArray:
    """Normalise fiber directions to unit length.

    Parameters
    ----------
    fiber : array_like, shape (..., 3)
        Fiber directions in the reference configuration (any non-zero length).

    Returns
    -------
    ndarray, shape (..., 3)
        Unit vectors (dimensionless).

    Raises
    ------
    ValueError
        If the last dimension is not 3, or a direction is zero or not finite.
    """
    f = np.asarray(fiber, dtype=np.float64)
    if f.ndim < 1 or f.shape[-1] != 3:
        raise ValueError(
            f"'fiber' must have shape (..., 3), got {f.shape!r}; pass one unit vector per point"
        )
    norm = np.sqrt(np.einsum("...i,...i->...", f, f))
    if not np.all(np.isfinite(norm) & (norm > 0.0)):
        bad = int(np.count_nonzero(~(np.isfinite(norm) & (norm > 0.0))))
        raise ValueError(
            f"'fiber' has {bad} zero-length or non-finite direction(s); "
            "every point needs a finite, non-zero fiber vector"
        )
    return f / norm[..., None]


def cofactor(F: ArrayLike) -> FloatArray:
    """Cofactor matrix ``cof F = det(F) F^{-T}`` of 3x3 tensors.

    Parameters
    ----------
    F : array_like, shape (..., 3, 3)
        Deformation gradients (dimensionless).

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``cof F``; ``det F = sum(F * cof F, axis=-1)`` along any row.

    Examples
    --------
    >>> from harpx.mechanics.kinematics import cofactor
    >>> cofactor(np.diag([2.0, 3.0, 4.0]))
    array([[12.,  0.,  0.],
           [ 0.,  8.,  0.],
           [ 0.,  0.,  6.]])
    """
    F = _as_tensor(F)
    # rows: b x c, c x a, a x b for the rows a, b, c of F, written component by component
    cof = np.empty(F.shape)
    for r in range(3):
        s, t = (r + 1) % 3, (r + 2) % 3
        for j in range(3):
            k, m = (j + 1) % 3, (j + 2) % 3
            np.subtract(
                F[..., s, k] * F[..., t, m], F[..., s, m] * F[..., t, k], out=cof[..., r, j]
            )
    return cof


def _det_cof(F: FloatArray) -> tuple[FloatArray, FloatArray]:
    cof = cofactor(F)
    return np.einsum("...j,...j->...", F[..., 0, :], cof[..., 0, :]), cof


def positive_det_cof(F: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(det F, cof F)`` of deformation gradients that must not invert.

    Raises
    ------
    ValueError
        If ``det F <= 0`` or NaN anywhere (names how many points and the smallest value).
    """
    J, cof = _det_cof(F)
    if not np.all(J > 0.0):
        bad = int(np.count_nonzero(~(J > 0.0)))
        raise ValueError(
            f"'F' has det F <= 0 (or NaN) at {bad} point(s) (min {np.nanmin(J)!r}); "
            "the material response is only defined for J > 0 -- cut the load step"
        )
    return J, cof


def _outer(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a[..., i, J] b[..., k, L]`` as ``(..., 3, 3, 3, 3)``."""
    return a[..., :, :, None, None] * b[..., None, None, :, :]


def right_cauchy_green(F: ArrayLike) -> FloatArray:
    """Right Cauchy--Green tensor ``C = F^T F`` (dimensionless, symmetric).

    ``F`` holds deformation gradients of shape ``(..., 3, 3)`` as in :func:`cofactor`;
    ``C`` has the same shape.
    """
    F = _as_tensor(F)
    return np.matmul(np.swapaxes(F, -1, -2), F)


def green_strain(F: ArrayLike) -> FloatArray:
    """Green--Lagrange strain ``E = (C - I) / 2``, ``C`` the :func:`right_cauchy_green` tensor.

    Parameters and shapes as in :func:`right_cauchy_green`; ``E`` is dimensionless and
    symmetric.

    Examples
    --------
    >>> from harpx.mechanics.kinematics import green_strain
    >>> round(float(green_strain(np.diag([1.1, 1.0, 1.0]))[0, 0]), 12)
    0.105
    """
    return 0.5 * (right_cauchy_green(F) - _EYE)


def fiber_stretch(F: ArrayLike, fiber: ArrayLike) -> FloatArray:
    """Fiber stretch ``lambda = |F f0| = sqrt(2 E_ff + 1)``.

    Parameters
    ----------
    F : array_like, shape (..., 3, 3)
        Deformation gradients (dimensionless).
    fiber : array_like, shape (..., 3)
        Unit fiber directions ``f0`` in the reference configuration; broadcast against the
        batch dimensions of ``F``.

    Returns
    -------
    ndarray, shape (...)
        Fiber stretch (dimensionless).
    """
    F = _as_tensor(F)
    f = np.asarray(fiber, dtype=np.float64)
    a = np.einsum("...iJ,...J->...i", F, f)
    return np.sqrt(np.einsum("...i,...i->...", a, a))


def fiber_basis(fiber: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Right-handed orthonormal basis ``(f, s, n)`` around each fiber direction.

    ``f`` is the normalised fiber; ``s`` is the component of the coordinate axis least
    aligned with ``f`` (first one on ties) orthogonal to ``f``, normalised; ``n = f x s``.
    The choice is deterministic. The transverse pair ``(s, n)`` is arbitrary up to a
    rotation about ``f``, which does not matter for transversely isotropic laws.

    Parameters
    ----------
    fiber : array_like, shape (..., 3)
        Fiber directions (non-zero; normalised here).

    Returns
    -------
    f, s, n : ndarray, shape (..., 3)
        Unit vectors (dimensionless) with ``f x s = n``.

    Examples
    --------
    >>> from harpx.mechanics.kinematics import fiber_basis
    >>> f, s, n = fiber_basis([1.0, 0.0, 0.0])
    >>> s.tolist(), n.tolist()
    ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
    """
    f = unit_fibers(fiber)
    k = np.argmin(np.abs(f), axis=-1)
    e = np.zeros_like(f)
    np.put_along_axis(e, k[..., None], 1.0, axis=-1)
    s = e - np.take_along_axis(f, k[..., None], axis=-1) * f
    s /= np.sqrt(np.einsum("...i,...i->...", s, s))[..., None]
    n = np.cross(f, s)
    return f, s, n


def growth_tensor(fiber: ArrayLike, stretch: ArrayLike) -> FloatArray:
    """Growth tensor along fibers ``Fg = I + (theta - 1) f0 (x) f0``.

    Parameters
    ----------
    fiber : array_like, shape (..., 3)
        Fiber directions ``f0`` (normalised here).
    stretch : array_like
        Growth stretch ``theta > 0`` (dimensionless), scalar or broadcasting over the batch.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``Fg`` (dimensionless); ``det Fg = theta``.

    Examples
    --------
    >>> from harpx.mechanics.kinematics import growth_tensor
    >>> np.diag(growth_tensor([0.0, 0.0, 1.0], 1.2)).tolist()
    [1.0, 1.0, 1.2]
    """
    f = unit_fibers(fiber)
    theta = np.asarray(stretch, dtype=np.float64)
    return _EYE + (theta - 1.0)[..., None, None] * (f[..., :, None] * f[..., None, :])


def split_growth(F: ArrayLike, Fg: ArrayLike) -> FloatArray:
    """Elastic part ``Fe = F Fg^{-1}`` of a multiplicative split ``F = Fe Fg``.

    Parameters
    ----------
    F : array_like, shape (..., 3, 3)
        Total deformation gradients (dimensionless).
    Fg : array_like, shape (..., 3, 3)
        Growth tensors (dimensionless, invertible).

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``Fe`` (dimensionless).
    """
    return np.matmul(_as_tensor(F), np.linalg.inv(_as_tensor(Fg, "Fg")))


def push_growth_response(
    P_e: ArrayLike, A_e: ArrayLike, Fg: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Response to the total ``F`` of ``W(F) = det(Fg) W_e(F Fg^{-1})``.

    Parameters
    ----------
    P_e : array_like, shape (..., 3, 3)
        ``dW_e/dFe`` at ``Fe = F Fg^{-1}`` (kPa).
    A_e : array_like, shape (..., 3, 3, 3, 3)
        ``d^2 W_e / dFe dFe`` with ``A_e[..., i, J, k, L] = dP_e[iJ]/dFe[kL]`` (kPa).
    Fg : array_like, shape (..., 3, 3)
        Growth tensors (dimensionless).

    Returns
    -------
    P : ndarray, shape (..., 3, 3)
        First Piola--Kirchhoff stress w.r.t. the reference (ungrown) configuration (kPa):
        ``P_iJ = Jg P^e_iM G_JM`` with ``G = Fg^{-1}``.
    A : ndarray, shape (..., 3, 3, 3, 3)
        ``A_iJkL = Jg A^e_iMkN G_JM G_LN`` (kPa).

    Notes
    -----
    See the module docstring for the derivation.
    """
    P_e = np.asarray(P_e, dtype=np.float64)
    A_e = np.asarray(A_e, dtype=np.float64)
    Fg = _as_tensor(Fg, "Fg")
    G = np.linalg.inv(Fg)
    Jg = np.linalg.det(Fg)
    GT = np.swapaxes(G, -1, -2)
    P = Jg[..., None, None] * np.matmul(P_e, GT)
    # A_e[..., i, M, k, N] G_LN: contract the last index with G^T, then the second with G^T.
    A = np.matmul(A_e, GT[..., None, None, :, :])
    A = np.einsum("...iMkL,...JM->...iJkL", A, G)
    A *= Jg[..., None, None, None, None]
    return P, A


def volumetric_response(
    F: ArrayLike, dU: ArrayLike, d2U: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Stress and tangent of a volumetric energy ``U(J)`` evaluated pointwise.

    Parameters
    ----------
    F : array_like, shape (..., 3, 3)
        Deformation gradients (dimensionless, ``det F > 0``).
    dU, d2U : array_like, shape (...)
        ``U'(J)`` and ``U''(J)`` at ``J = det F`` (kPa), e.g. from a material's
        ``volumetric(J)``.

    Returns
    -------
    P : ndarray, shape (..., 3, 3)
        ``U' J F^{-T}`` (kPa).
    A : ndarray, shape (..., 3, 3, 3, 3)
        ``(U'' J^2 + U' J) H_iJ H_kL - U' J H_iL H_kJ`` with ``H = F^{-T}`` (kPa).
    """
    F = _as_tensor(F)
    J, cof = _det_cof(F)
    dU = np.asarray(dU, dtype=np.float64)
    d2U = np.asarray(d2U, dtype=np.float64)
    P = dU[..., None, None] * cof
    # (U'' J^2 + U' J) H (x) H = (U'' + U'/J) cof (x) cof; U' J H_iL H_kJ = (U'/J) cof_iL cof_kJ
    a = (d2U + dU / J)[..., None, None, None, None]
    b = (dU / J)[..., None, None, None, None]
    cofT = np.swapaxes(cof, -1, -2)
    A = a * (cof[..., :, :, None, None] * cof[..., None, None, :, :])
    A -= b * (cof[..., :, None, None, :] * cofT[..., None, :, :, None])
    return P, A
