r"""Laws along the muscle fibres: active contraction and fibre growth.

*Active fibre stress.* :math:`S_a = T_a(\lambda) f_0 \otimes f_0` with
:math:`\lambda = |F f_0|` and :math:`a = F f_0`: :math:`P = T_a\, a \otimes f_0` and, using
:math:`\partial\lambda/\partial F = a \otimes f_0 / \lambda`,

.. math::

    \mathbb A_{iJkL} = T_a\, \delta_{ik} f_J f_L + \frac{T_a'(\lambda)}{\lambda}
      (a_i f_J)(a_k f_L) .

For the calcium law :math:`T_a = T_{max}\, e/(e + r^2)` with
:math:`e = \exp(B(l - l_0)) - 1`, :math:`l = l_r \lambda`, :math:`r = Ca_{0,max}/Ca_0`,
so :math:`dT_a/d\lambda = T_{max}\, r^2/(e + r^2)^2 \cdot B (e + 1)\, l_r` for
:math:`l > l_0` and 0 otherwise. The active stress derives from the potential
:math:`W_a = \int_1^\lambda T_a(\mu)\,\mu\, d\mu`, so :math:`\mathbb A` is symmetric.

*Growth* :math:`F = F_e F_g` with a fibre growth tensor
(:func:`harpx.mechanics.kinematics.growth_tensor`) is composed by the assembly with
:func:`harpx.mechanics.kinematics.push_growth_response`.

Units: kPa for stresses, dimensionless stretches.

References
----------
.. [1] Guccione JM, McCulloch AD. Mechanics of active contraction in cardiac muscle:
   Part I. J Biomech Eng 115:72--81, 1993.
.. [2] Maas SA, Rawlins D, Weiss JA, Ateshian GA. FEBio theory manual (active
   contraction, section 5.12).
.. [3] Rodriguez EK, Hoger A, McCulloch AD. Stress-dependent finite growth in soft elastic
   tissues. J Biomech 27:455--467, 1994.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike

from harpx._typing import FloatArray
from harpx.mechanics.kinematics import _as_tensor, _outer, growth_tensor, unit_fibers
from harpx.mechanics.materials import _check

__all__ = ["ActiveContraction", "FiberGrowth"]


# --------------------------------------------------------------------------------------
# active stress
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ActiveContraction:
    r"""Active fiber stress of Guccione--McCulloch type (second Piola--Kirchhoff form).

    Parameters
    ----------
    t_max : float, default 135.7
        Maximum isometric tension :math:`T_{max}` in kPa (>= 0).
    law : {"prescribed", "calcium"}, default "calcium"
        ``"prescribed"``: :math:`T_a = T_{max}` (FEBio ``prescribed fiber active
        contraction``); ``"calcium"``: the length-dependent calcium law below.
    ca0 : float, default 4.35
        Peak intracellular calcium :math:`Ca_0` in uM.
    ca0_max : float, default 4.35
        Maximum peak calcium :math:`(Ca_0)_{max}` in uM.
    beta : float, default 4.75
        Shape coefficient :math:`B` in 1/um.
    l0 : float, default 1.58
        Sarcomere length without active tension :math:`l_0` in um.
    lr : float, default 2.04
        Stress-free sarcomere length :math:`l_r` in um.

    Raises
    ------
    ValueError
        If ``t_max`` is negative, ``law`` is neither of its values, or another parameter
        is not a finite positive number (the message names it).

    Notes
    -----
    .. math::

        S_a = T_a\, f_0 \otimes f_0, \qquad
        T_a = T_{max} \frac{Ca_0^2}{Ca_0^2 + ECa_{50}^2}, \qquad
        ECa_{50} = \frac{(Ca_0)_{max}}{\sqrt{\exp(B (l - l_0)) - 1}},

    with :math:`l = l_r \lambda`, :math:`\lambda = \sqrt{2 E_{ff} + 1} = |F f_0|`, and
    :math:`T_a = 0` for :math:`l \le l_0`. Defaults are FEBio's "typical" values
    (Guccione & McCulloch 1993). Unlike FEBio's uncoupled variant, which uses the
    deviatoric stretch :math:`J^{-1/3}|F f_0|`, the total stretch is used; they agree at
    :math:`J = 1`. With the defaults, :math:`T_a(\lambda = 1) = 120.4368` kPa. The
    consistent tangent is derived in the module docstring.

    References
    ----------
    .. [1] Guccione JM, McCulloch AD. J Biomech Eng 115:72--81, 1993.
    .. [2] Maas SA et al. FEBio theory manual, section 5.12 (active contraction).

    Examples
    --------
    >>> from harpx.mechanics.fiber_laws import ActiveContraction
    >>> act = ActiveContraction()
    >>> round(float(act.tension(1.0)), 4)
    120.4368
    """

    t_max: float = 135.7
    law: Literal["prescribed", "calcium"] = "calcium"
    ca0: float = 4.35
    ca0_max: float = 4.35
    beta: float = 4.75
    l0: float = 1.58
    lr: float = 2.04
    needs_fibers: ClassVar[bool] = True

    def __post_init__(self) -> None:
        _check("t_max", self.t_max, allow_zero=True)
        if self.law not in ("prescribed", "calcium"):
            raise ValueError(f"parameter 'law' must be 'prescribed' or 'calcium', got {self.law!r}")
        for name in ("ca0", "ca0_max", "beta", "l0", "lr"):
            _check(name, getattr(self, name))

    def _g_dg(self, stretch: ArrayLike) -> tuple[FloatArray, FloatArray]:
        lam = np.asarray(stretch, dtype=np.float64)
        if self.law == "prescribed":
            nan = np.isnan(lam)
            return np.where(nan, np.nan, 1.0), np.where(nan, np.nan, 0.0)
        r2 = (self.ca0_max / self.ca0) ** 2
        dl = self.lr * lam - self.l0
        on = dl > 0.0
        x = np.where(on, self.beta * dl, 0.0)
        # huge stretches overflow e to inf; the law saturates there (g = 1, dg = 0)
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            e = np.expm1(x)
            big = np.isinf(e)
            e = np.where(big, 1.0, e)
            g = np.where(on, e / (e + r2), 0.0)
            dg = np.where(on, r2 / (e + r2) ** 2 * self.beta * (e + 1.0) * self.lr, 0.0)
        g = np.where(big, 1.0, g)
        dg = np.where(big, 0.0, dg)
        nan = np.isnan(lam)
        return np.where(nan, np.nan, g), np.where(nan, np.nan, dg)

    def activation_factor(self, stretch: ArrayLike) -> FloatArray:
        """Length dependence ``g(lambda)`` with ``T_a = t_max g``.

        Parameters
        ----------
        stretch : array_like
            Fiber stretch :math:`\\lambda` (dimensionless).

        Returns
        -------
        ndarray
            ``g`` in [0, 1] (dimensionless); 1 for the prescribed law, 0 where
            :math:`l_r \\lambda \\le l_0` for the calcium law.
        """
        return self._g_dg(stretch)[0]

    def tension(self, stretch: ArrayLike, t_max: ArrayLike | None = None) -> FloatArray:
        """Active fiber tension ``T_a = t_max g(lambda)``.

        Parameters
        ----------
        stretch : array_like
            Fiber stretch (dimensionless).
        t_max : array_like, optional
            Maximum tension in kPa, broadcasting against ``stretch``; default ``self.t_max``.

        Returns
        -------
        ndarray
            ``T_a`` in kPa (second Piola--Kirchhoff fiber component).
        """
        t = self.t_max if t_max is None else np.asarray(t_max, dtype=np.float64)
        return t * self.activation_factor(stretch)

    def t_max_for_tension(self, stretch: ArrayLike, tension: ArrayLike) -> FloatArray:
        """Invert the law for ``t_max``: ``t_max = tension / g(lambda)``.

        Parameters
        ----------
        stretch : array_like
            Fiber stretch (dimensionless).
        tension : array_like
            Active tension ``T_a`` in kPa, broadcasting against ``stretch``.

        Returns
        -------
        ndarray
            ``t_max`` in kPa. NaN where ``g(lambda) = 0`` (the calcium law is inactive for
            :math:`l_r \\lambda \\le l_0`, so any ``t_max`` fits) and where an input is NaN.
            No warnings are emitted.
        """
        g = self.activation_factor(stretch)
        T = np.asarray(tension, dtype=np.float64)
        g, T = np.broadcast_arrays(g, T)
        out = np.full(g.shape, np.nan)
        np.divide(T, g, out=out, where=g > 0.0)
        return out

    def response(
        self, F: ArrayLike, fiber: ArrayLike, t_max: ArrayLike | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """First Piola--Kirchhoff active stress and its consistent tangent.

        Parameters
        ----------
        F : array_like, shape (..., 3, 3)
            Deformation gradients (dimensionless).
        fiber : array_like, shape (..., 3)
            Unit reference fiber directions, broadcast against the batch of ``F``.
        t_max : array_like, optional
            Maximum tension in kPa broadcasting over the batch (e.g. ``(n_cells, 1)`` per
            cell); default ``self.t_max``.

        Returns
        -------
        P : ndarray, shape (..., 3, 3)
            ``P = F S_a = T_a (F f0) (x) f0`` (kPa).
        A : ndarray, shape (..., 3, 3, 3, 3)
            ``A[..., i, J, k, L] = dP_iJ/dF_kL`` (kPa), including ``dT_a/dlambda``.
        """
        F = _as_tensor(F)
        f = unit_fibers(fiber)
        a = np.einsum("...iJ,...J->...i", F, f)
        lam = np.sqrt(np.einsum("...i,...i->...", a, a))
        g, dg = self._g_dg(lam)
        t = self.t_max if t_max is None else np.asarray(t_max, dtype=np.float64)
        T = t * g
        dT = t * dg
        batch = np.broadcast_shapes(F.shape[:-2], f.shape[:-1], np.shape(T))
        af = np.broadcast_to(a[..., :, None] * f[..., None, :], batch + (3, 3))
        T = np.broadcast_to(T, batch)
        P = T[..., None, None] * af
        ff = f[..., :, None] * f[..., None, :]
        A = (np.broadcast_to(dT / lam, batch)[..., None, None, None, None]) * _outer(af, af)
        for i in range(3):
            A[..., i, :, i, :] += T[..., None, None] * ff
        return P, A


# --------------------------------------------------------------------------------------
# growth
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FiberGrowth:
    r"""Multiplicative growth (prestretch) along the fibers.

    Parameters
    ----------
    stretch : float
        Growth stretch :math:`\vartheta > 0` along the fibers (dimensionless); > 1 lengthens
        the stress-free fibers, so a body held at ``F = I`` is compressed along them.

    Raises
    ------
    ValueError
        If ``stretch`` is not a finite positive number.

    Notes
    -----
    .. math::

        F = F_e F_g, \qquad F_g = I + (\vartheta - 1) f_0 \otimes f_0, \qquad
        W(F) = \det(F_g)\, W_e(F F_g^{-1}).

    The assembly composes a passive response at :math:`F_e` with
    :func:`harpx.mechanics.kinematics.push_growth_response`.

    References
    ----------
    .. [1] Rodriguez EK, Hoger A, McCulloch AD. J Biomech 27:455--467, 1994.

    Examples
    --------
    >>> from harpx.mechanics.fiber_laws import FiberGrowth
    >>> np.diag(FiberGrowth(1.1).tensor([1.0, 0.0, 0.0])).tolist()
    [1.1, 1.0, 1.0]
    """

    stretch: float
    needs_fibers: ClassVar[bool] = True

    def __post_init__(self) -> None:
        _check("stretch", self.stretch)

    def tensor(self, fiber: ArrayLike) -> FloatArray:
        """Growth tensor ``Fg = I + (stretch - 1) f0 ⊗ f0``.

        Parameters
        ----------
        fiber : array_like, shape (..., 3)
            Reference fiber directions ``f0`` (normalised here).

        Returns
        -------
        ndarray, shape (..., 3, 3)
            ``Fg`` (dimensionless).
        """
        return growth_tensor(fiber, self.stretch)
