r"""Passive hyperelastic laws for myocardium-like soft tissue: neo-Hookean and Guccione.

All laws are evaluated on batches of deformation gradients ``F`` with shape ``(..., 3, 3)``
(typically ``(n_cells, n_qp, 3, 3)``) and return the first Piola--Kirchhoff stress
``P[..., i, J]`` (kPa) and the consistent tangent ``A[..., i, J, k, L] = dP_iJ/dF_kL`` (kPa),
which is what a total-Lagrangian assembly needs.

Uncoupled split
---------------
Both passive laws are *uncoupled* (FEBio's convention): with :math:`J = \det F`,
:math:`\bar F = J^{-1/3} F`, :math:`\bar C = \bar F^T \bar F = J^{-2/3} C`,

.. math::

    W(F) = \bar W(\bar C) + U(J), \qquad U(J) = \tfrac{\kappa}{2} (\ln J)^2 .

``isochoric_response`` returns the response of :math:`\bar W` only, so that the
mean-dilatation (u--p--J) assembly can treat :math:`U` with an element-constant ``J``;
``volumetric(J)`` returns :math:`U, U', U''` with :math:`U' = \kappa \ln J / J` and
:math:`U'' = \kappa (1 - \ln J) / J^2`.

Derivation of the isochoric response (generic)
----------------------------------------------
Write :math:`\bar W` as a function :math:`\Psi(\bar F)` and let
:math:`\bar P = \partial\Psi/\partial\bar F = \bar F \bar S` (with :math:`\bar S = 2
\partial\bar W/\partial\bar C`) and :math:`\bar{\mathbb A} = \partial\bar P/\partial\bar F`.
With :math:`j = J^{-1/3}`, :math:`H = F^{-T}` and the identities
:math:`\partial j/\partial F = -\tfrac13 j H`,
:math:`\partial H_{iJ}/\partial F_{kL} = -H_{iL} H_{kJ}`,

.. math::

    \frac{\partial \bar F_{aB}}{\partial F_{kL}} = j\,(\delta_{ak}\delta_{BL}
    - \tfrac13 F_{aB} H_{kL}), \qquad
    P = j\,(\bar P - \tfrac13 p\, H), \quad p = \bar P : F .

Differentiating once more, with :math:`\bar H = \bar F^{-T} = H/j`,
:math:`\bar D = \bar{\mathbb A} : \bar F` (i.e. :math:`\bar D_{iJ} = \bar{\mathbb A}_{iJaB}
\bar F_{aB}`), :math:`\bar p = \bar P : \bar F` and :math:`\bar{\mathbb A}` major-symmetric,

.. math::

    \mathbb A = j^2 \Big[ \bar{\mathbb A}
      - \tfrac13 \big( (\bar D + \bar P) \otimes \bar H + \bar H \otimes (\bar D + \bar P) \big)
      + \tfrac19 \big( \bar F : \bar{\mathbb A} : \bar F + \bar p \big)\, \bar H \otimes \bar H
      + \tfrac13 \bar p\, \bar H \odot \bar H \Big],

where :math:`(\bar H \odot \bar H)_{iJkL} = \bar H_{iL} \bar H_{kJ}`. This is exact (no
finite differences) and symmetric in :math:`(iJ) \leftrightarrow (kL)`.

*Neo-Hookean.* :math:`\Psi = C_1 (\bar F : \bar F - 3)`, so :math:`\bar P = 2 C_1 \bar F`,
:math:`\bar{\mathbb A} = 2 C_1 \delta_{ik}\delta_{JL}`; substituting gives the closed form used
by :class:`NeoHookean`, with :math:`I_1 = F : F`,

.. math::

    P = 2 C_1 J^{-2/3} \big( F - \tfrac{I_1}{3} H \big), \qquad
    \mathbb A = 2 C_1 J^{-2/3} \Big[ \delta_{ik}\delta_{JL}
      - \tfrac23 (F \otimes H + H \otimes F) + \tfrac29 I_1 H \otimes H
      + \tfrac13 I_1 H \odot H \Big].

*Guccione.* In the local orthonormal fiber basis :math:`R = [f\ s\ n]` (columns), with
:math:`G = \bar F R` (columns :math:`g_a = \bar F r_a`), :math:`\tilde E = (G^T G - I)/2` the
local components of :math:`\bar E`, and the symmetric weight matrix :math:`B` with
:math:`B_{ff} = b_f`, :math:`B_{ss} = B_{nn} = B_{sn} = B_{ns} = b_t`,
:math:`B_{fs} = B_{sf} = B_{fn} = B_{nf} = b_{fs}`, the exponent is
:math:`Q = \sum_{ab} B_{ab} \tilde E_{ab}^2`. With :math:`\sigma_{ab} = B_{ab}\tilde E_{ab}`
and :math:`\psi = C e^Q`,

.. math::

    \bar S = \psi\, R \sigma R^T, \qquad
    \frac{\partial \tilde S_{ab}}{\partial \tilde E_{cd}} = \psi\,\big( 2 \sigma_{ab}
    \sigma_{cd} + B_{ab} \tfrac12 (\delta_{ac}\delta_{bd} + \delta_{ad}\delta_{bc}) \big),

and :math:`\bar{\mathbb A}_{iJkL} = \delta_{ik} \bar S_{JL} + \bar F_{iM}
\bar{\mathbb C}_{MJPL} \bar F_{kP}` becomes a sum of 7 symmetric rank-one terms,

.. math::

    \bar{\mathbb A} = \delta_{ik} \bar S_{JL} + \psi \Big[ 2 Z \otimes Z
      + \sum_{a} B_{aa} Y_{aa} \otimes Y_{aa} + \sum_{a<b} B_{ab} Y_{ab} \otimes Y_{ab} \Big],

with :math:`Z = G \sigma R^T`, :math:`Y_{aa} = g_a \otimes r_a` and
:math:`Y_{ab} = (g_a \otimes r_b + g_b \otimes r_a)/\sqrt2`.

*Low-rank evaluation.* Write :math:`\bar{\mathbb A} = \sum_k \omega_k Y_k \otimes Y_k
+ \delta_{ik} \bar S_{JL}` and note :math:`(\delta \otimes \bar S) : \bar F = \bar F \bar S
= \bar P`. The first three terms of the generic formula are then
:math:`\mathcal P^T \bar{\mathbb A}_Y \mathcal P = \sum_k \omega_k \hat Y_k \otimes \hat Y_k`
with :math:`\mathcal P = \mathbb I - \tfrac13 \bar F \otimes \bar H` (so
:math:`\partial \bar F/\partial F = j \mathcal P`), weights :math:`\omega = \psi B_{ab}` for
the :math:`Y_{ab}` and :math:`2\psi` for :math:`Z`, projected factors
:math:`\hat Y = \mathcal P^T Y = Y - \tfrac13 (Y : \bar F) \bar H`, and

.. math::

    \mathbb A = j^2 \Big[ \sum_k \omega_k \hat Y_k \otimes \hat Y_k
      + \delta_{ik} \bar S_{JL}
      - \tfrac23 (\bar P \otimes \bar H + \bar H \otimes \bar P)
      + \tfrac29 \bar p\, \bar H \otimes \bar H + \tfrac13 \bar p\, \bar H \odot \bar H \Big].

Here :math:`Y_{ab} : \bar F = g_a \cdot g_b = \tilde C_{ab}` (times :math:`\sqrt2` for
:math:`a \ne b`) and :math:`\hat Z = P / (j \psi)`. The rank-one and rank-two parts are
evaluated as one batched product :math:`K^T (M K)` of ``(9, 9)`` matrices per point
(timings in ``benchmarks/results/mechanics.md``).

The active fibre stress and fibre growth laws live in :mod:`harpx.mechanics.fiber_laws`.

References
----------
.. [1] Guccione JM, McCulloch AD, Waldman LK. Passive material properties of intact
   ventricular myocardium determined from a cylindrical model. J Biomech Eng
   113:42--55, 1991.
.. [2] Guccione JM, McCulloch AD. Mechanics of active contraction in cardiac muscle:
   Part I. J Biomech Eng 115:72--81, 1993.
.. [3] Maas SA, Rawlins D, Weiss JA, Ateshian GA. FEBio theory manual (uncoupled
   Mooney--Rivlin, section 5.3; active contraction, section 5.12).
.. [4] Rodriguez EK, Hoger A, McCulloch AD. Stress-dependent finite growth in soft elastic
   tissues. J Biomech 27:455--467, 1994.
.. [5] Holzapfel GA. Nonlinear Solid Mechanics. Wiley, 2000 (section 6.4, uncoupled
   elasticity tensors).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from harpx._moved import moved_getattr
from harpx._typing import FloatArray
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.mechanics.kernel import TangentFactors
from harpx.mechanics.kinematics import _as_tensor, fiber_basis, positive_det_cof

__all__ = ["Guccione", "NeoHookean"]


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------


def _check(name: str, value: float, *, allow_zero: bool = False) -> None:
    ok = isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool)
    if ok:
        v = float(value)
        ok = math.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        need = "a finite number >= 0" if allow_zero else "a finite number > 0"
        raise ValueError(f"parameter {name!r} must be {need}, got {value!r}")


_SQRT2 = math.sqrt(2.0)
_SQRT_HALF = math.sqrt(0.5)


def _log_volumetric(kappa: float, J: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    J = np.asarray(J, dtype=np.float64)
    lnJ = np.log(J)
    return 0.5 * kappa * lnJ**2, kappa * lnJ / J, kappa * (1.0 - lnJ) / J**2


def _poisson_ratio(shear_weights: tuple[float, float, float], kappa: float) -> float:
    """Smallest small-strain Poisson ratio of an uncoupled law with linearised energy
    ``sum_a w_a dev(eps)_aa^2 / 2 + kappa tr(eps)^2 / 2`` along its axes (kPa), from the
    compliance of the normal components (shears decouple); nan if it is singular."""
    P = np.eye(3) - 1.0 / 3.0
    D = P @ np.diag(shear_weights) @ P + kappa * np.ones((3, 3))
    if np.linalg.cond(D) > 1e12:
        return math.nan
    S = np.linalg.inv(D)
    nu = -S / np.diag(S)[:, None]  # nu[a, b] = -eps_b / eps_a under a stress along a
    return float(nu[~np.eye(3, dtype=bool)].min())


def _warn_auxetic(law: str, nu: float, kappa: float, shear: str) -> None:
    """A HarpxWarning when the small-strain Poisson ratio ``nu`` is negative."""
    if nu < 0.0:
        warnings.warn(
            f"{law}: kappa={kappa!r} kPa is small for {shear}, a negative small-strain "
            f"Poisson ratio ({nu:.3f}): the solid widens when stretched. Soft tissue is "
            "nearly incompressible (harpx's guide keeps kappa / C1 >= 100, C1 = mu / 2); "
            "check that the parameters are not swapped and are in kPa",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )


class _Uncoupled:
    """Shared volumetric part ``U = kappa/2 (ln J)^2`` and derived quantities."""

    kappa: float
    needs_fibers: ClassVar[bool]

    def isochoric_energy(self, F: ArrayLike, fiber: ArrayLike | None = None) -> FloatArray:
        raise NotImplementedError

    def isochoric_response(
        self, F: ArrayLike, fiber: ArrayLike | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """First Piola--Kirchhoff stress and tangent of the isochoric energy.

        Parameters
        ----------
        F : array_like, shape (..., 3, 3)
            Deformation gradients (dimensionless, ``det F > 0``).
        fiber : array_like, shape (..., 3), optional
            Unit reference fiber directions, broadcast against the batch of ``F``; required
            by a law that ``needs_fibers``, ignored by an isotropic one.

        Returns
        -------
        P : ndarray, shape (..., 3, 3)
            ``dWbar/dF`` (kPa).
        A : ndarray, shape (..., 3, 3, 3, 3)
            ``A[..., i, J, k, L] = dP_iJ/dF_kL`` (kPa).

        Raises
        ------
        ValueError
            If ``det F <= 0`` somewhere, or the law needs fibers and ``fiber`` is None.
        """
        P, factors = self.isochoric_factors(F, fiber)
        return P, factors.dense()

    def isochoric_factors(
        self,
        F: ArrayLike,
        fiber: ArrayLike | None = None,
        *,
        det_cof: tuple[FloatArray, FloatArray] | None = None,
    ) -> tuple[FloatArray, TangentFactors]:
        """Stress and the factored tangent of the isochoric energy (no 4th-order array).

        Parameters
        ----------
        F, fiber : array_like
            As for :meth:`isochoric_response`.
        det_cof : (ndarray, ndarray), optional
            ``(det F, cof F)`` if the caller has them (all ``det F > 0``), to save their
            evaluation (a law working in a local fiber basis recomputes them).

        Returns
        -------
        P : ndarray, shape (..., 3, 3)
            ``dWbar/dF`` (kPa).
        factors : TangentFactors
            The low-rank factors the law's Notes give; ``factors.dense()`` is the tangent
            of :meth:`isochoric_response`.

        Raises
        ------
        ValueError
            As :meth:`isochoric_response`.
        """
        return self._factors(_as_tensor(F), fiber, det_cof)

    def isochoric_stress(
        self,
        F: ArrayLike,
        fiber: ArrayLike | None = None,
        *,
        det_cof: tuple[FloatArray, FloatArray] | None = None,
    ) -> FloatArray:
        """Stress ``dWbar/dF`` (kPa, shape (..., 3, 3)) without the tangent's factors.

        The first output of :meth:`isochoric_factors`, for a residual alone (a line-search
        or fold check); arguments and errors as there.
        """
        return self._stress(_as_tensor(F), fiber, det_cof)

    def _stress(
        self, F: FloatArray, fiber: ArrayLike | None, det_cof: tuple[FloatArray, FloatArray] | None
    ) -> FloatArray:
        return self._factors(F, fiber, det_cof)[0]

    def _factors(
        self, F: FloatArray, fiber: ArrayLike | None, det_cof: tuple[FloatArray, FloatArray] | None
    ) -> tuple[FloatArray, TangentFactors]:
        raise NotImplementedError

    def volumetric(self, J: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Volumetric energy ``U = kappa/2 (ln J)^2`` and its first two derivatives.

        Parameters
        ----------
        J : array_like
            Volume ratio ``det F > 0`` (dimensionless); any shape.

        Returns
        -------
        U, dU, d2U : ndarray
            ``U`` (kPa), ``U' = kappa ln J / J`` (kPa) and
            ``U'' = kappa (1 - ln J) / J^2`` (kPa), same shape as ``J``.
        """
        return _log_volumetric(self.kappa, J)

    def strain_energy(self, F: ArrayLike, fiber: ArrayLike | None = None) -> FloatArray:
        """Total strain energy density ``W = Wbar(Cbar) + U(J)`` per unit reference volume
        (kPa, i.e. kJ/m^3), shape ``(...)``; ``F`` and ``fiber`` as for
        :meth:`isochoric_response`."""
        F = _as_tensor(F)
        J, _ = positive_det_cof(F)
        return self.isochoric_energy(F, fiber) + self.volumetric(J)[0]

    def cauchy_stress(self, F: ArrayLike, fiber: ArrayLike | None = None) -> FloatArray:
        """Total Cauchy stress ``sigma = J^{-1} P_iso F^T + U'(J) I`` (pointwise ``J``).

        Parameters
        ----------
        F, fiber : array_like
            As for :meth:`isochoric_response`.

        Returns
        -------
        ndarray, shape (..., 3, 3)
            Cauchy stress (kPa), symmetric.
        """
        F = _as_tensor(F)
        J, _ = positive_det_cof(F)
        P, _ = self.isochoric_response(F, fiber)
        sigma = np.matmul(P, np.swapaxes(F, -1, -2)) / J[..., None, None]
        return sigma + self.volumetric(J)[1][..., None, None] * np.eye(3)


# --------------------------------------------------------------------------------------
# passive laws
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class NeoHookean(_Uncoupled):
    r"""Uncoupled neo-Hookean solid (FEBio ``Mooney-Rivlin`` with ``c2 = 0``).

    Parameters
    ----------
    c1 : float
        Coefficient of :math:`(\bar I_1 - 3)` in kPa; small-strain shear modulus
        :math:`\mu = 2 C_1`.
    kappa : float
        Bulk modulus :math:`\kappa` in kPa (nearly incompressible: ``kappa / c1 >= 100``).

    Raises
    ------
    ValueError
        If a parameter is not a finite positive number (the message names it).

    Warns
    -----
    HarpxWarning
        If ``kappa < 4 c1 / 3``: the small-strain Poisson ratio (:attr:`poisson_ratio`) is
        negative, which soft tissue's is not (swapped parameters, or one not in kPa).

    Notes
    -----
    .. math::

        W = C_1 (\bar I_1 - 3) + \frac{\kappa}{2} (\ln J)^2, \qquad
        \bar I_1 = J^{-2/3} I_1, \quad I_1 = \operatorname{tr}(F^T F),

    with Cauchy stress :math:`\sigma = 2 C_1 J^{-5/3} (b - \tfrac{I_1}{3} I)
    + \kappa \tfrac{\ln J}{J} I`. The paper's "C1 = 1.0 kPa, kappa = 120 kPa" is
    ``NeoHookean(c1=1.0, kappa=120.0)``. The tangent is derived in the module docstring;
    :meth:`isochoric_factors` gives it, with :math:`a = 2 C_1 J^{-2/3}`, as
    :math:`Y = (F, H)`, :math:`Z = a\,(-\tfrac23 H,\ -\tfrac23 F + \tfrac29 I_1 H)`,
    :math:`s = a`, :math:`c = a I_1/3` (``h_index = 1``).

    References
    ----------
    .. [1] Maas SA et al. FEBio theory manual, section 5.3 (uncoupled Mooney--Rivlin).

    Examples
    --------
    >>> from harpx.mechanics.materials import NeoHookean
    >>> mat = NeoHookean(c1=1.0, kappa=120.0)
    >>> gamma = 0.5
    >>> F = np.eye(3) + gamma * np.eye(3)[:, [0]] * np.eye(3)[[1], :]  # simple shear
    >>> float(mat.cauchy_stress(F)[0, 1])  # 2 C1 gamma
    1.0
    """

    c1: float
    kappa: float
    needs_fibers: ClassVar[bool] = False

    def __post_init__(self) -> None:
        _check("c1", self.c1)
        _check("kappa", self.kappa)
        _warn_auxetic("NeoHookean", self.poisson_ratio, self.kappa, f"c1={self.c1!r} kPa")

    @property
    def poisson_ratio(self) -> float:
        """Small-strain Poisson ratio ``(3 kappa - 4 C1) / (2 (3 kappa + 2 C1))`` (negative,
        with a warning at construction, if ``kappa < 4 C1 / 3``)."""
        k, c1 = float(self.kappa), float(self.c1)
        return (3.0 * k - 4.0 * c1) / (2.0 * (3.0 * k + 2.0 * c1))

    def isochoric_energy(self, F: ArrayLike, fiber: ArrayLike | None = None) -> FloatArray:
        """Isochoric energy density ``C1 (J^{-2/3} I1 - 3)``.

        Parameters
        ----------
        F : array_like, shape (..., 3, 3)
            Deformation gradients (dimensionless, ``det F > 0``).
        fiber : array_like, shape (..., 3), optional
            Ignored (the law is isotropic).

        Returns
        -------
        ndarray, shape (...)
            ``Wbar`` per unit reference volume (kPa).

        Raises
        ------
        ValueError
            If ``det F <= 0`` somewhere.
        """
        F = _as_tensor(F)
        J, _ = positive_det_cof(F)
        I1 = np.einsum("...iJ,...iJ->...", F, F)
        return self.c1 * (J ** (-2.0 / 3.0) * I1 - 3.0)

    def _factors(
        self, F: FloatArray, fiber: ArrayLike | None, det_cof: tuple[FloatArray, FloatArray] | None
    ) -> tuple[FloatArray, TangentFactors]:
        """Stress and factors of the tangent (class Notes); ``fiber`` is ignored."""
        J, cof = positive_det_cof(F) if det_cof is None else det_cof
        H = cof / J[..., None, None]
        I1 = np.einsum("...iJ,...iJ->...", F, F)
        a = 2.0 * self.c1 * J ** (-2.0 / 3.0)
        P = a[..., None, None] * (F - (I1 / 3.0)[..., None, None] * H)
        # rank-two part a (-2/3 (F(x)H + H(x)F) + 2/9 I1 H(x)H) = Y^T Z with Y = [F; H]
        Y = np.empty(F.shape[:-2] + (2, 3, 3))
        Y[..., 0, :, :] = F
        Y[..., 1, :, :] = H
        am = (-2.0 / 3.0) * a[..., None, None]
        Z = np.empty_like(Y)
        np.multiply(am, H, out=Z[..., 0, :, :])
        np.multiply(((2.0 / 9.0) * a * I1)[..., None, None], H, out=Z[..., 1, :, :])
        Z[..., 1, :, :] += am * F
        return P, TangentFactors(Y=Y, Z=Z, s=a, c=a * I1 / 3.0, H=H, h_index=1)


def _transposed(A: FloatArray) -> FloatArray:
    """``A^T`` of a stack of 3×3 matrices, contiguous: numpy's batched matmul of a
    transposed view takes a slow strided path, slower than the copy and a contiguous
    product together (benchmarks/results/tracking_speed.md)."""
    return np.ascontiguousarray(np.swapaxes(A, -1, -2))


@dataclass(frozen=True)
class Guccione(_Uncoupled):
    r"""Transversely isotropic Guccione law for passive myocardium (uncoupled form).

    Parameters
    ----------
    c : float
        Stiffness scale :math:`C` in kPa.
    bf : float
        Fiber exponent coefficient :math:`b_f` (dimensionless, >= 0).
    bt : float
        Transverse exponent coefficient :math:`b_t` (dimensionless, >= 0).
    bfs : float
        Fiber--sheet/normal shear coefficient :math:`b_{fs}` (dimensionless, >= 0).
    kappa : float
        Bulk modulus :math:`\kappa` in kPa.

    Raises
    ------
    ValueError
        If ``c`` or ``kappa`` is not a finite positive number, or ``bf``, ``bt`` or ``bfs``
        not a finite non-negative one (the message names it).

    Warns
    -----
    HarpxWarning
        If ``kappa`` is so small for ``c bf`` and ``c bt`` that a small-strain Poisson ratio
        (:attr:`poisson_ratio`, the smallest along the fibre, sheet and normal axes) is
        negative, which soft tissue's is not.

    Notes
    -----
    .. math::

        W = \frac{C}{2} (e^Q - 1) + \frac{\kappa}{2} (\ln J)^2, \qquad
        Q = b_f \bar E_{ff}^2 + b_t (\bar E_{ss}^2 + \bar E_{nn}^2 + 2 \bar E_{sn}^2)
            + 2 b_{fs} (\bar E_{fs}^2 + \bar E_{fn}^2),

    with :math:`\bar E = (\bar C - I)/2`, :math:`\bar C = J^{-2/3} C`, components in the
    local orthonormal fiber basis ``(f, s, n)`` of
    :func:`harpx.mechanics.kinematics.fiber_basis` (``Q`` does not depend on the choice of
    ``s, n`` about ``f``). The law is written *uncoupled* (in :math:`\bar E`, not
    :math:`E`) so that the mean-dilatation assembly can treat the volumetric part
    separately. The incompressible closed forms (e.g. uniaxial stretch along the fibre)
    therefore hold exactly at ``J = 1``, where :math:`\bar E = E`. Derivation of the tangent: module
    docstring; :meth:`isochoric_factors` gives its nine rank-one factors
    (:math:`Y^r = K^r`, :math:`Z^r = J^{-2/3} (MK)^r`, the last one written with
    :math:`Y = H = F^{-T}`, ``h_index = 8``), :math:`c = \bar p/3`,
    :math:`S = J^{-2/3} \bar S` and :math:`s = 0`.

    References
    ----------
    .. [1] Guccione JM, McCulloch AD, Waldman LK. J Biomech Eng 113:42--55, 1991.
    .. [2] Maas SA et al. FEBio theory manual (uncoupled Guccione/Fung-type materials).

    Examples
    --------
    >>> from harpx.mechanics.materials import Guccione
    >>> mat = Guccione(c=2.0, bf=8.0, bt=2.0, bfs=4.0, kappa=200.0)
    >>> float(mat.strain_energy(np.eye(3), fiber=[1.0, 0.0, 0.0]))
    0.0
    """

    c: float
    bf: float
    bt: float
    bfs: float
    kappa: float
    needs_fibers: ClassVar[bool] = True

    def __post_init__(self) -> None:
        _check("c", self.c)
        _check("bf", self.bf, allow_zero=True)
        _check("bt", self.bt, allow_zero=True)
        _check("bfs", self.bfs, allow_zero=True)
        _check("kappa", self.kappa)
        shear = f"c={self.c!r} kPa with bf={self.bf!r}, bt={self.bt!r}"
        _warn_auxetic("Guccione", self.poisson_ratio, self.kappa, shear)

    @property
    def poisson_ratio(self) -> float:
        """Smallest small-strain Poisson ratio along the fibre, sheet and normal axes (nan if
        ``bt = 0``: no transverse stiffness); negative, with a warning at construction, if
        ``kappa`` is too small for ``c bf`` and ``c bt``."""
        c, bf, bt = float(self.c), float(self.bf), float(self.bt)
        return _poisson_ratio((c * bf, c * bt, c * bt), float(self.kappa))

    def _weights(self) -> FloatArray:
        bf, bt, bfs = float(self.bf), float(self.bt), float(self.bfs)
        return np.array([[bf, bfs, bfs], [bfs, bt, bt], [bfs, bt, bt]])

    def _local(
        self, F: FloatArray, fiber: ArrayLike | None
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        if fiber is None:
            raise ValueError(
                "Guccione needs fiber directions: pass 'fiber' with shape (..., 3) "
                "(unit reference vectors per cell or quadrature point)"
            )
        f, s, n = fiber_basis(fiber)
        R = np.stack([f, s, n], axis=-1)  # columns are the local basis vectors
        batch = np.broadcast_shapes(F.shape[:-2], R.shape[:-2])
        F = np.broadcast_to(F, batch + (3, 3))
        R = np.broadcast_to(R, batch + (3, 3))
        J, cof = positive_det_cof(F)
        j = J ** (-1.0 / 3.0)
        G = np.matmul(j[..., None, None] * F, R)  # columns g_a = Fbar r_a
        Ct = np.matmul(_transposed(G), G)  # local components of Cbar
        Et = 0.5 * (Ct - np.eye(3))
        Q = np.einsum("...ab,...ab->...", self._weights() * Et, Et)
        return F, J, cof, R, G, Ct, Q

    def isochoric_energy(self, F: ArrayLike, fiber: ArrayLike | None = None) -> FloatArray:
        """Isochoric energy density ``C/2 (exp Q - 1)``.

        Parameters
        ----------
        F : array_like, shape (..., 3, 3)
            Deformation gradients (dimensionless, ``det F > 0``).
        fiber : array_like, shape (..., 3)
            Reference fiber directions (normalised here), broadcast against the batch of
            ``F``; required.

        Returns
        -------
        ndarray, shape (...)
            ``Wbar`` per unit reference volume (kPa), over the broadcast batch of ``F`` and
            ``fiber``.

        Raises
        ------
        ValueError
            If ``det F <= 0`` somewhere, or ``fiber`` is None.
        """
        F = _as_tensor(F)
        *_, Q = self._local(F, fiber)
        return 0.5 * self.c * np.expm1(Q)

    def _factors(
        self, F: FloatArray, fiber: ArrayLike | None, det_cof: tuple[FloatArray, FloatArray] | None
    ) -> tuple[FloatArray, TangentFactors]:
        """Stress and factors of the tangent (class Notes); ``det_cof`` is recomputed in the
        local basis."""
        P, K, MK, pbar, Hbar, Sbar, j, H = self._tangent_parts(F, fiber)
        jj = (j * j)[..., None, None, None]
        Y = K
        Z = MK
        Z *= jj  # in place: MK is not used again
        # factor 8 is Hbar = H / j: carried as Y = H exactly (the assembly adds its H ⊗ H
        # weight there), so its Z takes the 1/j
        Y[..., 8, :, :] = H
        Z[..., 8, :, :] /= j[..., None, None]
        S = (j * j)[..., None, None] * Sbar
        return P, TangentFactors(Y=Y, Z=Z, s=np.zeros_like(j), c=pbar / 3.0, H=H, h_index=8, S=S)

    def _stress(
        self, F: FloatArray, fiber: ArrayLike | None, det_cof: tuple[FloatArray, FloatArray] | None
    ) -> FloatArray:
        """Stress alone (``det_cof`` is recomputed in the local basis)."""
        return self._stress_parts(F, fiber)[0]

    def _stress_parts(self, F: FloatArray, fiber: ArrayLike | None) -> tuple[FloatArray, ...]:
        """``(P, Pbar, pbar, Hbar, j, J, cof, R, G, Ct, sig, psi)`` (module docstring)."""
        F, J, cof, R, G, Ct, Q = self._local(F, fiber)
        sig = 0.5 * self._weights() * (Ct - np.eye(3))
        j = J ** (-1.0 / 3.0)
        psi = self.c * np.exp(Q)
        Hbar = cof / (J * j)[..., None, None]
        Pbar = psi[..., None, None] * np.matmul(np.matmul(G, sig), _transposed(R))
        pbar = psi * np.einsum("...ab,...ab->...", Ct, sig)  # Pbar : Fbar
        P = j[..., None, None] * (Pbar - (pbar / 3.0)[..., None, None] * Hbar)
        return P, Pbar, pbar, Hbar, j, J, cof, R, G, Ct, sig, psi

    def _tangent_parts(self, F: FloatArray, fiber: ArrayLike | None) -> tuple[FloatArray, ...]:
        """Stress and the pieces of the tangent (module docstring):
        ``(P, K, MK, pbar, Hbar, Sbar, j, H)`` with ``K`` and ``MK`` of shape (..., 9, 3, 3)."""
        P, Pbar, pbar, Hbar, j, J, cof, R, G, Ct, sig, psi = self._stress_parts(F, fiber)
        batch = J.shape
        B = self._weights()
        Sbar = psi[..., None, None] * np.matmul(np.matmul(R, sig), _transposed(R))
        # low-rank form of the tangent (module docstring): A = j^2 [K^T M K + ...]. The six
        # strain factors are formed from the products g_a ⊗ r_b (columns of G and R) with
        # the points along the last axis (contiguous rows; with the points first numpy's
        # inner loops are 3 long), then moved into the (..., 9, 3, 3) layout in one copy.
        flat = int(np.prod(batch))
        g = np.ascontiguousarray(G.reshape(flat, 3, 3).transpose(2, 1, 0))  # (a, i, point)
        r = np.ascontiguousarray(R.reshape(flat, 3, 3).transpose(2, 1, 0))  # (b, J, point)
        c = Ct.reshape(flat, 3, 3).transpose(1, 2, 0)  # (a, b, point)
        third = np.ascontiguousarray((1.0 / 3.0) * Hbar.reshape(flat, 3, 3).transpose(1, 2, 0))
        psi_rows = psi.reshape(flat)
        strain = np.empty((2, 6, 3, 3, flat))  # K, then MK
        for k, (a, b) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
            Kk = strain[0, k]
            np.multiply(g[a][:, None], r[b][None], out=Kk)
            if a == b:
                Kk -= c[a, a] * third
            else:
                Kk += g[b][:, None] * r[a][None]
                Kk *= _SQRT_HALF
                Kk -= (_SQRT2 * c[a, b]) * third
            np.multiply(B[a, b] * psi_rows, Kk, out=strain[1, k])
        K = np.empty(batch + (9, 3, 3))
        MK = np.empty(batch + (9, 3, 3))
        K.reshape(flat, 9, 3, 3)[:, :6] = strain[0].transpose(3, 0, 1, 2)
        MK.reshape(flat, 9, 3, 3)[:, :6] = strain[1].transpose(3, 0, 1, 2)
        K[..., 6, :, :] = P / (j * psi)[..., None, None]
        MK[..., 6, :, :] = (2.0 * psi)[..., None, None] * K[..., 6, :, :]
        K[..., 7, :, :] = Pbar
        K[..., 8, :, :] = Hbar
        MK[..., 7, :, :] = (-2.0 / 3.0) * Hbar
        MK[..., 8, :, :] = (-2.0 / 3.0) * Pbar + ((2.0 / 9.0) * pbar)[..., None, None] * Hbar
        return P, K, MK, pbar, Hbar, Sbar, j, cof / J[..., None, None]


__getattr__ = moved_getattr(__name__)
