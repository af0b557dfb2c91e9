r"""Element tangent kernels: factored material tangents contracted without forming them.

A material tangent :math:`\mathbb A_{iJkL} = \partial P_{iJ}/\partial F_{kL}` enters the
element stiffness of the total-Lagrangian assembly as

.. math::

    K_{ai,bk} = \sum_q dV_q\, \partial_J N_a\, \mathbb A_{iJkL}\, \partial_L N_b .

Forming :math:`\mathbb A` (81 numbers per Gauss point) and contracting it costs memory
traffic and a batched product per point. The hyperelastic laws of
:mod:`harpx.mechanics.materials` have a tangent of the *factored* form

.. math::

    \mathbb A_{iJkL} = \sum_{r=1}^{m} Y^r_{iJ} Z^r_{kL} + s\, \delta_{ik}\delta_{JL}
                     + c\, H_{iL} H_{kJ}, \qquad H = F^{-T},

(:class:`TangentFactors`; the neo-Hookean law has :math:`m = 2`, :math:`Y = (F, H)`; the
Guccione law has :math:`m = 9` and an extra initial-stress term
:math:`\delta_{ik} S_{JL}` with a matrix :math:`S`, contracted as
:math:`\partial_J N_a S_{JL} \partial_L N_b`). With
the vectors :math:`y^r_{ai} = Y^r_{iJ}\partial_J N_a`, :math:`z^r_{bk} = Z^r_{kL}\partial_L
N_b` and :math:`h_{ai} = H_{iJ}\partial_J N_a` the element matrix is

.. math::

    K_{ai,bk} = \sum_q dV_q \Big[ \sum_r y^r_{ai} z^r_{bk}
      + s\, \delta_{ik}\, \nabla N_a \cdot \nabla N_b + c\, h_{ak} h_{bi} \Big] ,

i.e. one batched matrix product ``(3 nb, m nq) @ (m nq, 3 nb)`` per element for the
low-rank part (the condensed volumetric block of the mean or linear dilatation rides along as
``npr`` extra rows), one ``(3 nb, nq) @ (nq, 3 nb)`` for the :math:`H \odot H` part, whose
3×3 blocks are then transposed, and a scalar ``(nb, 3 nq) @ (3 nq, nb)`` Laplacian-like
product for the :math:`\delta_{ik}` part. The volumetric initial-stress term
:math:`p J (H \otimes H - H \odot H)` of the assembly is absorbed into :math:`Z` (the factor
``h_index`` with :math:`Y = H`) and :math:`c`, so it costs nothing extra. All products run
in element blocks at BLAS speed; no 4th-order array is ever formed.

Element matrices are laid out ``(ncell, nb, 3, 3, nb)`` (entry ``(a, i, k, b)``), the layout
of :attr:`harpx.mechanics.assembly.Pattern.element_positions`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from harpx._typing import FloatArray, IntArray

__all__ = [
    "Gradients",
    "Sink",
    "TangentFactors",
    "dense_tangent",
    "factored_tangent",
    "into",
    "scatter",
]

#: target size (floats) of the per-block temporaries of the element products: a few MB,
#: so that a block's operands stay in cache between the products
_BLOCK_FLOATS = 300_000


@dataclass(frozen=True)
class TangentFactors:
    r"""Factored first elasticity tensor at a batch of points.

    .. math::

        \mathbb A_{iJkL} = \sum_r Y^r_{iJ} Z^r_{kL} + s\, \delta_{ik}\delta_{JL}
                         + c\, H_{iL} H_{kJ}

    Attributes
    ----------
    Y : ndarray, shape (..., m, 3, 3)
        Left factors (any unit ``[Y]``).
    Z : ndarray, shape (..., m, 3, 3)
        Right factors, kPa / ``[Y]``; the low-rank part is symmetric in total
        (:math:`\sum_r Y^r \otimes Z^r = \sum_r Z^r \otimes Y^r`).
    s : ndarray, shape (...)
        Coefficient of :math:`\delta_{ik}\delta_{JL}`, kPa.
    c : ndarray, shape (...)
        Coefficient of :math:`H_{iL} H_{kJ}`, kPa.
    H : ndarray, shape (..., 3, 3)
        :math:`F^{-T}` (dimensionless).
    h_index : int or None
        ``r`` with :math:`Y^r = H` exactly (the assembly adds its volumetric
        :math:`H \otimes H` weight to that :math:`Z^r`), or None.
    S : ndarray, shape (..., 3, 3), or None
        A symmetric matrix coefficient of :math:`\delta_{ik}`: the term
        :math:`\delta_{ik} S_{JL}` is added (the initial-stress term of an anisotropic
        law, e.g. Guccione's :math:`J^{-2/3} \bar S`), kPa.
    """

    Y: FloatArray
    Z: FloatArray
    s: FloatArray
    c: FloatArray
    H: FloatArray
    h_index: int | None = None
    S: FloatArray | None = None

    def dense(self) -> FloatArray:
        """The tensor itself, ``A[..., i, J, k, L]`` (kPa), shape ``(..., 3, 3, 3, 3)``."""
        batch = self.s.shape
        m = self.Y.shape[-3]
        Y = self.Y.reshape(batch + (m, 9))
        Z = self.Z.reshape(batch + (m, 9))
        A = np.matmul(np.swapaxes(Y, -1, -2), Z).reshape(batch + (3, 3, 3, 3))
        H = self.H
        A += self.c[..., None, None, None, None] * (
            H[..., :, None, None, :] * np.swapaxes(H, -1, -2)[..., None, :, :, None]
        )
        s = self.s[..., None, None] * np.eye(3)
        if self.S is not None:
            s = s + self.S
        for i in range(3):
            A[..., i, :, i, :] += s
        return A


#: receives ``(cells, Ke)``: a slice of cells and their element matrices (n, nb, 3, 3, nb)
Sink = Callable[[slice, FloatArray], None]


def scatter(data: FloatArray, positions: IntArray) -> Sink:
    """A sink adding element matrices into CSR ``data`` at ``positions[cells]``.

    Parameters
    ----------
    data : ndarray, shape (nnz,)
        CSR data, accumulated in place (zeros to start).
    positions : ndarray of int, shape (ncell, nb, 3, 3, nb)
        Position in ``data`` of every element entry
        (:attr:`harpx.mechanics.assembly.Pattern.element_positions`).

    Returns
    -------
    callable
        The sink. Entries are added in element order, as ``np.bincount`` of all element
        matrices at once would add them.
    """

    def add(cells: slice, Ke: FloatArray) -> None:
        np.add.at(data, positions[cells].ravel(), Ke.ravel())

    return add


def into(Ke: FloatArray) -> Sink:
    """A sink copying element matrices into ``Ke`` (ncell, nb, 3, 3, nb)."""

    def put(cells: slice, block: FloatArray) -> None:
        Ke[cells] = block

    return put


@dataclass(frozen=True)
class Gradients:
    """Reference shape-function gradients (1/mm) in three layouts (built once per body).

    Attributes
    ----------
    G : ndarray, shape (ncell, nqp, nb, 3)
        ``G[e, q, a, J] = ∂N_a/∂X_J``.
    GT : ndarray, shape (ncell, nqp, 3, nb)
        Its per-point transpose, contiguous.
    Gn : ndarray, shape (ncell, nb, 3 nqp)
        Node-major, columns ``(q, J)``, contiguous.
    """

    G: FloatArray
    GT: FloatArray
    Gn: FloatArray

    @classmethod
    def of(cls, G: FloatArray) -> Gradients:
        """The three layouts of ``G`` (ncell, nqp, nb, 3)."""
        nel, nq, nb, _ = G.shape
        GT = np.ascontiguousarray(np.swapaxes(G, -1, -2))
        Gn = np.ascontiguousarray(G.transpose(0, 2, 1, 3)).reshape(nel, nb, 3 * nq)
        return cls(G, GT, Gn)


def factored_tangent(
    grads: Gradients,
    dV: FloatArray,
    factors: TangentFactors,
    h_weight: FloatArray | None,
    sink: Sink,
    condensed: tuple[FloatArray, FloatArray] | None = None,
) -> None:
    r"""Element stiffness matrices of a factored tangent, handed to ``sink`` block by block.

    Parameters
    ----------
    grads : Gradients
        Reference shape-function gradients in the layouts the products need, 1/mm.
    dV : ndarray, shape (ncell, nqp)
        Quadrature weights times the reference Jacobian, mm³.
    factors : TangentFactors
        Batch shape ``(ncell, nqp)``. ``factors.c`` must already include any volumetric
        :math:`H \odot H` weight.
    h_weight : ndarray, shape (ncell, nqp), or None
        Extra weight of :math:`H \otimes H` (kPa), added to the factor ``h_index`` (the
        volumetric initial-stress and pointwise :math:`U''` terms); ``h_index`` must be set
        when this is given.
    sink : callable
        ``sink(cells, Ke)`` receives the element matrices ``Ke`` (n, nb, 3, 3, nb) of the
        cells ``cells`` (a slice), mN/mm (kPa·mm); ``Ke`` is a buffer reused for the next
        block (:func:`scatter`, :func:`into`).
    condensed : (W, Q), optional
        Statically condensed volumetric block :math:`C^T Q C` with
        :math:`C_{r,ai} = \sum_q W_{rq} H_{iJ} \partial_J N_a` (for the dilatation modes
        :math:`\psi_r`, :math:`W_{rq} = \psi_r J\, dV_q`, so that :math:`C` is the
        derivative of :math:`\int \psi_r J\, dV`): ``W`` (ncell, npr, nqp) in mm³ and ``Q``
        (ncell, npr, npr) in kPa/mm⁶.

    Raises
    ------
    ValueError
        If ``h_weight`` is given but ``factors`` has no ``h_index``.
    """
    G, GT, Gn = grads.G, grads.GT, grads.Gn
    nel, nq, nb, _ = G.shape
    m = factors.Y.shape[2]
    hi = factors.h_index
    npr = 0 if condensed is None else condensed[1].shape[1]
    nt = m * nq + npr
    n3 = 3 * nb
    H = factors.H
    Y, Z = factors.Y, factors.Z
    wc = factors.c * dV
    ws = np.repeat(factors.s * dV, 3, axis=1)  # per (q, J)
    if h_weight is not None and hi is None:
        raise ValueError("h_weight needs factors.h_index")
    step = min(nel, _blocks_step(2 * nt * n3 + 2 * n3 * n3 + nq * n3))
    # buffers of one block, reused (they stay in cache)
    Lb = np.empty((step, nt, n3))  # rows (q, r) | pressure modes; columns (a, i)
    Rb = np.empty((step, nt, n3))  # rows as L; columns (k, b)
    Kb = np.empty((step, n3, n3))  # rows (a, i), columns (k, b)
    Sb = np.empty((step, n3, n3))  # rows (a, k), columns (i, b)
    for s0 in range(0, nel, step):
        sl = slice(s0, min(s0 + step, nel))
        n = sl.stop - sl.start
        L, R, K, S = Lb[:n], Rb[:n], Kb[:n], Sb[:n]
        GTs = GT[sl]  # (n, q, J, b)
        Lq = L[:, : m * nq].reshape(n, nq, m, nb, 3)
        np.einsum("eqaJ,eqriJ->eqrai", G[sl], Y[sl], optimize=True, out=Lq)
        Zs = Z[sl] * dV[sl, :, None, None, None]
        if h_weight is not None:
            assert hi is not None
            Zs[:, :, hi] += (h_weight[sl] * dV[sl])[:, :, None, None] * H[sl]
        np.matmul(Zs.reshape(n, nq, 3 * m, 3), GTs, out=R[:, : m * nq].reshape(n, nq, 3 * m, nb))
        HGt = np.matmul(H[sl], GTs)  # (n, q, i, b): h_bi
        if condensed is not None:
            W, Q = condensed[0][sl], condensed[1][sl]
            Ck = np.matmul(W, HGt.reshape(n, nq, n3))  # (n, npr, (k, b)): C in column layout
            L[:, m * nq :] = np.swapaxes(Ck.reshape(n, npr, 3, nb), -1, -2).reshape(n, npr, n3)
            np.matmul(Q, Ck, out=R[:, m * nq :])
        np.matmul(np.swapaxes(L, 1, 2), R, out=K)
        # c H_iL H_kJ: rows (a, k), columns (i, b), then the 3x3 blocks transposed
        if hi is not None:
            h = Lq[:, :, hi].reshape(n, nq, n3)  # (n, q, (a, k))
        else:
            h = np.einsum("eqaJ,eqiJ->eqai", G[sl], H[sl], optimize=True).reshape(n, nq, n3)
        Rs = (HGt * wc[sl, :, None, None]).reshape(n, nq, n3)
        np.matmul(np.swapaxes(h, 1, 2), Rs, out=S)
        # s δ_ik ∇N_a·∇N_b
        Gns = Gn[sl]
        lap = np.matmul(Gns, np.swapaxes(Gns * ws[sl, None, :], 1, 2))  # (n, a, b)
        if factors.S is not None:  # δ_ik ∂_J N_a S_JL ∂_L N_b
            GS = np.matmul(G[sl], factors.S[sl] * dV[sl, :, None, None])  # (n, q, a, L)
            lap += np.matmul(
                GS.transpose(0, 2, 1, 3).reshape(n, nb, 3 * nq), np.swapaxes(Gns, 1, 2)
            )
        S.reshape(n, nb, 9, nb)[:, :, ::4, :] += lap[:, :, None, :]
        Ke = K.reshape(n, nb, 3, 3, nb)
        Ke += S.reshape(n, nb, 3, 3, nb).transpose(0, 1, 3, 2, 4)
        sink(sl, Ke)


def _blocks_step(per_cell: int) -> int:
    return max(1, _BLOCK_FLOATS // max(per_cell, 1))


def dense_tangent(
    grads: Gradients,
    dV: FloatArray,
    A: FloatArray,
    sink: Sink,
    condensed: tuple[FloatArray, FloatArray] | None = None,
    H: FloatArray | None = None,
) -> None:
    r"""Element stiffness matrices of a full tangent ``A``, handed to ``sink`` block by block.

    Parameters
    ----------
    grads : Gradients
        Reference shape-function gradients, 1/mm.
    dV : ndarray, shape (ncell, nqp)
        Quadrature weights times the reference Jacobian, mm³.
    A : ndarray, shape (ncell, nqp, 3, 3, 3, 3)
        ``dP_iJ/dF_kL`` (kPa), including every pointwise volumetric term.
    sink : callable
        Receives the element matrices block by block, as in :func:`factored_tangent`.
    condensed : (W, Q), optional
        Condensed volumetric block as in :func:`factored_tangent`; needs ``H``.
    H : ndarray, shape (ncell, nqp, 3, 3), optional
        :math:`F^{-T}` (dimensionless).
    """
    G, GT, Gn = grads.G, grads.GT, grads.Gn
    nel, nq, nb, _ = G.shape
    n3 = 3 * nb
    step = min(nel, _blocks_step(nq * 81 + nq * 27 * nb + 2 * n3 * n3))
    Kb = np.empty((step, nb, 3, 3, nb))
    for s0 in range(0, nel, step):
        sl = slice(s0, min(s0 + step, nel))
        n = sl.stop - sl.start
        Ke = Kb[:n]
        # (e, q, J, i, k, L) scaled by dV in one pass
        Ap = A[sl].transpose(0, 1, 3, 2, 4, 5) * dV[sl, :, None, None, None, None]
        B = np.matmul(Ap.reshape(n, nq, 27, 3), GT[sl])  # (e, q, (J, i, k), b)
        np.matmul(Gn[sl], B.reshape(n, nq * 3, 9 * nb), out=Ke.reshape(n, nb, 9 * nb))
        if condensed is not None:
            assert H is not None
            W, Q = condensed[0][sl], condensed[1][sl]
            cg = np.matmul(H[sl], GT[sl]).reshape(n, nq, n3)  # (k, b)
            Ck = np.matmul(W, cg)  # (n, npr, (k, b))
            npr = Ck.shape[1]
            Ca = np.swapaxes(Ck.reshape(n, npr, 3, nb), -1, -2).reshape(n, npr, n3)
            Ke += np.matmul(np.swapaxes(Ca, 1, 2), np.matmul(Q, Ck)).reshape(n, nb, 3, 3, nb)
        sink(sl, Ke)
