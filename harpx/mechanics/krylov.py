"""Preconditioned Krylov loops of :class:`~harpx.mechanics.linsolve.LinearSolver`'s ``reuse``.

Conjugate gradients (symmetric matrices) and BiCGSTAB (others), started from zero and
preconditioned by the solve phase of an earlier factorisation, with one stopping rule
(:class:`Stop`): a relative residual, or (``measure="step"``) the relative error of the
solution as the preconditioner estimates it, and an early give-up when the residual falls
too slowly for the iteration budget. A loop returns None when it does not converge; the
caller then factorises.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import numpy as np

from harpx._typing import FloatArray

__all__ = ["Measure", "Stop", "bicgstab", "cg", "refine", "vector_norm"]

#: What the ``reuse`` loop's tolerance bounds (``LinearSolver(reuse_measure=...)``)
Measure = Literal["residual", "step"]


#: The Krylov loop of ``reuse`` gives up on a matrix from this iteration on when the mean rate
#: of decrease of its residual so far would need more than ``_GIVE_UP_SLACK`` times
#: ``reuse_iterations`` to reach the tolerance (chosen on the residual histories of the
#: tracking benchmarks, benchmarks/results/tracking_speed.md).
_GIVE_UP_AFTER = 4
_GIVE_UP_SLACK = 1.25


def _dot(a: FloatArray, b: FloatArray) -> float:
    """``a · b`` without BLAS: OpenBLAS runs its dot product on several threads from 10 000
    entries, whose spinning then takes a second core beside each PARDISO solve phase."""
    return float(np.einsum("i,i->", a, b))


def vector_norm(a: FloatArray) -> float:
    """Euclidean norm without BLAS (see :func:`_dot`).

    Parameters
    ----------
    a : ndarray, shape (n,)
        A vector.

    Returns
    -------
    float
        ``sqrt(a · a)``.
    """
    return float(np.sqrt(_dot(a, a)))


class Stop:
    """The stopping rule of the Krylov loops of ``reuse`` for one right-hand side ``b``.

    With ``measure="residual"`` the loop has converged when its residual norm is at most
    ``target = reuse |b|``; with ``measure="step"`` when the held factorisation's solve of
    the residual (an estimate of the error of ``x``, :meth:`reached`) is at most ``reuse |x|``.
    It runs at most ``limit`` iterations, gives up early (:meth:`give_up`) and records in
    ``iterations`` how many it ran.

    Parameters
    ----------
    b : ndarray, shape (n,)
        The right-hand side; its norm is ``first``, the scale of ``target``.
    reuse : float
        Relative accuracy in (0, 1) (``LinearSolver(reuse=...)``).
    limit : int
        Iteration limit of the loop (steps, for :func:`refine`).
    measure : {"residual", "step"}, default "residual"
        What ``reuse`` bounds: the relative residual, or the relative error of ``x`` as the
        preconditioner estimates it (``LinearSolver(reuse_measure=...)``).
    """

    def __init__(
        self, b: FloatArray, reuse: float, limit: int, measure: Measure = "residual"
    ) -> None:
        self.first = vector_norm(b)
        self.reuse = reuse
        self.target = reuse * self.first
        self.limit = limit
        self.measure = measure
        self.iterations = 0
        self.norm = self.first  # the loop's residual norm when it last checked

    def reached(self, norm: float, x: FloatArray, correction: FloatArray | None) -> bool:
        """Whether ``x`` (residual norm ``norm``) is accurate enough.

        ``correction`` is the held factorisation's solve of the residual, ``M⁻¹ r``: with a
        preconditioner close to the matrix it is close to the error ``x* − x`` itself, so
        ``|M⁻¹ r| <= reuse |x|`` bounds the relative error of the step (inexact Newton;
        Dembo, Eisenstat & Steihaug 1982, SIAM J. Numer. Anal. 19:400).

        Parameters
        ----------
        norm : float
            The loop's residual norm ``|b − K x|``; recorded as ``self.norm``.
        x : ndarray, shape (n,)
            The current iterate.
        correction : ndarray, shape (n,), or None
            ``M⁻¹ r`` for ``measure="step"`` (None there means not reached); not used for
            ``measure="residual"``.

        Returns
        -------
        bool
            ``norm <= target`` (``"residual"``), or ``|correction| <= reuse |x|``
            (``"step"``).
        """
        self.norm = norm
        if self.measure == "residual":
            return norm <= self.target
        return correction is not None and vector_norm(correction) <= self.reuse * vector_norm(x)

    def accepted_residual(self) -> float:
        """The largest true residual norm ``|b − K x|`` accepted once the loop has stopped.

        Returns
        -------
        float
            ``target``, or with ``measure="step"`` the larger of ``target`` and twice the
            loop's own last residual norm (its recurrence drifts from the true one by
            rounding only).
        """
        return self.target if self.measure == "residual" else max(self.target, 2.0 * self.norm)

    def give_up(self, k: int, norm: float) -> bool:
        """Whether the loop stops at iteration ``k`` with residual ``norm`` (of ``first``).

        From iteration ``_GIVE_UP_AFTER`` on: when the residual's mean rate of decrease so
        far would not reach ``target`` within ``_GIVE_UP_SLACK`` times ``limit`` iterations
        (CG speeds up as it goes, hence the slack). A factorisation gone stale shows in the
        first iterations, and a failed attempt then costs a few solve phases.

        Parameters
        ----------
        k : int
            The iteration just completed (from 1).
        norm : float
            The loop's residual norm after it.

        Returns
        -------
        bool
            True if ``norm`` is not finite, or from iteration ``_GIVE_UP_AFTER`` on if it is
            not below ``first`` or decreases too slowly.
        """
        if not np.isfinite(norm):
            return True
        if k < _GIVE_UP_AFTER:
            return False
        if norm >= self.first:
            return True
        limit = _GIVE_UP_SLACK * self.limit
        return bool(k * np.log(self.target / self.first) < limit * np.log(norm / self.first))


_Operator = Callable[[FloatArray], FloatArray]


def cg(apply: _Operator, precondition: _Operator, b: FloatArray, stop: Stop) -> FloatArray | None:
    """Preconditioned conjugate gradients from zero.

    Parameters
    ----------
    apply : callable
        ``apply(v) -> K v``, the product with the matrix, shape (n,) to (n,).
    precondition : callable
        ``precondition(r) -> M⁻¹ r``, the solve with the held factorisation.
    b : ndarray, shape (n,)
        Right-hand side.
    stop : Stop
        Stopping rule for ``b``; its ``iterations`` is set to the iterations run.

    Returns
    -------
    ndarray, shape (n,) or None
        The solution once ``stop`` is reached; None if the loop breaks down (a singular or
        indefinite matrix), gives up or runs out of iterations.
    """
    x = np.zeros_like(b)
    r = b.copy()
    z = precondition(r)
    p = z.copy()
    rz = _dot(r, z)
    for k in range(1, stop.limit + 1):
        q = apply(p)
        pq = _dot(p, q)
        if not (np.isfinite(pq) and pq != 0.0 and np.isfinite(rz) and rz != 0.0):
            return None  # a breakdown: singular or indefinite
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        stop.iterations = k
        norm = vector_norm(r)
        if stop.measure == "residual" and stop.reached(norm, x, None):
            return x
        if stop.give_up(k, norm):
            return None
        z = precondition(r)
        if stop.measure == "step" and stop.reached(norm, x, z):
            return x
        rz_new = _dot(r, z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return None


def refine(
    apply: _Operator, precondition: _Operator, b: FloatArray, stop: Stop
) -> FloatArray | None:
    """Iterative refinement from ``M⁻¹ b``; None: not converged within ``stop.limit`` steps.

    Each step adds the correction ``c = M⁻¹ (b − K x)``, with the residual computed in double
    precision; with ``M`` a factorisation of ``K`` itself in single precision the error falls
    by about ``cond(K) × 6e-8`` a step, so one or two steps reach double-precision-worthy
    accuracy on a matrix of condition below ~10⁶ (mixed-precision refinement: Moler 1967,
    J. ACM 14:316; Carson & Higham 2018, SIAM J. Sci. Comput. 40:A817). Unlike conjugate
    gradients it needs no definiteness. It stops when :meth:`Stop.reached` holds for the
    residual and correction of the current ``x``, and returns ``x`` plus that correction.

    Parameters
    ----------
    apply, precondition, b, stop : see :func:`cg`
        As for :func:`cg`; the ``limit`` of ``stop`` bounds the refinement steps, and its
        ``iterations`` records them.

    Returns
    -------
    ndarray, shape (n,) or None
        The refined solution; None if the residual or correction is not finite or
        ``stop`` is not reached within ``stop.limit`` steps.
    """
    x = precondition(b)
    for k in range(1, stop.limit + 1):
        r = b - apply(x)
        norm = vector_norm(r)
        correction = precondition(r)
        stop.iterations = k
        if not (np.isfinite(norm) and np.all(np.isfinite(correction))):
            return None
        if stop.reached(norm, x, correction):
            return x + correction
        x += correction
    return None


def bicgstab(
    apply: _Operator, precondition: _Operator, b: FloatArray, stop: Stop
) -> FloatArray | None:
    """Right-preconditioned BiCGSTAB from zero.

    Parameters
    ----------
    apply, precondition, b, stop : see :func:`cg`
        The matrix product, the held factorisation's solve, the right-hand side and the
        stopping rule, as for :func:`cg`.

    Returns
    -------
    ndarray, shape (n,) or None
        The solution once ``stop`` is reached; None if the loop breaks down, gives up or
        runs out of iterations.
    """
    x = np.zeros_like(b)
    r = b.copy()
    shadow = b.copy()
    p = np.zeros_like(b)
    v = np.zeros_like(b)
    rho_old = alpha = omega = 1.0
    for k in range(1, stop.limit + 1):
        rho = _dot(shadow, r)
        if not (np.isfinite(rho) and rho != 0.0 and omega != 0.0):
            return None  # a breakdown
        p = r + (rho / rho_old) * (alpha / omega) * (p - omega * v)
        p_hat = precondition(p)
        v = apply(p_hat)
        sv = _dot(shadow, v)
        if not (np.isfinite(sv) and sv != 0.0):
            return None
        alpha = rho / sv
        s = r - alpha * v
        stop.iterations = k
        if stop.measure == "residual" and stop.reached(vector_norm(s), x, None):
            return x + alpha * p_hat
        s_hat = precondition(s)
        t = apply(s_hat)
        tt = _dot(t, t)
        if not (np.isfinite(tt) and tt != 0.0):
            return None
        omega = _dot(t, s) / tt
        x += alpha * p_hat + omega * s_hat
        r = s - omega * t
        norm = vector_norm(r)
        correction = precondition(r) if stop.measure == "step" else None
        if stop.reached(norm, x, correction):
            return x
        if stop.give_up(k, norm):
            return None
        rho_old = rho
    return None
