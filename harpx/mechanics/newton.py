r"""Total-Lagrangian Newton--Raphson with line search and automatic step cut-back.

:func:`solve` ramps the loads with a load factor :math:`s = 1/n, 2/n, \dots, 1` and calls
:func:`equilibrate` at each factor; :func:`equilibrate` runs Newton at one fixed factor
from a given displacement (the tracking loop calls it repeatedly with changing constraint
penalties).

At each iterate :math:`u_k` the residual :math:`R = f_{int} - f_{ext}` and the tangent
:math:`K` are assembled (``assembly.internal_forces`` plus every load term's
``residual_tangent``). Dirichlet dofs :math:`D` are eliminated on the fixed
sparsity pattern (rows and columns zeroed, a diagonal of typical size): with the remaining
prescribed increment :math:`\Delta g = g(s) - u_D`,

.. math::

    K_{FF}\, x_F = -R_F - K_{FD}\, \Delta g, \qquad \delta u = x + \Delta g ,

so the first iteration of a step is the consistent linearised predictor and the boundary
moves with it. Steps are full Newton steps (keeping quadratic convergence, which energy or
``‖R‖`` line searches destroy for nearly incompressible solids, where a full step overshoots
the volumetric energy yet lands in the basin of convergence; ``benchmarks/results/newton.md``).
The line search is a safeguard: a trial with an inverted
element or NaN is halved (:math:`\alpha = 1, 1/2, \dots`; if the trial still moves the
prescribed boundary the step fails at once, so that the load increment is halved), and
once :math:`\|R_F\|` has grown in two consecutive iterations the energy-slope line search
takes over, accepting :math:`\alpha` when :math:`|\delta u \cdot R_F(u + \alpha\delta u)| \le 0.9\,
|\delta u \cdot R_F(u)|` and otherwise moving to the secant zero of that slope (it needs
only residuals, so it serves non-conservative terms too). Convergence: the boundary values
are reached and :math:`\|R_F\| \le \max(\mathrm{tol}\cdot\rho, \mathrm{atol})`, with the
force scale :math:`\rho` = the larger of the free residual at the start and the reaction
norm :math:`\|R_D\|`. A step that diverges (``‖R_F‖`` grows four times in a row, or
exceeds :math:`10^8\rho`), stalls (the smallest ``‖R_F‖`` of the last six iterates is no
smaller than the smallest of the six before them: a residual that still decreases, however
far it first rose above the starting value, is never abandoned), runs out of
``max_iterations``, produces a non-finite state or inverts an element is retried with half
the load increment, at most ``max_cutbacks`` times in a row
and never below ``1/(steps · 2**max_cutbacks)`` (otherwise, near a limit point, a converged
tiny step between failures would reset the count and the load factor would creep towards it
forever); after a converged step the increment doubles again up to ``1/steps``.

Volumetric tangent
------------------
The residual is always that of the body's displacement formulation, with the pressure
:math:`p = U'(\theta)` of the dilatation :math:`\theta = \Pi J(u)` (projected,
vertex-averaged or pointwise, ``harpx.mechanics.assembly``). The tangent at the first iterate
of a step is the consistent one; at a later iterate :math:`u_{k+1} = u_k + \alpha\,\delta
u_k` its volumetric part (the pressure's geometric stiffness and the :math:`U''` block) is
formed at the dilatation the linearisation carries,
:math:`\theta_{k+1} = \Pi[J(u_k) + \alpha \operatorname{cof}F(u_k) : \operatorname{Grad}
\delta u_k]`, instead of at :math:`\Pi J(u_{k+1})` (``internal_forces``'
``tangent_jacobian``; where that is not a positive volume ratio, at the iterate's own). This
is how the dilatation is updated in Newton's iteration of the three-field
:math:`u`--:math:`p`--:math:`\theta` formulation (Simo, Taylor & Pister 1985). With the
residual unchanged the solutions are the same; the tangent differs from the consistent one
by :math:`O(\kappa\,|\operatorname{Grad}\delta u_k|^2)`, which vanishes quadratically as
the iterates converge, so the convergence stays quadratic. What it leaves out is the
pressure :math:`\kappa\, O(|\operatorname{Grad}\delta u_k|^2)` that the second-order
volume error of a full step puts into a nearly incompressible body (:math:`\kappa \gg
\mu`): in the consistent tangent its geometric stiffness outweighs the isochoric stiffness
and turns the next step away from the solution, so that the displacement-only Newton
converges only from within a distance that shrinks like :math:`\mu/\kappa` (load
increments cut back over and over, or a manual ramp of :math:`\kappa`).

References: Simo JC, Taylor RL, Pister KS. Variational and projection methods for the volume
constraint in finite deformation elasto-plasticity. Comput Methods Appl Mech Eng
51:177--208, 1985.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse

from harpx._blas import dot_one_thread, norm_one_thread
from harpx._progress import progress_bar
from harpx._typing import FloatArray, IntArray
from harpx.errors import ConvergenceError, ElementInversionError
from harpx.mechanics.assembly import Pattern, internal_forces, linearised_jacobian, sparsity
from harpx.mechanics.linsolve import LinearSolver, rigid_body_modes
from harpx.mechanics.loads import BodyForce, Pressure, dirichlet_values, split_loads, unheld_note

if TYPE_CHECKING:
    from harpx.mechanics.body import Body

__all__ = ["SolveResult", "equilibrate", "solve", "split_loads"]


@dataclass
class SolveResult:
    """Outcome of :func:`solve` or :func:`equilibrate`.

    Attributes
    ----------
    u : ndarray, shape (ndof,)
        Displacement (mm) of the last converged state.
    converged : bool
        Whether the full load (factor 1, or the requested factor) was reached.
    iterations : int
        Newton iterations (linear solves) over all attempts, including failed ones.
    step_iterations : list of int
        Newton iterations of each accepted load step.
    residual_history : list of list of float
        ``‖R_F‖`` (mN) at every iterate of each accepted load step.
    cutbacks : int
        Number of halved load increments.
    cutback_reasons : list of str
        Why each failed attempt was cut back: ``"inverted"``, ``"diverged"``, ``"nan"``
        (a non-finite state), ``"stalled"`` or ``"max_iterations"``.
    min_jacobian : float
        Smallest ``det F`` at the Gauss points of ``u``.
    time_assembly, time_solve : float
        Wall time (s) spent assembling and in linear solves.
    load_factors : list of float
        Load factor of each accepted step.
    line_search_steps : int
        Backtracking reductions over all iterations.
    message : str
        Why it stopped, when it did not converge.
    """

    u: FloatArray
    converged: bool
    iterations: int = 0
    step_iterations: list[int] = field(default_factory=list)
    residual_history: list[list[float]] = field(default_factory=list)
    cutbacks: int = 0
    cutback_reasons: list[str] = field(default_factory=list)
    min_jacobian: float = float("nan")
    time_assembly: float = 0.0
    time_solve: float = 0.0
    load_factors: list[float] = field(default_factory=list)
    line_search_steps: int = 0
    message: str = ""


@dataclass
class _Assembled:
    R: FloatArray | None
    data: FloatArray | None
    symmetric: bool
    min_jacobian: float
    inverted: IntArray


@dataclass
class _Outcome:
    ok: bool
    u: FloatArray
    history: list[float]
    iterations: int
    reason: str = ""
    cells: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    min_jacobian: float = float("nan")


class _Newton:
    """Newton iterations for one body and load set (caches Dirichlet data and solver)."""

    #: form the volumetric tangent at the dilatation carried by the linearisation (the
    #: three-field iteration of the module notes); False: at the iterate's own dilatation
    #: (the displacement-only Newton, kept for benchmarks/bench_newton.py)
    carry_dilatation: bool = True

    def __init__(
        self,
        body: Body,
        loads: Iterable[Any],
        *,
        tol: float,
        atol: float | None,
        max_iterations: int,
        line_search: bool,
        linear_solver: str | LinearSolver,
        max_backtracks: int = 5,
        t_max: Any = None,
    ) -> None:
        self.body = body
        self.t_max = _activation_target(body, t_max)
        self.dirichlet, self.terms = split_loads(loads)
        self.tol = float(tol)
        if atol is None:
            # force of a 1e-12 volumetric strain on the body's cross-section (mN)
            atol = 1e-12 * float(body.material.kappa) * float(body.cell_volume.sum()) ** (2 / 3)
        self.atol = float(atol)
        self.max_iterations = int(max_iterations)
        self.line_search = bool(line_search)
        self.max_backtracks = int(max_backtracks)
        self.ls_ratio = 0.9
        self.stall_iterations = 6
        self.solver = (
            linear_solver
            if isinstance(linear_solver, LinearSolver)
            else LinearSolver(linear_solver)
        )
        self.pattern: Pattern = sparsity(body)
        self.time_assembly = 0.0
        self.time_solve = 0.0
        self.line_search_steps = 0
        self.iterations = 0
        dofs = [np.asarray(d.dofs(body), dtype=np.int64) for d in self.dirichlet]
        alld = np.concatenate(dofs) if dofs else np.zeros(0, dtype=np.int64)
        self.D = np.unique(alld)
        is_d = np.zeros(body.ndof, dtype=bool)
        is_d[self.D] = True
        self.is_d = is_d
        pat = self.pattern
        self.zero_mask = np.nonzero(is_d[pat.row_of_entry] | is_d[pat.indices])[0]
        self.diag_D = pat.diagonal[self.D]
        self._sym_cache: dict[int, bool] = {}

    def unheld_note(self) -> str:
        """For a failure message: the rigid-body motions nothing holds, when no term can."""
        if any(not isinstance(term, (BodyForce, Pressure)) for term in self.terms):
            return ""  # another term (e.g. the phase constraint) may hold the body
        return unheld_note(self.body, self.D)

    def boundary_values(self, s: float) -> FloatArray:
        """Prescribed values on ``self.D`` at load factor ``s`` (conditions must agree)."""
        return dirichlet_values(self.body, self.dirichlet, s)[self.D]

    def count_into(self, res: SolveResult) -> None:
        """Copy the counters over all attempts so far (iterations, timings, line-search
        reductions) into ``res``."""
        res.iterations = self.iterations
        res.time_assembly = self.time_assembly
        res.time_solve = self.time_solve
        res.line_search_steps = self.line_search_steps

    def _term_symmetric(self, term: Any, K: sparse.spmatrix) -> bool:
        flag = getattr(term, "symmetric_tangent", None)
        if flag is not None:
            return bool(flag)
        key = id(term)
        if key not in self._sym_cache:
            diff = abs(K - K.T).max() if K.nnz else 0.0
            self._sym_cache[key] = bool(diff <= 1e-12 * max(abs(K).max(), 1e-300))
        return self._sym_cache[key]

    def assemble(self, u: FloatArray, s: float, jacobian: FloatArray | None = None) -> _Assembled:
        """Residual and tangent at ``u``; ``jacobian``: the stand-in ``det F`` of the
        volumetric tangent (``assembly.internal_forces``' ``tangent_jacobian``)."""
        t0 = time.perf_counter()
        if self.t_max is not None:  # activation ramped with the loads: t_max(s) = s t_max
            self.body.t_max = s * self.t_max
        internal = internal_forces(self.body, u, tangent=True, tangent_jacobian=jacobian)
        if internal.r is None or internal.K is None:
            self.time_assembly += time.perf_counter() - t0
            return _Assembled(None, None, True, internal.min_jacobian, internal.inverted_cells)
        R = internal.r
        data = internal.K.data
        symmetric = True
        pat = self.pattern
        for term in self.terms:
            r_t, K_t = term.residual_tangent(self.body, u, s)
            R = R + np.asarray(r_t, dtype=np.float64)
            if K_t is None:
                continue
            K_t = K_t.tocsr() if not sparse.isspmatrix_csr(K_t) else K_t
            symmetric &= self._term_symmetric(term, K_t)
            if K_t.indptr is pat.indptr and K_t.indices is pat.indices:
                data += K_t.data
            else:
                coo = K_t.tocoo()
                try:
                    pos = pat.positions(coo.row, coo.col)
                except ValueError:
                    raise ValueError(
                        f"the tangent of {type(term).__name__} couples dofs outside the body's "
                        "stiffness pattern (dofs of one cell); build it on "
                        "harpx.mechanics.assembly.sparsity(body)"
                    ) from None
                data += np.bincount(pos, weights=coo.data, minlength=pat.nnz)
        self.time_assembly += time.perf_counter() - t0
        return _Assembled(R, data, symmetric, internal.min_jacobian, internal.inverted_cells)

    def _stalled(self, history: list[float]) -> bool:
        """No progress: the last ``k`` residuals never undercut the ``k`` before them."""
        k = self.stall_iterations
        if len(history) < 2 * k:
            return False
        return min(history[-k:]) >= min(history[-2 * k : -k])

    def run(self, u0: FloatArray, s: float) -> _Outcome:
        # trial states far from equilibrium may overflow or turn NaN (an inverted or
        # exploded element): that is detected and answered by a cut-back, so numpy's
        # RuntimeWarnings would only alarm the user
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            return self._run(u0, s)

    def _run(self, u0: FloatArray, s: float) -> _Outcome:
        body = self.body
        u = np.array(u0, dtype=np.float64, copy=True)
        g = self.boundary_values(s)
        history: list[float] = []
        scale = 0.0
        growth = 0
        asm = self.assemble(u, s)
        for it in range(self.max_iterations + 1):
            if asm.R is None or asm.data is None:
                return _Outcome(False, u, history, it, "inverted", asm.inverted, asm.min_jacobian)
            dg = np.zeros(body.ndof)
            dg[self.D] = g - u[self.D]
            pending = bool(np.any(dg[self.D] != 0.0))
            R = asm.R
            RF = R.copy()
            RF[self.D] = 0.0
            rn = norm_one_thread(RF)
            history.append(rn)
            if not np.isfinite(rn):
                return _Outcome(False, u, history, it, "nan", min_jacobian=asm.min_jacobian)
            if it == 0:
                scale = rn
            scale = max(scale, norm_one_thread(R[self.D]))
            if not pending and (rn <= self.tol * scale or rn <= self.atol):
                return _Outcome(True, u, history, it, min_jacobian=asm.min_jacobian)
            if it == self.max_iterations:
                return _Outcome(
                    False, u, history, it, "max_iterations", min_jacobian=asm.min_jacobian
                )
            if it > 2 and rn > 1e8 * max(scale, self.atol):
                return _Outcome(False, u, history, it, "diverged", min_jacobian=asm.min_jacobian)
            step = self._step(asm, u, RF, dg, pending)
            if step is None:
                return _Outcome(False, u, history, it + 1, "nan", min_jacobian=asm.min_jacobian)
            # line search on the energy slope σ(α) = δu·R_F(u + α δu) (residual-only, so it
            # also serves non-conservative terms), switched on once ‖R_F‖ has grown twice in a
            # row; inverted or NaN trials always halve α
            if it > 0 and not pending and rn > history[-2]:
                growth += 1
            elif it > 0:
                growth = 0
            damping = self.line_search and growth >= 2
            if growth >= 4 or (not pending and self._stalled(history)):
                # diverging, or no progress: give up early, the caller halves the increment
                reason = "diverged" if growth >= 4 else "stalled"
                return _Outcome(False, u, history, it, reason, min_jacobian=asm.min_jacobian)
            accepted, last_bad = self._line_search(u, s, step, RF, asm, pending, damping)
            if accepted is None:
                return _Outcome(False, u, history, it + 1, "inverted", last_bad, asm.min_jacobian)
            u, asm = accepted
        raise AssertionError("unreachable")  # pragma: no cover

    def _step(
        self, asm: _Assembled, u: FloatArray, RF: FloatArray, dg: FloatArray, pending: bool
    ) -> FloatArray | None:
        """Newton step: Dirichlet elimination on the fixed pattern (module notes); None if NaN."""
        data = asm.data
        assert data is not None
        K = self.pattern.matrix(data)
        rhs = -RF
        if pending:
            rhs -= K @ dg
        rhs[self.D] = 0.0
        diag = np.abs(data[self.pattern.diagonal])
        dscale = float(diag[~self.is_d].mean()) if np.any(~self.is_d) else 1.0
        data[self.zero_mask] = 0.0
        data[self.diag_D] = dscale if dscale > 0 else 1.0
        t0 = time.perf_counter()
        nullspace = None
        if self.solver.method == "amg-cg":
            nullspace = rigid_body_modes(self.body.dof_points + u.reshape(-1, 3))
        x = self.solver.solve(K, rhs, symmetric=asm.symmetric, near_nullspace=nullspace)
        self.time_solve += time.perf_counter() - t0
        self.iterations += 1
        if not np.all(np.isfinite(x)):
            return None
        x[self.D] = dg[self.D]
        return x

    def _line_search(
        self,
        u: FloatArray,
        s: float,
        step: FloatArray,
        RF: FloatArray,
        asm: _Assembled,
        pending: bool,
        damping: bool,
    ) -> tuple[tuple[FloatArray, _Assembled] | None, IntArray]:
        """The accepted ``(u + α step, its assembly)`` (module notes) or None, and the cells
        of the last inverted trial."""
        alpha = 1.0
        slope0 = dot_one_thread(step, RF)
        # dilatation carried to u + α δu: J(u) + α cof F(u) : Grad δu at the Gauss points
        lin = linearised_jacobian(self.body, u, step) if self.carry_dilatation else None
        last_bad = asm.inverted
        fallback = None
        for _ in range(self.max_backtracks + 1):
            ut = u + alpha * step
            trial = self.assemble(ut, s, None if lin is None else lin[0] + alpha * lin[1])
            if trial.R is None or not np.all(np.isfinite(trial.R)):
                if trial.R is None:
                    last_bad = trial.inverted
                if pending:
                    # the prescribed increment cannot be applied in one linearised step:
                    # fail fast, the caller halves the load increment
                    break
                alpha *= 0.5
                self.line_search_steps += 1
                continue
            fallback = (ut, trial)
            if pending or not damping or slope0 >= 0.0:
                return fallback, last_bad
            tf = trial.R.copy()
            tf[self.D] = 0.0
            slope = dot_one_thread(step, tf)
            if slope <= 0.0 or abs(slope) <= self.ls_ratio * abs(slope0):
                return fallback, last_bad
            # overshoot (the energy rises again before α): secant zero of σ, safeguarded
            alpha *= float(np.clip(slope0 / (slope0 - slope), 0.1, 0.9))
            self.line_search_steps += 1
        return fallback, last_bad


def _activation_target(body: Body, t_max: Any) -> FloatArray | None:
    """Per-cell activation (kPa) that ``t_max`` names, or None (the body's level stays)."""
    if t_max is None:
        return None
    if getattr(body, "active", None) is None:
        raise ValueError(
            "t_max was given but the body has no active contraction law; build it with "
            "Body(..., active=ActiveContraction(...))"
        )
    body.set_t_max(t_max)
    return np.asarray(body.t_max, dtype=np.float64).copy()


def _check_u0(body: Body, u0: ArrayLike | None) -> FloatArray:
    if u0 is None:
        return np.zeros(body.ndof)
    u = np.asarray(u0, dtype=np.float64)
    if u.shape != (body.ndof,):
        raise ValueError(f"u0 has shape {u.shape!r}; expected ({body.ndof},) dofs")
    return u.copy()


def _failure(
    reason: str, cells: IntArray, s: float, history: list[float], tries: int, note: str
) -> Exception:
    if reason == "inverted":
        shown = ", ".join(str(c) for c in cells[:12]) + (" ..." if len(cells) > 12 else "")
        return ElementInversionError(
            f"cells [{shown}] ({len(cells)} in all) invert (det F <= 0) at load factor "
            f"s={s:.6g} after {tries} step cut-back(s); reduce the load, use more steps "
            f"or refine the mesh there{note}",
            cells,
            history,
        )
    return ConvergenceError(
        f"Newton failed ({reason}) at load factor s={s:.6g} after {tries} step cut-back(s); "
        f"residual history {[f'{h:.3e}' for h in history]}; use more steps, check the "
        f"loads and boundary conditions{note}",
        history,
    )


def equilibrate(
    body: Body,
    loads: Iterable[Any],
    u0: ArrayLike | None = None,
    s: float = 1.0,
    *,
    tol: float = 1e-8,
    atol: float | None = None,
    max_iterations: int = 25,
    line_search: bool = True,
    linear_solver: str | LinearSolver = "auto",
    raise_on_failure: bool = True,
) -> SolveResult:
    """Newton iterations at one fixed load factor, starting from ``u0``.

    Parameters
    ----------
    body : Body
        The model, as in :func:`solve`.
    loads : iterable
        Dirichlet conditions and residual terms, as in :func:`solve`.
    u0 : array_like, shape (ndof,), optional
        Starting displacement (mm); zeros by default. Its Dirichlet values need not match:
        the remaining increment is applied through the linearised predictor.
    s : float, default 1.0
        Load factor passed to every load.
    tol : float, default 1e-8
        Relative tolerance on the free residual norm, as in :func:`solve`.
    atol : float, optional
        Absolute tolerance in mN, as in :func:`solve`.
    max_iterations : int, default 25
        Newton iterations before giving up (no cut-back here).
    line_search : bool, default True
        Safeguarded line search, as in :func:`solve`.
    linear_solver : str or LinearSolver, default "auto"
        As in :func:`solve`. Pass a :class:`~harpx.mechanics.linsolve.LinearSolver`
        instance to reuse its symbolic analysis across calls.
    raise_on_failure : bool, default True
        Raise on failure; otherwise return ``u0`` with ``converged=False``.

    Returns
    -------
    SolveResult
        One load step; ``converged`` False (and ``u = u0``) on failure when
        ``raise_on_failure`` is False.

    Raises
    ------
    ElementInversionError
        If an element inverts and line search cannot avoid it.
    ConvergenceError
        If Newton diverges or stalls.
    ValueError
        If two Dirichlet conditions disagree on a dof they share (:func:`.dirichlet_values`).
    """
    u = _check_u0(body, u0)
    nt = _Newton(body, loads, tol=tol, atol=atol, max_iterations=max_iterations,
                 line_search=line_search, linear_solver=linear_solver)  # fmt: skip
    out = nt.run(u, float(s))
    res = SolveResult(
        u=out.u if out.ok else u,
        converged=out.ok,
        step_iterations=[out.iterations] if out.ok else [],
        residual_history=[out.history] if out.ok else [],
        min_jacobian=out.min_jacobian,
        load_factors=[float(s)] if out.ok else [],
    )
    nt.count_into(res)
    if not out.ok:
        err = _failure(out.reason, out.cells, float(s), out.history, 0, nt.unheld_note())
        if raise_on_failure:
            raise err
        res.message = str(err)
    return res


def solve(
    body: Body,
    loads: Iterable[Any],
    *,
    steps: int = 10,
    u0: ArrayLike | None = None,
    tol: float = 1e-8,
    atol: float | None = None,
    max_iterations: int = 25,
    line_search: bool = True,
    max_cutbacks: int = 6,
    linear_solver: str | LinearSolver = "auto",
    raise_on_failure: bool = True,
    t_max: Any = None,
    progress: bool | None = None,
) -> SolveResult:
    """Static equilibrium under loads ramped over load steps, with cut-back on failure.

    Parameters
    ----------
    body : Body
        The model; unchanged unless ``t_max`` is given (its activation level is then set).
    loads : iterable
        Dirichlet conditions (:class:`~harpx.mechanics.loads.Fixed`,
        :class:`~harpx.mechanics.loads.Prescribed`) and residual terms
        (:class:`~harpx.mechanics.loads.Pressure`, :class:`~harpx.mechanics.loads.BodyForce`,
        or any object with ``residual_tangent(body, u, s)``).
    steps : int, default 10
        Number of equal load increments; ``s = 1/steps, ..., 1``.
    u0 : array_like, shape (ndof,), optional
        Starting displacement (mm), zeros by default.
    tol : float, default 1e-8
        Relative tolerance on the free residual norm (relative to the larger of the
        step's initial free residual and the reaction norm).
    atol : float, optional
        Absolute tolerance in mN; default ``1e-12 κ V^(2/3)`` (the force of a 1e-12
        volumetric strain over the body's cross-section).
    max_iterations : int, default 25
        Newton iterations per load step before a cut-back.
    line_search : bool, default True
        Safeguarded line search (see the module docstring): halve steps that invert
        elements; energy-slope line search after two consecutive residual increases.
    max_cutbacks : int, default 6
        Consecutive halvings of a failing increment before giving up; the increment never
        falls below ``1/(steps · 2**max_cutbacks)`` either.
    linear_solver : str or LinearSolver, default "auto"
        See :mod:`harpx.mechanics.linsolve`.
    raise_on_failure : bool, default True
        Raise on failure; otherwise return the last converged state with
        ``converged=False``.
    t_max : float, dict of str to float or array_like of shape (ncell,), optional
        Target activation in kPa (as :meth:`Body.set_t_max`), ramped together with the
        loads: ``t_max(s) = s · t_max`` at load factor ``s`` (cut-backs included). The
        body keeps the full level afterwards. Needs a body with an active law; by
        default the body's current level is held fixed.
    progress : bool or None, default None
        A bar of the load factor reached (in %), with the Newton iterations and cut-backs
        so far; None: shown in a terminal or notebook once the solve has run two seconds.

    Returns
    -------
    SolveResult
        The displacement at load factor 1 (or, with ``raise_on_failure=False``, the last
        converged one), with the iteration, cut-back and timing record.

    Raises
    ------
    ElementInversionError
        If elements invert and ``max_cutbacks`` halvings cannot avoid it (names the cells
        and the load factor).
    ConvergenceError
        If Newton fails for another reason after ``max_cutbacks`` halvings.
    ValueError
        If an argument is out of range, or two Dirichlet conditions disagree on a dof they
        share (:func:`~harpx.mechanics.loads.dirichlet_values`).

    Examples
    --------
    >>> from harpx.mechanics import Body, NeoHookean, Fixed, Prescribed, box, solve
    >>> body = Body(box((1.0, 1.0, 1.0), (1, 1, 1)), NeoHookean(c1=1.0, kappa=120.0))
    >>> pull = Prescribed("right", lambda X, s: 0.1 * s * np.ones_like(X), components=(0,))
    >>> loads = [Fixed("left", (0,)), Fixed("front", (1,)), Fixed("bottom", (2,)), pull]
    >>> result = solve(body, loads, steps=2)
    >>> result.converged, round(float(result.u.reshape(-1, 3)[:, 0].max()), 6)
    (True, 0.1)
    """
    if int(steps) < 1:
        raise ValueError(f"steps={steps!r} must be >= 1")
    u = _check_u0(body, u0)
    nt = _Newton(body, loads, tol=tol, atol=atol, max_iterations=max_iterations,
                 line_search=line_search, linear_solver=linear_solver, t_max=t_max)  # fmt: skip
    nominal = 1.0 / int(steps)
    res = SolveResult(u=u, converged=False)
    with progress_bar(progress=progress, total=100, desc="load", unit="%") as bar:
        return _ramp(nt, u, res, bar, nominal=nominal, max_cutbacks=max_cutbacks,
                     raise_on_failure=raise_on_failure)  # fmt: skip


def _ramp(
    nt: _Newton,
    u: FloatArray,
    res: SolveResult,
    bar: Any,
    *,
    nominal: float,
    max_cutbacks: int,
    raise_on_failure: bool,
) -> SolveResult:
    """The load stepping of :func:`solve`: increments of ``nominal``, halved on failure."""
    ds = nominal
    s_done = 0.0
    consecutive = 0
    inverted: tuple[IntArray, float, list[float]] | None = None
    min_j = float("nan")
    while s_done < 1.0 - 1e-12:
        s = min(1.0, s_done + ds)
        if 1.0 - s < 1e-9:
            s = 1.0
        out = nt.run(u, s)
        bar.set_postfix(iterations=nt.iterations, cutbacks=res.cutbacks + (not out.ok))
        if out.ok:
            bar.update(round(100 * s) - bar.n)
            u = out.u
            s_done = s
            consecutive = 0
            inverted = None
            min_j = out.min_jacobian
            res.step_iterations.append(out.iterations)
            res.residual_history.append(out.history)
            res.load_factors.append(s)
            ds = min(2.0 * ds, nominal) if ds < nominal else ds
            continue
        res.cutbacks += 1
        res.cutback_reasons.append(out.reason)
        consecutive += 1
        if out.reason == "inverted":
            inverted = (out.cells, s, out.history)
        # give up after max_cutbacks halvings in a row, or once the increment would fall
        # below its floor: converged tiny steps near a limit point must not reset the
        # count forever (the load factor would creep towards the limit point)
        if consecutive > max_cutbacks or 0.5 * ds < nominal * 0.5**max_cutbacks:
            if inverted is not None:  # an inversion in this failure chain is the root cause
                err = _failure("inverted", *inverted, res.cutbacks, nt.unheld_note())
            else:
                err = _failure(
                    out.reason, out.cells, s, out.history, res.cutbacks, nt.unheld_note()
                )
            res.u, res.min_jacobian, res.message = u, min_j, str(err)
            nt.count_into(res)
            if raise_on_failure:
                raise err
            return res
        ds *= 0.5
    res.u = u
    res.converged = True
    res.min_jacobian = min_j
    nt.count_into(res)
    return res
