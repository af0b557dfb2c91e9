r"""Vectorised residual and consistent tangent of the total-Lagrangian hyperelastic energy.

Energy
------
With reference gradients :math:`\nabla N_a = \partial N_a/\partial X` at every Gauss point,
:math:`F = I + \sum_a u_a \otimes \nabla N_a`, :math:`J = \det F`, cofactor
:math:`\operatorname{cof}F = J F^{-T}`, and growth :math:`F = F_e F_g`,
:math:`J_g = \det F_g`, the stored energy of the body is

.. math::

    \Pi(u) = \sum_e \int_e J_g\, \bar W(F F_g^{-1})\, dV + \Pi_{vol}(u),

where :math:`\bar W` is the material's isochoric energy (``isochoric_response``) plus the
active fibre stress (not an energy in general, but its stress and tangent enter in the same
place). Two volumetric treatments are offered (``Body.volumetric``):

* ``"pointwise"`` (plain displacement formulation; locks when :math:`\kappa \gg C_1`):
  :math:`\Pi_{vol} = \sum_e \int_e J_g U(J/J_g)\, dV`.
* ``"mean-dilatation"`` (default; Simo--Taylor--Pister three-field :math:`u`--:math:`p`--
  :math:`\theta` with element-constant pressure and dilatation, statically condensed):
  :math:`\Pi_{vol} = \sum_e V_e J_{g,e} U(\theta_e / J_{g,e})`, with
  :math:`V_e = \int_e dV` and :math:`\theta_e = V_e^{-1}\int_e J\, dV`.
  For uncoupled materials the modified gradient :math:`\bar F = (\theta/J)^{1/3}F` has the
  same isochoric part as :math:`F`, so the isochoric energy is evaluated with :math:`F`
  itself; only the volumetric energy sees :math:`\theta_e`. Condensing the element pressure
  :math:`p_e = U'(\theta_e/J_{g,e})` gives exactly the formulas below. The same treatment
  serves hex8 (Q1/P0) and hex20 (Q2/P0, inf--sup stable).
* ``"nodal-dilatation"`` (tet4 and tet10; average nodal pressure, Bonet & Burton 1998): a linear
  tetrahedron has one dilatation per cell, so the mean dilatation is the pointwise one and
  locks. Instead the volume is averaged over the cells around each vertex :math:`a`:
  :math:`v_a = \sum_{e \ni a} v_e/4` with :math:`v_e = \int_e J\, dV`, grown reference
  volume :math:`G_a = \sum_{e \ni a} V_e J_{g,e}/4`, energy
  :math:`\Pi_{vol} = \sum_a G_a U(v_a/G_a)`. There are about as many vertices as
  incompressibility constraints a tetrahedral mesh can carry (one per vertex instead of
  one per cell, ~5.5 cells per vertex), which removes the locking. The residual is that of
  an element pressure :math:`\bar p_e = \tfrac14\sum_{a \in e} U'(v_a/G_a)`; the tangent
  adds :math:`\sum_a \frac{U''(v_a/G_a)}{G_a}\, \beta_a \beta_a^T` with
  :math:`\beta_a = \sum_{e \ni a} b_e/4`, which couples the dofs of all cells around
  a vertex (the stiffness pattern is widened accordingly, :func:`sparsity`). For tet10 the
  vertex shares are weighted by the linear shape functions, :math:`v_a = \sum_{e \ni a}
  \int_e \lambda_a J\, dV`, :math:`G_a = \sum_{e \ni a} J_{g,e}\int_e \lambda_a dV`,
  and the pressure :math:`p = \sum_a \lambda_a U'(v_a/G_a)` is continuous and linear:
  Taylor--Hood P2/P1 with a lumped pressure mass (tet4 is the case of one Gauss point,
  :math:`\lambda_a = 1/4`).
* ``"linear-dilatation"`` (Q2/P1-disc for hex20): the same with the dilatation and pressure
  linear in each element, :math:`\theta = \Pi_e J` the element-wise :math:`L^2` projection
  onto :math:`\psi = (1, X - X_c, Y - Y_c, Z - Z_c)`, energy
  :math:`\sum_e \int_e J_g U(\theta/J_g)\, dV`. Optimal for hex20 (L2 error
  :math:`O(h^3)` where Q2/P0 is limited by its constant pressure).

Residual
--------
With :math:`b_{e,ai} = \int_e (\operatorname{cof}F)_{iJ}\, \partial_J N_a\, dV
= \partial (V_e\theta_e)/\partial u_{ai}`:

.. math::

    r_{ai} = \sum_e \int_e \big(P^{iso}_{iJ} + p\, (\operatorname{cof}F)_{iJ}\big)
             \partial_J N_a\, dV ,

with :math:`p = p_e` (mean dilatation), :math:`p = \Pi_e U'(\theta/J_g)` (linear
dilatation) or :math:`p = U'(J/J_g)` (pointwise), and
:math:`P^{iso}` already pushed through the growth split (``kinematics.push_growth_response``).

Tangent
-------
Using :math:`\partial(\operatorname{cof}F)_{iJ}/\partial F_{kL}
= J^{-1}\big[(\operatorname{cof}F)_{iJ}(\operatorname{cof}F)_{kL}
- (\operatorname{cof}F)_{iL}(\operatorname{cof}F)_{kJ}\big]`:

.. math::

    K_{ai,bk} = \int_e \partial_J N_a\, \mathbb{A}_{iJkL}\, \partial_L N_b\, dV
              + \frac{U''(\theta_e/J_{g,e})}{J_{g,e} V_e}\, b_{e,ai}\, b_{e,bk}
              \quad\text{(mean dilatation)},

and in general (the mean dilatation is the case :math:`\psi = 1`)
:math:`C^T M^{-1} D M^{-1} C` with :math:`C = \int_e \psi\, b\, dV`,
:math:`M = \int_e \psi\psi^T dV`, :math:`D = \int_e \psi\, U''(\theta/J_g)/J_g\,
\psi^T dV`,

.. math::

    \mathbb{A} = \mathbb{A}^{iso}
      + \frac{p}{J}\big(\operatorname{cof}F \otimes \operatorname{cof}F
      - \operatorname{cof}F \,\overline{\otimes}\, \operatorname{cof}F\big)
      \;\Big[+ \frac{U''(J/J_g)}{J_g}\, \operatorname{cof}F \otimes \operatorname{cof}F
      \ \text{(pointwise only)}\Big].

The pointwise volumetric terms are terms of :math:`\mathbb A` itself
(:math:`(p/J)(\operatorname{cof}F \otimes \operatorname{cof}F - \operatorname{cof}F
\,\overline{\otimes}\, \operatorname{cof}F) = pJ\,(H \otimes H - H \odot H)` with
:math:`H = F^{-T}`); the condensed block :math:`C^T M^{-1} D M^{-1} C` is added per element.
A material with a factored tangent (``isochoric_factors``, e.g. neo-Hookean;
:mod:`harpx.mechanics.kernel`) is contracted without forming :math:`\mathbb A`: its
low-rank part and the condensed block in one batched ``(3 n_b, m n_{qp}) @ (m n_{qp}, 3
n_b)`` product per element, the :math:`H \odot H` part (material and volumetric weights
together) in one ``(3 n_b, n_{qp}) @ (n_{qp}, 3 n_b)`` product; about
:math:`O(n_{el}\, n_{qp}\, (3 n_b)^2 (m + 1))` at BLAS speed in cache-sized element blocks.
Other materials (Guccione, active stress, growth) form :math:`\mathbb A` and contract it in
two batched products per block (``A·∇N_b`` over :math:`L`, then ``∇N_a^T·(…)`` over the
Gauss points and :math:`J` at once, :math:`O(n_{el}\, n_{qp}\, (3 n_b)^2\, 3)`). Element
matrices are scattered into a CSR matrix whose pattern (``indptr``, ``indices`` and the
element-entry → CSR-position map) is computed once per body (:func:`sparsity`) from the
scalar pattern by 3×3 block expansion.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse

from harpx._blas import matmul_one_thread
from harpx._typing import FloatArray, IntArray
from harpx.mechanics import kernel, kinematics

if TYPE_CHECKING:
    from harpx.mechanics.body import Body

__all__ = [
    "Internal",
    "Pattern",
    "first_piola",
    "cauchy_stress",
    "internal_forces",
    "linearised_jacobian",
    "material_response",
    "sparsity",
]

#: target size (floats) of the per-block temporary in the tangent contraction
_BLOCK_FLOATS = 4_000_000


@dataclass(frozen=True)
class Pattern:
    """CSR sparsity of a body's stiffness matrix, built once and reused.

    Attributes
    ----------
    ndof : int
        Matrix size.
    indptr, indices : ndarray of int32
        CSR structure (sorted column indices per row).
    element_positions : ndarray of int64, shape (ncell, nb, 3, 3, nb)
        CSR data position of element entry ``(a, i, k, b)`` = (row dof ``3 s_a + i``,
        column dof ``3 s_b + k``).
    diagonal : ndarray of int64, shape (ndof,)
        CSR data position of each diagonal entry.
    row_of_entry : ndarray of int32, shape (nnz,)
        Row of every stored entry.
    """

    ndof: int
    indptr: NDArray[np.int32]
    indices: NDArray[np.int32]
    element_positions: IntArray
    diagonal: IntArray
    row_of_entry: NDArray[np.int32]
    _scalar_keys: IntArray
    _scalar_indptr: IntArray
    _n_scalar: int

    @property
    def nnz(self) -> int:
        """Number of stored entries."""
        return int(self.indices.size)

    def matrix(self, data: FloatArray) -> sparse.csr_matrix:
        """A CSR matrix on this pattern (shares ``indptr``/``indices``)."""
        K = sparse.csr_matrix((data, self.indices, self.indptr), shape=(self.ndof, self.ndof))
        K.has_sorted_indices = True
        return K

    def positions(self, rows: ArrayLike, cols: ArrayLike) -> IntArray:
        """CSR data positions of ``(rows, cols)`` pairs, which must lie in the pattern.

        Parameters
        ----------
        rows, cols : array_like of int
            Dof ids of the same shape.

        Returns
        -------
        ndarray of int64
            Positions into ``data``, same shape as ``rows``.

        Raises
        ------
        ValueError
            If a pair is not in the pattern.
        """
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.asarray(cols, dtype=np.int64)
        srow, scol = rows // 3, cols // 3
        key = srow * self._n_scalar + scol
        p = np.searchsorted(self._scalar_keys, key)
        p = np.minimum(p, self._scalar_keys.size - 1)
        if not np.all(self._scalar_keys[p] == key):
            raise ValueError("some (row, col) pairs are not in the body's stiffness pattern")
        start = self._scalar_indptr[srow]
        deg = self._scalar_indptr[srow + 1] - start
        return 9 * start + 3 * deg * (rows % 3) + 3 * (p - start) + cols % 3


def sparsity(body: Body) -> Pattern:
    """The body's stiffness pattern, computed on first use and cached on the body.

    Parameters
    ----------
    body : Body
        The body.

    Returns
    -------
    Pattern
    """
    return body.cached("sparsity", lambda: _build_sparsity(body))


def _build_sparsity(body: Body) -> Pattern:
    sd = body.cell_scalar_dofs
    ns = int(body.n_dof_nodes)
    nel, nb = sd.shape
    keys = (sd[:, :, None].astype(np.int64) * ns + sd[:, None, :]).ravel()  # (e, a, b)
    if getattr(body, "volumetric", None) == "nodal-dilatation":
        # dofs of all cells around a vertex are coupled through its nodal dilatation
        inc = _vertex_incidence(sd, ns, body.vertex_weights.shape[1])
        S = (inc.T @ inc).tocoo()
        uniq = np.unique(np.concatenate([keys, S.row.astype(np.int64) * ns + S.col]))
        inv = np.searchsorted(uniq, keys)
    else:
        uniq, inv = np.unique(keys, return_inverse=True)
    srow = uniq // ns
    scol = uniq % ns
    sindptr = np.zeros(ns + 1, dtype=np.int64)
    np.cumsum(np.bincount(srow, minlength=ns), out=sindptr[1:])
    deg = np.diff(sindptr)
    rank = np.arange(uniq.size) - sindptr[srow]
    # vector entry (scalar entry p, i, k) -> 9 start + 3 deg i + 3 rank + k
    base = 9 * sindptr[srow] + 3 * rank  # (nnz_s,)
    i3 = np.arange(3)
    pos_pik = base[:, None, None] + 3 * deg[srow][:, None, None] * i3[None, :, None] + i3
    nnz = 9 * uniq.size
    indices = np.empty(nnz, dtype=np.int32)
    indices[pos_pik.ravel()] = np.broadcast_to(3 * scol[:, None, None] + i3, pos_pik.shape).ravel()
    indptr = np.empty(3 * ns + 1, dtype=np.int64)
    indptr[:-1] = (9 * sindptr[:-1, None] + 3 * deg[:, None] * i3).ravel()
    indptr[-1] = nnz
    inv = inv.reshape(nel, nb, nb)  # (e, a, b)
    # element layout (e, a, i, k, b)
    element_positions = pos_pik[inv]  # (e, a, b, i, k)
    element_positions = np.ascontiguousarray(element_positions.transpose(0, 1, 3, 4, 2))
    row_of_entry = np.repeat(np.arange(3 * ns, dtype=np.int32), np.diff(indptr))
    pat = Pattern(
        ndof=3 * ns,
        indptr=indptr.astype(np.int32),
        indices=indices,
        element_positions=element_positions,
        diagonal=np.empty(0, dtype=np.int64),
        row_of_entry=row_of_entry,
        _scalar_keys=uniq,
        _scalar_indptr=sindptr,
        _n_scalar=ns,
    )
    d = np.arange(3 * ns)
    return dataclasses.replace(pat, diagonal=pat.positions(d, d))


def _vertex_incidence(sd: IntArray, ns: int, nv: int) -> sparse.csr_matrix:
    """(ns, ns) 0/1 matrix: row ``a`` marks the scalar dofs of every cell containing ``a``.

    Only the cells' first ``nv`` dofs (their vertices, the pressure nodes) have rows.
    """
    nel, nb = sd.shape
    rows = np.repeat(sd[:, :nv], nb, axis=1).ravel()
    cols = np.tile(sd, (1, nv)).ravel()
    inc = sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(ns, ns))
    inc.data[:] = 1.0
    return inc


def material_response(
    body: Body, F: FloatArray, *, tangent: bool = True
) -> tuple[FloatArray, FloatArray | None]:
    """Isochoric (+ active) first Piola--Kirchhoff stress and tangent at the Gauss points.

    Growth is composed (``F = Fe Fg``); the volumetric energy is not included.

    Parameters
    ----------
    body : Body
        Supplies material, fibres, active law and level, growth.
    F : ndarray, shape (ncell, nqp, 3, 3)
        Deformation gradients.
    tangent : bool, default True
        Also return the tangent.

    Returns
    -------
    P : ndarray, shape (ncell, nqp, 3, 3)
        kPa.
    A : ndarray, shape (ncell, nqp, 3, 3, 3, 3) or None
        ``dP_iJ/dF_kL``, kPa.
    """
    Fg = body.growth_tensor
    fiber = body.fibers_qp
    Fe = F if Fg is None else kinematics.split_growth(F, Fg)
    P, A = body.material.isochoric_response(Fe, fiber)
    active = body.active
    if active is not None:
        t_max = body.t_max
        Pa, Aa = active.response(Fe, fiber, t_max=None if t_max is None else t_max[:, None])
        P = P + Pa
        A = A + Aa
    if Fg is not None:
        P, A = kinematics.push_growth_response(P, A, Fg)
    return P, (A if tangent else None)


@dataclass
class Internal:
    """Internal forces of a body at a displacement.

    Attributes
    ----------
    r : ndarray, shape (ndof,) or None
        Internal force vector ``∂Π/∂u`` (mN = kPa·mm²); None if elements inverted (or
        their stress overflowed).
    K : scipy.sparse.csr_matrix or None
        Consistent tangent on ``sparsity(body)``.
    min_jacobian : float
        Smallest ``det F`` over all Gauss points.
    inverted_cells : ndarray of int
        Cells with ``det F <= 0`` at some Gauss point, or else cells whose stress or
        tangent is not finite (an exponential law overflowed at extreme strain).
    """

    r: FloatArray | None
    K: sparse.csr_matrix | None
    min_jacobian: float
    inverted_cells: IntArray


def _pressure_space(body: Body) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Element pressure/dilatation basis ψ at the Gauss points and its projector (cached).

    Returns ``psi`` (ncell, nqp, npr), ``psiW = ψᵀ diag(dV)`` (ncell, npr, nqp),
    ``Minv = (ψᵀ W ψ)⁻¹`` (ncell, npr, npr) and the L2 projector ``Pr = ψ Minv ψᵀ W``
    (ncell, nqp, nqp). ``npr`` = 1 (mean dilatation) or 4 (linear dilatation: 1 and the
    centred, scaled coordinates).
    """
    return body.cached("pressure_space", lambda: _build_pressure_space(body))


def _build_pressure_space(body: Body) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    dV = body.dV
    Ve = body.cell_volume
    nel, nq = dV.shape
    if body.volumetric == "linear-dilatation":
        X = body.quadrature_points
        xc = np.einsum("eq,eqi->ei", dV, X) / Ve[:, None]
        ell = np.cbrt(Ve)
        psi = np.concatenate([np.ones((nel, nq, 1)), (X - xc[:, None, :]) / ell[:, None, None]], -1)
    else:
        psi = np.ones((nel, nq, 1))
    psiW = np.ascontiguousarray((psi * dV[..., None]).transpose(0, 2, 1))
    Minv = np.linalg.inv(np.matmul(psiW, psi))
    proj = np.matmul(psi, np.matmul(Minv, psiW))
    return psi, psiW, Minv, proj


def _volumetric(
    body: Body, F: FloatArray, Jc: tuple[FloatArray, FloatArray] | None = None
) -> tuple[FloatArray, FloatArray, FloatArray, dict]:
    """Pressure field p (ncell,nqp), cof F, J and extra data for the tangent.

    ``Jc`` is ``(det F, cof F)`` if already computed.
    """
    Jg = body.growth_jacobian
    J, cof = _det_cof(F) if Jc is None else Jc
    mat = body.material
    extra: dict = {}
    jg = 1.0 if Jg is None else Jg[:, None]
    if body.volumetric == "pointwise":
        _, dU, d2U = mat.volumetric(J / jg)
        p = np.asarray(dU, dtype=np.float64)
        extra["d2U"] = np.asarray(d2U, dtype=np.float64) / jg
        return p, cof, J, extra
    if body.volumetric == "nodal-dilatation":
        # vertex a of cell e weighs its Gauss points by the linear (P1) shape function λ_a:
        # tet4 1/4 at the centroid; tet10 a continuous linear pressure (Taylor–Hood P2/P1)
        wdV = body.dV[:, :, None] * body.vertex_weights  # (ncell, nqp, nv)
        nv = wdV.shape[2]
        sd = body.cell_scalar_dofs[:, :nv]  # the vertices
        ns = int(body.n_dof_nodes)
        grown = wdV.sum(axis=1) * (1.0 if Jg is None else Jg[:, None])  # (ncell, nv)
        G = np.bincount(sd.ravel(), weights=grown.ravel(), minlength=ns)
        vol = np.einsum("eq,eqa->ea", J, wdV)
        v = np.bincount(sd.ravel(), weights=vol.ravel(), minlength=ns)
        used = G > 0
        Jn = np.ones(ns)
        Jn[used] = v[used] / G[used]
        _, dU, d2U = mat.volumetric(Jn)
        dU = np.broadcast_to(np.asarray(dU, dtype=np.float64), (ns,))
        p = matmul_one_thread(dU[sd], body.vertex_weights.T)  # (ncell, nqp)
        c = np.zeros(ns)
        c[used] = np.broadcast_to(np.asarray(d2U, dtype=np.float64), (ns,))[used] / G[used]
        extra["nodal"] = c
        extra["nodal_weights"] = wdV
        return p, cof, J, extra
    psi, psiW, Minv, proj = _pressure_space(body)
    theta = np.matmul(proj, J[..., None])[..., 0]  # L2 projection of J per element
    _, dU, d2U = mat.volumetric(theta / jg)
    # projected pressure p̃ = Pr U'(θ) (Pr is self-adjoint in the dV-weighted product)
    p = np.matmul(proj, np.asarray(dU, dtype=np.float64)[..., None])[..., 0]
    D = np.matmul(psiW * (np.asarray(d2U, dtype=np.float64) / jg)[:, None, :], psi)
    extra["Q"] = np.matmul(Minv, np.matmul(D, Minv))  # (ncell, npr, npr)
    extra["theta"] = theta
    return p, cof, J, extra


def _stand_in_volumetric(
    body: Body, F: FloatArray, cof: FloatArray, Jt: ArrayLike, p: FloatArray, extra: dict
) -> tuple[FloatArray, dict]:
    """Pressure and tangent data of ``_volumetric`` at a stand-in ``det F`` (``Jt``), or the
    given ``(p, extra)`` where its dilatation is not a volume ratio (not finite, or not
    positive after the formulation's projection)."""
    Jt = np.asarray(Jt, dtype=np.float64)
    if Jt.shape != p.shape:
        raise ValueError(
            f"tangent_jacobian has shape {Jt.shape!r}; expected (ncell, nqp) = {p.shape!r}"
        )
    if not Jt.min() > 0.0:  # also NaN
        return p, extra
    pt, _, _, xt = _volumetric(body, F, (Jt, cof))
    positive = "theta" not in xt or bool((xt["theta"] > 0.0).all())
    checks = [pt, *(xt[k] for k in ("d2U", "Q", "nodal") if k in xt)]
    if positive and all(np.isfinite(c).all() for c in checks):
        return pt, xt
    return p, extra


def linearised_jacobian(body: Body, u: ArrayLike, step: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """``det F`` at ``u`` and its derivative along ``step`` at the Gauss points.

    ``J(u + α step) = J + α dJ + O(α²)`` with ``dJ = cof F(u) : Grad step``: the
    dilatation a linearised step carries (``internal_forces``' ``tangent_jacobian``).

    Parameters
    ----------
    body : Body
        The body.
    u, step : array_like, shape (ndof,)
        Displacement and its increment, mm.

    Returns
    -------
    J, dJ : ndarray, shape (ncell, nqp)
        Dimensionless.
    """
    J, cof = _det_cof(_gradient(body, u) + np.eye(3))
    dJ = np.einsum("eqij,eqij->eq", cof, _gradient(body, step))
    return J, dJ


def _gradient(body: Body, u: ArrayLike) -> FloatArray:
    """``Grad u`` (ncell, nqp, 3, 3): one (3, nb) @ (nb, 3 nq) product per element."""
    nel, nq = body.dV.shape
    grads = body.cached("gradient_layouts", lambda: kernel.Gradients.of(body.grad_N))
    ue = body.element_displacement(u)  # (e, a, i)
    return np.matmul(np.swapaxes(ue, 1, 2), grads.Gn).reshape(nel, 3, nq, 3).transpose(0, 2, 1, 3)


def _det_cof(F: FloatArray) -> tuple[FloatArray, FloatArray]:
    cof = kinematics.cofactor(F)
    J = np.einsum("...j,...j->...", F[..., 0, :], cof[..., 0, :])
    return J, cof


def first_piola(body: Body, u: ArrayLike) -> FloatArray:
    """Total first Piola--Kirchhoff stress at the Gauss points, shape (ncell, nqp, 3, 3), kPa.

    Includes the volumetric pressure of the body's formulation (element-constant for mean
    dilatation).
    """
    F = body.deformation_gradient(u)
    P, _ = material_response(body, F, tangent=False)
    p, cof, _, _ = _volumetric(body, F)
    return P + p[..., None, None] * cof


def cauchy_stress(body: Body, u: ArrayLike) -> FloatArray:
    """Cauchy stress ``σ = J⁻¹ P Fᵀ`` at the Gauss points, shape (ncell, nqp, 3, 3), kPa."""
    F = body.deformation_gradient(u)
    P = first_piola(body, u)
    J = np.linalg.det(F)
    return np.matmul(P, np.swapaxes(F, -1, -2)) / J[..., None, None]


def internal_forces(
    body: Body,
    u: ArrayLike,
    *,
    tangent: bool = True,
    pressure_stiffness: bool = True,
    tangent_jacobian: ArrayLike | None = None,
) -> Internal:
    """Internal force vector and consistent tangent of the body's stored energy.

    Parameters
    ----------
    body : Body
        The body.
    u : array_like, shape (ndof,)
        Displacement, mm.
    tangent : bool, default True
        Assemble the tangent too.
    pressure_stiffness : bool, default True
        Include the initial-stress (geometric) stiffness of the volumetric pressure,
        (p/J)(cof F ⊗ cof F − cof F ⊙ cof F) (module notes). False gives a
        Gauss–Newton-type tangent (the residual is unchanged): far from equilibrium a nearly
        incompressible body (κ ≫ C1) can carry pressures p ≫ μ after a large step, which make
        the consistent tangent indefinite; without that term the tangent stays positive on
        the isochoric modes and the next step restores the volume instead of diverging.
    tangent_jacobian : array_like, shape (ncell, nqp), optional
        Gauss-point values that stand in for ``det F`` when the dilatation of the
        *tangent's* volumetric terms (pressure stiffness, condensed or pointwise ``U''``
        block) is formed -- projected, vertex-averaged or pointwise as the body's
        formulation; the residual and the kinematics keep ``u``'s own ``det F``. Newton
        (:mod:`harpx.mechanics.newton`) passes the linearised ``J + cof F : Grad δu`` of
        the previous iterate: the dilatation a three-field u--p--θ iteration carries.

    Returns
    -------
    Internal
        ``r`` and ``K`` are None when some Gauss point has ``det F <= 0``, or some cell's
        stress or tangent is not finite (then ``inverted_cells`` lists the cells).
    """
    G = body.grad_N  # (e, q, a, J)
    nel, nq, nb, _ = G.shape
    grads = body.cached("gradient_layouts", lambda: kernel.Gradients.of(G))
    F = _gradient(body, u) + np.eye(3)  # F_iJ = δ_iJ + Σ_a u_ai ∂_J N_a
    Jq, cof = _det_cof(F)
    min_j = float(Jq.min()) if Jq.size else 1.0
    bad = np.nonzero(~(Jq > 0.0).all(axis=1))[0]
    if bad.size or not np.isfinite(min_j):
        return Internal(None, None, min_j, bad)
    # a material with a factored tangent is contracted without forming the 4th-order tensor
    # (harpx.mechanics.kernel); active stress and growth take the full tangent
    factored = hasattr(body.material, "isochoric_factors") and (
        body.active is None and body.growth_tensor is None
    )
    A: FloatArray | None = None
    fac: kernel.TangentFactors | None = None
    with np.errstate(over="ignore", invalid="ignore"):  # checked just below
        if factored and tangent:
            P, fac = body.material.isochoric_factors(F, body.fibers_qp, det_cof=(Jq, cof))
        elif factored:
            P = body.material.isochoric_stress(F, body.fibers_qp, det_cof=(Jq, cof))
        else:
            P, A = material_response(body, F, tangent=tangent)
        p, cof, J, extra = _volumetric(body, F, (Jq, cof))
        P = P + p[..., None, None] * cof
        if tangent and tangent_jacobian is not None:
            # pressure and volumetric stiffness of the tangent from the stand-in dilatation;
            # one that is not a volume ratio (a projection not positive everywhere) leaves
            # the tangent at u's own
            p, extra = _stand_in_volumetric(body, F, cof, tangent_jacobian, p, extra)
    # an exponential law (Guccione) overflows at extreme strain before det F reaches 0: such
    # a state is as inadmissible as an inverted one (the caller halves its step)
    with np.errstate(over="ignore", invalid="ignore"):  # inf - inf is the point of the test
        finite = np.isfinite(P.reshape(P.shape[0], -1).sum(axis=1))
        if tangent and A is not None:
            finite &= np.isfinite(A.reshape(A.shape[0], -1).sum(axis=1))
        if tangent and fac is not None:
            finite &= np.isfinite(fac.Z.reshape(fac.Z.shape[0], -1).sum(axis=1) + fac.c.sum(axis=1))
    if not finite.all():
        return Internal(None, None, min_j, np.nonzero(~finite)[0])
    dV = body.dV
    ed = body.element_dofs
    Pt = (P * dV[..., None, None]).transpose(0, 1, 3, 2).reshape(nel, nq * 3, 3)
    re = np.matmul(grads.Gn, Pt)  # (e, a, i)
    ndof = int(body.ndof)
    # bincount of float weights is float64 (numpy's stubs type it as int)
    r = np.asarray(np.bincount(ed.ravel(), weights=re.ravel(), minlength=ndof), dtype=np.float64)
    if not tangent:
        return Internal(r, None, min_j, bad)
    # Volumetric part (module notes): the initial stress (p/J)(cof ⊗ cof - cof ⊙ cof)
    # = p J (H ⊗ H - H ⊙ H) and the pointwise (U''/Jg) cof ⊗ cof = (U''/Jg) J² H ⊗ H are
    # pointwise terms of the tangent; the condensed block Cᵀ Q C (C = ψᵀ W B) is added per
    # element.
    geo = p * J if pressure_stiffness else np.zeros_like(p)
    hh = geo + extra["d2U"] * J * J if "d2U" in extra else geo
    Q = extra.get("Q")
    H = fac.H if fac is not None else cof / J[..., None, None]
    condensed = None if Q is None else (_pressure_space(body)[1] * J[:, None, :], Q)
    pat = sparsity(body)
    # element matrices (e, a, i, k, b) are added into the CSR data block by block, while
    # they are in cache
    data = np.zeros(pat.nnz)
    sink = kernel.scatter(data, pat.element_positions)
    if fac is not None:
        fac = dataclasses.replace(fac, c=fac.c - geo)
        kernel.factored_tangent(grads, dV, fac, hh, sink, condensed)
    else:
        assert A is not None
        A = A + (hh / (J * J))[..., None, None, None, None] * (
            cof[..., :, :, None, None] * cof[..., None, None, :, :]
        )
        A -= (geo / (J * J))[..., None, None, None, None] * (
            cof[..., :, None, None, :] * np.swapaxes(cof, -1, -2)[..., None, :, :, None]
        )
        kernel.dense_tangent(grads, dV, A, sink, condensed, H)
    nodal = extra.get("nodal")
    if nodal is not None:
        Bq = np.matmul(G, np.swapaxes(cof, -1, -2)).reshape(nel, nq, 3 * nb)  # (e, q, (a, i))
        beta = np.matmul(np.swapaxes(extra["nodal_weights"], 1, 2), Bq)  # (e, nv, 3 nb)
        data += _nodal_tangent(body, pat, beta, nodal)
    return Internal(r, pat.matrix(data), min_j, bad)


def _nodal_tangent(body: Body, pat: Pattern, b: FloatArray, c: FloatArray) -> FloatArray:
    """Pattern data of ``Σ_a c_a β_a β_aᵀ``, ``β_a = Σ_{e∋a} b_{e,a}`` (nodal dilatation).

    ``b`` (ncell, nv, 3 nb) are the gradients ``∂v_{e,a}/∂u`` of each cell's share of the
    volume of its vertices ``a`` (the cell's first ``nv`` dofs), in element-dof order.
    """
    nv = b.shape[1]
    sd = body.cell_scalar_dofs[:, :nv]
    ed = body.element_dofs.reshape(sd.shape[0], -1)
    ns = int(body.n_dof_nodes)
    nel = sd.shape[0]

    def build() -> dict[str, Any]:
        rows = np.broadcast_to(sd[:, :, None], (nel, nv, ed.shape[1]))
        cols = np.broadcast_to(ed[:, None, :], rows.shape)
        keys = rows.astype(np.int64).ravel() * pat.ndof + cols.ravel()
        uniq, inv = np.unique(keys, return_inverse=True)
        return {"inv": inv, "rows": uniq // pat.ndof, "cols": uniq % pat.ndof, "pos": None}

    cache = body.cached("nodal_tangent", build)
    vals = b.ravel()
    beta = sparse.csr_matrix(
        (np.bincount(cache["inv"], weights=vals), (cache["rows"], cache["cols"])),
        shape=(ns, pat.ndof),
    )
    K = (beta.T @ sparse.diags(c) @ beta).tocoo()
    pos = cache["pos"]
    if (
        pos is None
        or pos[0].shape != K.row.shape
        or not (np.array_equal(pos[0], K.row) and np.array_equal(pos[1], K.col))
    ):
        pos = (K.row.copy(), K.col.copy(), pat.positions(K.row, K.col))
        cache["pos"] = pos
    # numpy's stub types every bincount as int; with float weights it is float64
    return np.bincount(pos[2], weights=K.data, minlength=pat.nnz)  # type: ignore[return-value]
