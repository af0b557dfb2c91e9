"""Sparse linear solvers for the Newton iterations, with symbolic-analysis reuse.

``method``:

* ``"auto"`` — PARDISO through pypardiso when it imports and solves a tiny system, else
  SciPy's SuperLU (the pure-SciPy fallback).
* ``"pardiso"`` — MKL PARDISO (pypardiso). Symmetric tangents use the symmetric indefinite
  mode on the upper triangle; the symbolic analysis (ordering) is done once per sparsity
  pattern and reused: later factorisations run PARDISO phase 23 only. With ``reuse`` a
  matrix on the pattern of the last factorised one is first solved by a bounded Krylov loop
  in Python (conjugate gradients for symmetric matrices, BiCGSTAB otherwise, at most
  ``reuse_iterations`` iterations, given up early when its residual falls too slowly),
  preconditioned by PARDISO's solve phase (33) with the held factors of that earlier
  matrix; a sequence of nearby matrices (Newton or Gauss–Newton tangents) converges in a few
  iterations. The matrix is factorised afresh when the loop does not reach the relative
  residual ``reuse``, returns non-finite values, or the pattern changed, so a singular
  matrix meets the same factorisation (and the same errors) as without ``reuse``, after at
  most :attr:`LinearSolver.iteration_budget` iterations. That budget is
  ``reuse_iterations``, raised for a matrix whose factorisation costs many loop iterations
  (PARDISO's own operation counts of its analysis; e.g. quadratic elements, whose factors
  fill in far more than their iterations cost).
  With ``factors="single"`` the factorisations are in single precision (half the bytes
  for every solve phase) and a fresh factorisation's solution is refined in double
  precision to ``reuse``.
* ``"superlu"`` — SuperLU with ``MMD_AT_PLUS_A`` ordering and symmetric mode for symmetric
  tangents (COLAMD for non-symmetric ones).
* ``"superlu-colamd"`` — SuperLU with its default COLAMD ordering (reference).
* ``"umfpack"`` — UMFPACK via scikit-umfpack, if installed.
* ``"amg-cg"`` — pyamg smoothed aggregation with the six rigid-body modes as
  near-nullspace, as a preconditioner of CG (GMRES for non-symmetric tangents).
"""

from __future__ import annotations

import contextlib
import copy
import ctypes
import functools
import os
from collections.abc import Iterator
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse import linalg as spla

from harpx._typing import FloatArray
from harpx.errors import ConvergenceError
from harpx.mechanics.krylov import Measure, Stop, bicgstab, cg, refine, vector_norm

__all__ = ["LinearSolver", "METHODS", "available_methods", "rigid_body_modes"]

METHODS = ("auto", "pardiso", "superlu", "superlu-colamd", "umfpack", "amg-cg")
Method = Literal["auto", "pardiso", "superlu", "superlu-colamd", "umfpack", "amg-cg"]


#: Floating-point operations of a factorisation run this many times as fast, per operation,
#: as those of a Krylov iteration (dense supernodal kernels against memory-bound
#: substitutions and products): the ratio of the two times over the ratio of PARDISO's
#: operation counts, on the tracking benchmarks' tangents (benchmarks/results/tracking_speed.md).
_FACTOR_SPEEDUP = 6.0
#: The Krylov loop of ``reuse`` may run up to this share of a factorisation's cost (in
#: iterations, :attr:`LinearSolver.iteration_budget`), if that is more than
#: ``reuse_iterations``: a failed loop then costs at most this share on top of the
#: factorisation that follows it.
_BUDGET_SHARE = 0.5

#: Steps of iterative refinement a single-precision factorisation may take to solve the
#: matrix it factorised (``factors="single"``) before the solver goes over to double
#: precision: with a condition number below ~10⁶ one or two steps reach ``reuse``.
_REFINE_STEPS = 4

Precision = Literal["double", "single"]


def _new_pardiso(mtype: int) -> Any:
    """A new PyPardisoSolver, as its constructor makes it, without finding MKL again.

    The constructor searches the environment's library folders for MKL, slowly; the
    one pypardiso made at import (``pypardiso.ps``) has found it, so a copy of it shares the
    loaded library, and everything a solver owns is reset to the constructor's values.
    """
    import pypardiso

    solver = copy.copy(pypardiso.ps)
    solver.pt = np.zeros(64, dtype=solver._pt_type[1])
    solver.iparm = np.zeros(64, dtype=np.int32)
    solver.perm = np.zeros(0, dtype=np.int32)
    solver.factorized_A = sparse.csr_matrix((0, 0))
    solver.mtype, solver.phase, solver.msglvl = mtype, 13, False
    solver.size_limit_storage, solver._solve_transposed = 5e7, False
    return solver


@functools.cache
def _openmp_wait() -> tuple[Any, Any] | None:
    """``(kmp_get_blocktime, kmp_set_blocktime)`` of the Intel OpenMP runtime MKL already
    loaded, or None (another threading layer, or not loaded: nothing to release)."""
    names = ("libiomp5.so", "libiomp5.dylib", "libiomp5md.dll")
    mode = getattr(os, "RTLD_NOLOAD", 0) | ctypes.DEFAULT_MODE  # only if already loaded
    for name in names:
        try:
            runtime = ctypes.CDLL(name, mode=mode)
            get, set_ = runtime.kmp_get_blocktime, runtime.kmp_set_blocktime
        except (OSError, AttributeError):
            continue
        get.restype, get.argtypes = ctypes.c_int, []
        set_.restype, set_.argtypes = None, [ctypes.c_int]
        return get, set_
    return None


@functools.cache
def _pardiso_works() -> bool:
    try:
        A = sparse.csr_matrix(np.array([[4.0, 1.0], [1.0, 3.0]]))
        solver = _new_pardiso(11)
        x = solver.solve(A, np.array([1.0, 2.0]))
        solver.free_memory(everything=True)
        return bool(np.allclose(A @ x, [1.0, 2.0]))
    except Exception:  # noqa: BLE001 - any failure means "not usable here"
        return False


@functools.cache
def _umfpack_works() -> bool:
    try:
        import scikits.umfpack  # noqa: F401
    except Exception:  # noqa: BLE001
        return False
    return True


def available_methods() -> list[str]:
    """Solver methods usable on this machine.

    Returns
    -------
    list of str
        The methods of ``METHODS`` other than ``"auto"`` that work here: ``"pardiso"``
        (first, if pypardiso imports and solves a tiny system), ``"superlu"``,
        ``"superlu-colamd"``, then ``"umfpack"`` and ``"amg-cg"`` if their packages import.
    """
    out = ["superlu", "superlu-colamd"]
    if _pardiso_works():
        out.insert(0, "pardiso")
    if _umfpack_works():
        out.append("umfpack")
    try:
        import pyamg  # noqa: F401

        out.append("amg-cg")
    except ImportError:  # pragma: no cover
        pass
    return out


def rigid_body_modes(points: FloatArray) -> FloatArray:
    """The six rigid-body modes at dof nodes (dof order 3 n + component).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Node positions, mm.

    Returns
    -------
    ndarray, shape (3 n, 6)
        Columns: unit translations along x, y and z (dimensionless), then infinitesimal
        rotations about z, x and y through the centroid of ``points`` (displacement per
        radian, mm); not normalised.
    """
    n = len(points)
    x = points - points.mean(axis=0)
    B = np.zeros((n, 3, 6))
    B[:, 0, 0] = B[:, 1, 1] = B[:, 2, 2] = 1.0
    B[:, 0, 3], B[:, 1, 3] = -x[:, 1], x[:, 0]  # about z
    B[:, 1, 4], B[:, 2, 4] = -x[:, 2], x[:, 1]  # about x
    B[:, 0, 5], B[:, 2, 5] = x[:, 2], -x[:, 0]  # about y
    return B.reshape(3 * n, 6)


class LinearSolver:
    """Solve ``K x = b`` repeatedly for matrices on a fixed sparsity pattern.

    Parameters
    ----------
    method : str, default "auto"
        One of ``METHODS`` (see the module docstring).
    rtol : float, default 1e-10
        Relative residual tolerance of the iterative method (``"amg-cg"``).
    maxiter : int, default 500
        Iteration limit of the iterative method.
    reuse : float, optional
        PARDISO only: relative residual ``|b - K x| / |b|`` to which a matrix on the pattern
        of the last factorised one may be solved iteratively, preconditioned with that
        factorisation (module notes), e.g. 1e-8. None (default): every matrix is factorised.
    reuse_iterations : int, default 15
        With ``reuse``: the iteration limit of the Krylov loop, or more where a
        factorisation costs more than twice as many iterations
        (:attr:`iteration_budget`); a matrix the loop does not solve within its limit is
        factorised afresh.
    reuse_measure : {"residual", "step"}, default "residual"
        What ``reuse`` bounds: the relative residual, or (``"step"``) the relative error of
        ``x`` as the held factorisation estimates it, ``|M⁻¹(b − K x)| / |x|`` -- what a
        Newton step needs (an inexact Newton method): a step accurate to 1 % moves the
        iterates as an exact one does, where a relative residual says little about the
        error along the matrix's soft directions.
    threads : int, optional
        PARDISO only: threads of each call (MKL's thread-local setting, restored after the
        call), e.g. 1 where another thread of the caller keeps the other cores busy, or
        on a machine shared with other jobs, where spinning OpenMP threads wait for cores.
        None (default): MKL's own setting.
    release_cores : bool, default False
        PARDISO only: let its threads sleep as soon as each call returns (the Intel OpenMP
        runtime's wait, ``kmp_set_blocktime(0)``, for the calling thread's team, restored
        after the call) instead of spinning for a next call, e.g. where the caller's own
        threads need those cores between solves. No effect under another threading layer.
    factors : {"double", "single"}, default "double"
        PARDISO with ``reuse`` only: precision of the factorisation (PARDISO's
        ``iparm[27]``). Single-precision factors take half the memory, and their solve
        phase, which every iteration of the ``reuse`` loop runs, reads half the bytes; the
        solution of a freshly factorised matrix is then refined in double precision to
        ``reuse`` (:func:`~harpx.mechanics.krylov.refine`), and where a matrix is too
        ill-conditioned for that (no convergence in ``_REFINE_STEPS`` steps) the solver
        goes over to double-precision factors for good (:attr:`factors` says which).
        Other methods ignore it.

    Attributes
    ----------
    method : str
        The resolved method (``"auto"`` replaced by the choice made).
    analyses : int
        Number of symbolic analyses (orderings) computed so far.
    factorizations : int
        Number of numerical factorisations computed so far.
    reused : int
        Number of solves done iteratively with an earlier factorisation (``reuse``).
    reuse_failures : int
        Number of Krylov loops (``reuse``) that did not reach the tolerance, so that the
        matrix was factorised afresh.
    last_iterations : int
        Iterations of the last solve's Krylov loop (``reuse`` or ``"amg-cg"``), or of the
        refinement of a fresh single-precision factorisation (``factors="single"``); 0 when
        it factorised in double precision without trying a loop.
    factors : str
        Precision of the factorisations from now on: ``"single"`` only while single-precision
        factors refine to ``reuse`` (see the parameter).
    iteration_budget : int
        With ``reuse``: the iteration limit of the Krylov loop on the current pattern, the
        larger of ``reuse_iterations`` and ``_BUDGET_SHARE`` times the iterations one
        factorisation costs, estimated from the floating-point operations PARDISO's analysis
        reports for the factorisation and its substitutions (a factorisation's operations
        taken as ``_FACTOR_SPEEDUP`` times as fast); ``reuse_iterations`` before the first
        analysis or where PARDISO reports no counts.

    Raises
    ------
    ValueError
        If ``method`` is unknown or not installed (the message says what to install), or
        ``reuse``, ``reuse_measure``, ``reuse_iterations``, ``threads`` or ``factors`` is
        out of range (``factors="single"`` also needs ``reuse``).
    """

    def __init__(
        self,
        method: str = "auto",
        *,
        rtol: float = 1e-10,
        maxiter: int = 500,
        reuse: float | None = None,
        reuse_iterations: int = 15,
        reuse_measure: Measure = "residual",
        threads: int | None = None,
        release_cores: bool = False,
        factors: Precision = "double",
    ) -> None:
        if method not in METHODS:
            raise ValueError(f"linear_solver={method!r} is not one of {METHODS!r}")
        if method == "auto":
            method = "pardiso" if _pardiso_works() else "superlu"
        elif method == "pardiso" and not _pardiso_works():
            raise ValueError(
                "linear_solver='pardiso' needs pypardiso with a working MKL; "
                "install it with `pip install pypardiso` or use 'superlu'"
            )
        elif method == "umfpack" and not _umfpack_works():
            raise ValueError(
                "linear_solver='umfpack' needs scikit-umfpack; install it with "
                "`pip install scikit-umfpack` or use 'superlu'"
            )
        self.method = method
        self.rtol = float(rtol)
        self.maxiter = int(maxiter)
        if reuse is not None and not (0.0 < reuse < 1.0):
            raise ValueError(f"reuse={reuse!r} must be a relative accuracy in (0, 1), or None")
        if reuse_measure not in ("residual", "step"):
            raise ValueError(f"reuse_measure={reuse_measure!r} is not 'residual' or 'step'")
        if reuse_iterations < 1:
            raise ValueError(f"reuse_iterations={reuse_iterations!r} must be at least 1")
        if threads is not None and threads < 1:
            raise ValueError(f"threads={threads!r} must be at least 1, or None")
        if factors not in ("double", "single"):
            raise ValueError(f"factors={factors!r} is not 'double' or 'single'")
        if factors == "single" and reuse is None:
            raise ValueError(
                "factors='single' needs reuse: the relative accuracy to which a "
                "single-precision factorisation's solutions are refined"
            )
        self.factors: Precision = factors if method == "pardiso" else "double"
        self.threads = threads
        self.release_cores = bool(release_cores)
        self.reuse = None if reuse is None else float(reuse)
        self.reuse_iterations = int(reuse_iterations)
        self.reuse_measure = reuse_measure
        self._fresh = True  # the next solve factorises (no reusable factorisation yet)
        # the data array of the factorised matrix, as PARDISO read it (phase 33 needs it)
        self._held: NDArray[np.floating] | None = None
        self.analyses = 0
        self.factorizations = 0
        self.reused = 0
        self.reuse_failures = 0
        self._pardiso: Any = None
        self._pattern_key: tuple[Any, ...] | None = None
        self._upper: NDArray[np.int64] | None = None
        self._upper_indptr: NDArray[np.int32] | None = None
        self._upper_indices: NDArray[np.int32] | None = None
        self._diagonal: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None
        self.last_iterations = 0
        self.iteration_budget = self.reuse_iterations

    # ------------------------------------------------------------------ pardiso
    def _same_pattern(self, K: sparse.csr_matrix, symmetric: bool) -> bool:
        if self._pattern_key is None:
            return False
        indptr, indices, sym = self._pattern_key
        if sym != symmetric or indptr.shape != K.indptr.shape or indices.shape != K.indices.shape:
            return False
        if indptr is K.indptr and indices is K.indices:
            return True
        return bool(np.array_equal(indptr, K.indptr) and np.array_equal(indices, K.indices))

    def close(self) -> None:
        """Release PARDISO's internal memory (also done on garbage collection)."""
        if getattr(self, "_pardiso", None) is not None:
            try:
                self._pardiso.free_memory(everything=True)
            except Exception:  # noqa: BLE001 - best effort at shutdown
                pass
            self._pardiso = None
            self._pattern_key = None
            self._held = None

    def __del__(self) -> None:
        self.close()

    def _pardiso_solve(self, K: sparse.csr_matrix, b: FloatArray, symmetric: bool) -> FloatArray:
        mtype = -2 if symmetric else 11
        new_pattern = not self._same_pattern(K, symmetric)
        if new_pattern:
            self.close()
            self._pardiso = _new_pardiso(mtype)
            self._pardiso.set_iparm(1, 1)  # supply iparm
            self._pardiso.set_iparm(2, 2)  # nested-dissection ordering (METIS)
            # no forced iterative refinement: PARDISO still refines (two steps) whenever it
            # perturbed a pivot; forcing two steps on every solve cost time and gained no
            # accuracy (the residuals were equal)
            self._pardiso.set_iparm(8, 0)
            self._pardiso.set_iparm(10, 8 if symmetric else 13)  # pivot perturbation 1e-8 / 1e-13
            self._pardiso.set_iparm(11, 0 if symmetric else 1)  # scaling (non-symmetric)
            self._pardiso.set_iparm(13, 0 if symmetric else 1)  # weighted matching
            self._pardiso.set_iparm(18, -1)  # report the factors' entries (analysis)
            self._pardiso.set_iparm(19, -1)  # report the factorisation's Mflop (analysis)
            self._pardiso.set_iparm(28, 1 if self.factors == "single" else 0)
            self._pardiso.set_iparm(35, 1)  # zero-based indexing
            if symmetric:
                rows = np.repeat(np.arange(K.shape[0]), np.diff(K.indptr))
                upper = np.nonzero(K.indices >= rows)[0]
                self._upper = upper
                self._upper_indices = K.indices[upper].astype(np.int32)
                counts = np.bincount(rows[upper], minlength=K.shape[0])
                ip = np.zeros(K.shape[0] + 1, dtype=np.int32)
                np.cumsum(counts, out=ip[1:])
                self._upper_indptr = ip
                on = np.nonzero(self._upper_indices == rows[upper])[0]
                self._diagonal = (rows[upper][on], on)
            self._pattern_key = (K.indptr, K.indices, symmetric)
        if symmetric:
            assert self._upper is not None
            data = np.ascontiguousarray(K.data[self._upper])
            indptr, indices = self._upper_indptr, self._upper_indices
        else:
            # a copy: the caller may change K.data in place while the factors are held
            data = np.array(K.data, dtype=np.float64)
            indptr, indices = K.indptr.astype(np.int32), K.indices.astype(np.int32)
        rhs = np.ascontiguousarray(b, dtype=np.float64)
        self.last_iterations = 0
        with self._mkl_threads():
            if self.reuse is not None and not (new_pattern or self._fresh):
                x = self._krylov(data, indptr, indices, rhs, symmetric)
                if x is not None:
                    self.reused += 1
                    return x
                self.reuse_failures += 1
            if self.factors == "single":
                self._factorise(data.astype(np.float32), indptr, indices, None, new_pattern)
                x = self._refined(data, indptr, indices, rhs, symmetric)
            else:
                x = self._factorise(data, indptr, indices, rhs, new_pattern)
            if new_pattern:
                self.iteration_budget = self._budget(len(data))
        if x is None:  # too ill-conditioned for single precision: double from now on
            self.factors = "double"
            self.close()
            return self._pardiso_solve(K, b, symmetric)
        return x

    def _refined(
        self, data: FloatArray, indptr: Any, indices: Any, b: FloatArray, symmetric: bool
    ) -> FloatArray | None:
        """The solution of the matrix just factorised in single precision, refined in double
        to ``reuse`` (:func:`~harpx.mechanics.krylov.refine`); None if it does not get there,
        and then no factors are held."""
        assert self.reuse is not None
        apply, precondition = self._operators(data, indptr, indices, symmetric)
        stop = Stop(b, self.reuse, _REFINE_STEPS, self.reuse_measure)
        if stop.target == 0.0:
            return np.zeros_like(b)
        with np.errstate(all="ignore"):
            x = refine(apply, precondition, b, stop)
        self.last_iterations = stop.iterations
        if x is None or not np.all(np.isfinite(x)):
            self._held, self._fresh = None, True
            return None
        return x

    def _budget(self, stored: int) -> int:
        """The Krylov loop's iteration limit for the pattern just analysed (``stored``
        entries handed to PARDISO): :attr:`iteration_budget`."""
        iparm = self._pardiso.iparm
        factor_entries, mflop = int(iparm[17]), int(iparm[18])
        if factor_entries <= 0 or mflop <= 0:  # not reported
            return self.reuse_iterations
        # two flops per entry: CG substitutes forward and backward through L (LDLᵀ) and
        # multiplies by the stored upper triangle and its transpose; BiCGSTAB through L and U
        # (``factor_entries`` counts both) and by the matrix, twice each
        per_iteration = 4.0 * (factor_entries + stored)
        iterations = mflop * 1e6 / (_FACTOR_SPEEDUP * per_iteration)
        return max(self.reuse_iterations, int(_BUDGET_SHARE * iterations))

    def _factorise(
        self,
        data: NDArray[np.floating],
        indptr: Any,
        indices: Any,
        b: FloatArray | None,
        new_pattern: bool,
    ) -> FloatArray | None:
        """PARDISO phase 13 (new pattern) or 23: factorise ``data`` and solve ``b``; hold the
        factors. Without ``b``: phases 12 or 22, factorise only, and return None."""
        solver = self._pardiso
        solver.set_phase((13 if new_pattern else 23) - (b is None))
        solver.iparm[3] = 0  # no PARDISO-internal iterative solve: it may not return
        if new_pattern:
            self.analyses += 1
        self._held, self._fresh = None, True  # until this factorisation has succeeded
        rhs = np.zeros(len(indptr) - 1) if b is None else b
        x = self._call(solver, data, indptr, indices, rhs)
        self.factorizations += 1
        if np.all(np.isfinite(x)):  # factors worth preconditioning with
            self._held, self._fresh = data, False
        return None if b is None else x

    def _krylov(
        self, data: FloatArray, indptr: Any, indices: Any, b: FloatArray, symmetric: bool
    ) -> FloatArray | None:
        """Solve by CG (symmetric) or BiCGSTAB, preconditioned with the held factors.

        Returns None when the loop does not reach ``reuse`` in ``reuse_iterations``
        iterations, or its result or the preconditioner is not finite.
        """
        assert self.reuse is not None
        apply, precondition = self._operators(data, indptr, indices, symmetric)
        # a breakdown (a singular or indefinite matrix) divides by zero: non-finite values,
        # caught below, not warnings
        stop = Stop(b, self.reuse, self.iteration_budget, self.reuse_measure)
        if stop.target == 0.0:
            return np.zeros_like(b)
        with np.errstate(all="ignore"):
            try:
                x = (cg if symmetric else bicgstab)(apply, precondition, b, stop)
            except (ConvergenceError, ArithmeticError):  # refused or overflowed: factorise
                return None
            finally:
                self.last_iterations = stop.iterations
            if x is None or not np.all(np.isfinite(x)):
                return None
            # the true residual, not the loop's recurrence
            if not vector_norm(b - apply(x)) <= stop.accepted_residual():
                return None
        return x

    def _operators(
        self, data: FloatArray, indptr: Any, indices: Any, symmetric: bool
    ) -> tuple[Any, Any]:
        """``(apply, precondition)``: the product with the matrix ``data`` on the pattern
        (the upper triangle mirrored where ``symmetric``, as PARDISO reads it), in double
        precision, and PARDISO's solve phase (33) with the held factors."""
        assert self._held is not None
        n = len(indptr) - 1
        A = sparse.csr_matrix((data, indices, indptr), shape=(n, n))
        if symmetric:
            assert self._diagonal is not None
            rows, positions = self._diagonal
            diagonal = np.zeros(n)
            diagonal[rows] = data[positions]
            At = A.T

            def apply(v: FloatArray) -> FloatArray:
                return np.asarray(A @ v + At @ v - diagonal * v)
        else:

            def apply(v: FloatArray) -> FloatArray:
                return np.asarray(A @ v)

        solver, held = self._pardiso, self._held

        def precondition(r: FloatArray) -> FloatArray:
            solver.set_phase(33)  # solve only, with the factors of ``held``
            return self._call(solver, held, indptr, indices, r)

        return apply, precondition

    @contextlib.contextmanager
    def _mkl_threads(self) -> Iterator[None]:
        """MKL's thread-local thread count set to ``threads``, and with ``release_cores``
        the OpenMP wait set to 0, inside; both restored after."""
        with contextlib.ExitStack() as restore:
            if self.threads is not None and self._pardiso is not None:
                local = self._pardiso.libmkl.MKL_Set_Num_Threads_Local
                local.restype, local.argtypes = ctypes.c_int, [ctypes.c_int]
                previous = local(self.threads)
                restore.callback(local, previous)  # 0: back to MKL's global setting
            wait = _openmp_wait() if self.release_cores else None
            if wait is not None:
                get, set_ = wait
                restore.callback(set_, get())
                set_(0)
            yield

    @staticmethod
    def _call(
        solver: Any, data: NDArray[np.floating], indptr: Any, indices: Any, b: FloatArray
    ) -> FloatArray:
        """One PARDISO call at ``solver.phase`` in the precision of ``data`` (float64, or
        float32 for single-precision factors); the solution is returned in float64."""
        b = np.ascontiguousarray(b, dtype=data.dtype)
        x = np.zeros_like(b)
        err = ctypes.c_int32(0)
        i32 = ctypes.POINTER(ctypes.c_int32)
        real = ctypes.POINTER(ctypes.c_float if data.dtype == np.float32 else ctypes.c_double)
        n = len(indptr) - 1
        solver._mkl_pardiso(
            solver.pt.ctypes.data_as(ctypes.POINTER(solver._pt_type[0])),
            ctypes.byref(ctypes.c_int32(1)),
            ctypes.byref(ctypes.c_int32(1)),
            ctypes.byref(ctypes.c_int32(solver.mtype)),
            ctypes.byref(ctypes.c_int32(solver.phase)),
            ctypes.byref(ctypes.c_int32(n)),
            data.ctypes.data_as(real),
            indptr.ctypes.data_as(i32),
            indices.ctypes.data_as(i32),
            solver.perm.ctypes.data_as(i32),
            ctypes.byref(ctypes.c_int32(1)),
            solver.iparm.ctypes.data_as(i32),
            ctypes.byref(ctypes.c_int32(0)),
            b.ctypes.data_as(real),
            x.ctypes.data_as(real),
            ctypes.byref(err),
        )
        if err.value != 0:
            raise ConvergenceError(
                f"PARDISO failed with error {err.value} (e.g. -4: zero pivot, the tangent is "
                "singular); check the Dirichlet conditions remove all rigid-body modes"
            )
        return np.asarray(x, dtype=np.float64)

    # ------------------------------------------------------------------ public
    def refresh(self) -> None:
        """Factorise the next matrix afresh (with ``reuse``: e.g. after a large change)."""
        self._fresh = True

    def solve(
        self,
        K: sparse.csr_matrix,
        b: FloatArray,
        *,
        symmetric: bool = True,
        near_nullspace: FloatArray | None = None,
    ) -> FloatArray:
        """Solve ``K x = b``.

        Parameters
        ----------
        K : scipy.sparse.csr_matrix, shape (n, n)
            Sorted CSR matrix; for ``symmetric=True`` only its upper triangle is read by
            PARDISO.
        b : ndarray, shape (n,)
            Right-hand side.
        symmetric : bool, default True
            Whether ``K`` is symmetric.
        near_nullspace : ndarray, shape (n, m), optional
            Near-nullspace vectors for AMG (the rigid-body modes).

        Returns
        -------
        ndarray, shape (n,)
            The solution ``x`` (float64): from a factorisation, or with ``reuse`` (PARDISO)
            from the Krylov loop or the refinement to the relative accuracy ``reuse``, or
            for ``"amg-cg"`` to the relative residual ``rtol``.

        Raises
        ------
        ConvergenceError
            If the factorisation fails (a PARDISO error, or a zero pivot of SuperLU: the
            matrix is singular) or the iterative method does not converge. A direct solve of
            a nearly singular matrix can still return NaN or inf values; the caller checks
            (:func:`~harpx.mechanics.newton.solve` cuts the load step back).
        """
        if self.method == "pardiso":
            return self._pardiso_solve(K, b, symmetric)
        self.factorizations += 1
        if self.method in ("superlu", "superlu-colamd"):
            options: dict[str, Any] = {}
            if self.method == "superlu" and symmetric:
                options = {"permc_spec": "MMD_AT_PLUS_A", "diag_pivot_thresh": 0.0}
                options["options"] = {"SymmetricMode": True}
            try:
                lu = spla.splu(K.tocsc(), **options)
            except RuntimeError as exc:  # SuperLU: "Factor is exactly singular"
                raise ConvergenceError(
                    f"SuperLU could not factorise the {K.shape[0]}-dof matrix ({exc}); check "
                    "the Dirichlet conditions remove all rigid-body modes"
                ) from exc
            self.analyses += 1
            return lu.solve(b)
        if self.method == "umfpack":
            return spla.spsolve(K.tocsc(), b, use_umfpack=True)
        # amg-cg
        import pyamg

        ml = pyamg.smoothed_aggregation_solver(
            K,
            B=near_nullspace,
            symmetry="symmetric" if symmetric else "nonsymmetric",
            strength=("symmetric", {"theta": 0.0}),
            smooth="jacobi",
            max_coarse=500,
        )
        self.analyses += 1
        residuals: list[float] = []
        accel = "cg" if symmetric else "gmres"
        x = ml.solve(b, tol=self.rtol, accel=accel, maxiter=self.maxiter, residuals=residuals)
        self.last_iterations = len(residuals) - 1
        bn = float(np.linalg.norm(b))
        rn = float(np.linalg.norm(b - K @ x))
        if not np.isfinite(rn) or rn > 1e3 * self.rtol * max(bn, 1e-300):
            raise ConvergenceError(
                f"AMG-{accel.upper()} did not converge in {self.maxiter} iterations "
                f"(relative residual {rn / max(bn, 1e-300):.2e}); use linear_solver='pardiso' "
                "or 'superlu'",
                residuals,
            )
        return x
