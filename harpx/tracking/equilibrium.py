"""Gauss–Newton equilibrium of a hyperelastic body pulled by the phase constraint.

At a fixed penalty (and fixed multipliers) the tracked configuration minimises the stored
energy plus the constraint energy (:mod:`harpx.tracking.constraint`). The hyperelastic part
uses its consistent tangent (:func:`harpx.mechanics.assembly.internal_forces`); the phase
part its Gauss–Newton tangent, so convergence is fast but not exactly quadratic. Steps that
would invert an element are halved.

The hyperelastic tangent leaves out the initial-stress stiffness of the volumetric pressure
(``pressure_stiffness=False``), a Gauss–Newton simplification like the dropped phase
Hessian: with a nearly incompressible material (κ/C1 ≥ 10³) one large Gauss–Newton step
leaves volume errors of a few per cent, i.e. pressures of hundreds of μ, whose geometric
stiffness makes the consistent tangent indefinite, and the next steps then diverge. Without
that term the next step restores the volume; the residual, hence the solution, is unchanged.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from harpx._typing import FloatArray
from harpx.errors import ElementInversionError
from harpx.mechanics.assembly import internal_forces
from harpx.mechanics.linsolve import LinearSolver
from harpx.tracking.constraint import ConstraintState, PhaseConstraint
from harpx.tracking.settings import SolverTuning


@dataclass
class Timings:
    """Wall time spent in each part of tracking, s.

    ``sampling``, ``assembly`` and ``solve`` are the Gauss–Newton iterations' image
    sampling, residual/tangent assembly (with step-halving checks) and linear solves;
    ``phase`` validates (or extracts) the phase images, ``setup`` builds the constraint
    points and samples the reference frame, ``prefilter`` prepares each frame's images for
    interpolation, ``prediction`` picks each frame's starting guess, ``blur`` predicts and
    removes the band-pass blur between passes (:mod:`harpx.tracking.blur`) and ``output``
    builds the ``tracked/1`` dataset (strain, resampling onto the image grid). Parts that
    repeat in every pass add up. By stage: ``first_pass`` and ``correction_pass`` are the
    frames 1… of the first pass and of the blur-correction passes (each frame's
    preparation, prediction and Gauss–Newton solves), and ``total`` the whole call, from
    the phase images to the returned dataset.
    """

    sampling: float = 0.0
    assembly: float = 0.0
    solve: float = 0.0
    phase: float = 0.0
    setup: float = 0.0
    prefilter: float = 0.0
    prediction: float = 0.0
    blur: float = 0.0
    output: float = 0.0
    first_pass: float = 0.0
    correction_pass: float = 0.0
    total: float = 0.0

    def as_attrs(self) -> dict[str, float]:
        """The timings as dataset attributes (``time_sampling`` …), s."""
        return {f"time_{k}": round(float(v), 3) for k, v in vars(self).items()}


@dataclass
class EquilibriumResult:
    """Outcome of one Gauss–Newton solve.

    Attributes
    ----------
    u : ndarray, shape (ndof,)
        Displacement, mm.
    state : ConstraintState
        Constraint evaluated at ``u``.
    iterations : int
        Gauss–Newton iterations taken.
    step_norms : list of float
        Largest nodal displacement increment of each iteration, mm.
    converged : bool
        Whether the last increment was below the tolerance.
    internal : InternalForces or None
        Internal forces and tangent at ``u`` (a next solve from ``u`` starts with them).
    """

    u: FloatArray
    state: ConstraintState
    iterations: int
    step_norms: list[float] = field(default_factory=list)
    converged: bool = False
    internal: Any = None


def split_dirichlet(body: Any, dirichlet: Sequence[Any]) -> tuple[np.ndarray, FloatArray]:
    if not dirichlet:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    dofs = np.concatenate([d.dofs(body) for d in dirichlet])
    values = np.concatenate([d.values(body, 1.0) for d in dirichlet])
    return dofs, values


def _remaining(steps: list[float], fast: float = SolverTuning().fast) -> float:
    """Bound on the distance, mm, from the latest iterate to the converged one.

    With the last two increments contracting by ρ = s_k / s_(k-1) < ``fast``
    (:attr:`SolverTuning.fast <harpx.tracking.settings.SolverTuning>`), the
    increments still to come sum to at most ρ s_k / (1 − ρ) (a geometric series; Gauss–Newton
    near its solution contracts at least this fast). inf when the bound does not apply.
    """
    if len(steps) < 2 or steps[-2] <= 0.0:
        return float("inf")
    rate = steps[-1] / steps[-2]
    return rate * steps[-1] / (1.0 - rate) if rate < fast else float("inf")


def _admissible_step(
    body: Any,
    constraint: PhaseConstraint,
    u: FloatArray,
    du: FloatArray,
    alpha: float,
    seen: Any,
    max_halvings: int,
    iteration: int,
    history: list[float],
    executor: Executor | None = None,
) -> tuple[FloatArray, Any, float, Future[ConstraintState] | None]:
    """The step ``u + alpha du``, halved until no element inverts.

    With an ``executor`` the constraint state at the first trial is sampled on it while the
    internal forces are assembled here (image sampling and assembly do not depend on each
    other); its future is returned when that trial is taken, else None.
    """
    for halving in range(max_halvings + 1):
        trial = u + alpha * du
        if seen is not None:
            trial = seen.remove_unseen(trial)
        pending = executor.submit(constraint.state, trial) if executor and not halving else None
        internal_trial = internal_forces(body, trial, pressure_stiffness=False)
        if internal_trial.r is not None:
            return trial, internal_trial, alpha, pending
        if pending is not None and not pending.cancel():
            pending.result()  # an inverting trial: its samples are not needed
        alpha *= 0.5
    raise ElementInversionError(
        f"Gauss-Newton step {iteration} of frame {constraint.frame} inverts cells "
        f"{internal_trial.inverted_cells[:10].tolist()} (det F <= 0 or a non-finite "
        f"stress) even after {max_halvings} halvings; lower the penalty or track "
        "with more frames",
        internal_trial.inverted_cells,
        history,
    )


def equilibrate(
    body: Any,
    constraint: PhaseConstraint,
    u: FloatArray,
    *,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    solver: LinearSolver,
    tolerance: float = 1e-3,
    max_iterations: int = 10,
    max_halvings: int = 6,
    max_step: float | None = None,
    offset: FloatArray | None = None,
    timings: Timings | None = None,
    start: EquilibriumResult | None = None,
    tuning: SolverTuning | None = None,
    executor: Executor | None = None,
) -> EquilibriumResult:
    """Solve for equilibrium at the constraint's current penalty and multipliers.

    Parameters
    ----------
    body : Body
        The finite-element body.
    constraint : PhaseConstraint
        The phase constraint, already targeted at a frame.
    u : ndarray, shape (ndof,)
        Starting displacement, mm (e.g. the previous frame's or a prediction).
    dirichlet : sequence of Dirichlet loads, optional
        Prescribed displacements (``dofs(body)``, ``values(body, s)``).
    terms : sequence of residual terms, optional
        Further residual contributions (``residual_tangent(body, u, s)``).
    solver : LinearSolver
        Linear solver, reused across calls so factorisation set-up is reused.
    tolerance : float, default 1e-3
        Convergence when the largest nodal increment is below this, mm, or when the last
        two full steps contract so fast that the increments still to come sum to less than
        it (:func:`_remaining`).
    max_iterations : int, default 10
        Iteration limit (the result reports whether it converged).
    max_halvings : int, default 6
        Step halvings allowed when a step would invert an element.
    max_step : float, optional
        Trust radius: steps whose largest nodal increment exceeds it are scaled down to it,
        mm. Default: a quarter of the shortest tag period, so that no step carries a
        point across a phase wrap into another tag's basin.
    offset : ndarray, shape (ndof,), optional
        A constant force added to the residual, mN: minus the previous frame's internal
        force when the model regularises the increment only
        (``regularization="increment"``).
    timings : Timings, optional
        Accumulates the time spent sampling images, assembling and solving.
    start : EquilibriumResult, optional
        An earlier solve of the same frame that ended at ``u`` (e.g. the previous penalty
        stage): its constraint state and internal forces at ``u`` are reused instead of
        evaluated again (neither depends on the penalty or the multipliers).
    tuning : SolverTuning, optional
        Damping of cycling iterations and the geometric stopping bound; the defaults of
        :class:`~harpx.tracking.settings.SolverTuning` if omitted.
    executor : concurrent.futures.Executor, optional
        A worker (one thread suffices) that samples the images at each trial step while
        this thread assembles the internal forces there: the two are independent and
        release the interpreter for most of their time, so on two cores they overlap. The
        iterates are the same either way. ``timings.sampling`` then counts only the time
        spent waiting for the samples after the assembly.

    Returns
    -------
    EquilibriumResult

    Notes
    -----
    Rigid-body modes that no tag sees (``constraint.observability``) are removed at every
    step: one dof per such mode is held in the linear solve, so it is never singular, and
    the step is then shifted back to zero amplitude of those modes.

    Raises
    ------
    ElementInversionError
        If even the smallest step inverts elements.
    """
    tune = SolverTuning() if tuning is None else tuning
    clock = timings if timings is not None else Timings()
    u = np.array(u, dtype=float, copy=True)
    fixed, fixed_values = split_dirichlet(body, dirichlet)
    u[fixed] = fixed_values
    seen = constraint.observability
    if seen is not None:
        u = seen.remove_unseen(u)
        held = np.union1d(fixed, seen.pinned_dofs)
    else:
        held = fixed
    if max_step is None:
        max_step = 0.5 * np.pi / constraint.max_wavenumber
    free = np.setdiff1d(np.arange(body.ndof), held) if held.size else None
    damping = 1.0
    if start is not None and start.internal is not None and np.array_equal(start.u, u):
        result = EquilibriumResult(u, start.state, 0)
        internal = start.internal
    else:
        tic = time.perf_counter()
        pending = executor.submit(constraint.state, u) if executor is not None else None
        internal = internal_forces(body, u, pressure_stiffness=False)
        clock.assembly += time.perf_counter() - tic
        tic = time.perf_counter()
        result = EquilibriumResult(
            u, constraint.state(u) if pending is None else pending.result(), 0
        )
        clock.sampling += time.perf_counter() - tic
    if internal.r is None:
        raise ElementInversionError(
            f"the starting displacement of frame {constraint.frame} inverts cells "
            f"{internal.inverted_cells[:10].tolist()}",
            internal.inverted_cells,
        )
    for iteration in range(1, max_iterations + 1):
        tic = time.perf_counter()
        rc, Kc = constraint.assemble(result.state)
        R = internal.r + rc
        if offset is not None:
            R = R + offset
        assert internal.K is not None  # assembled with the tangent
        K = internal.K.copy()
        K.data += Kc.data
        for term in terms:
            rt, Kt = term.residual_tangent(body, u, 1.0)
            R = R + rt
            if Kt is not None:
                K = K + Kt
        clock.assembly += time.perf_counter() - tic
        tic = time.perf_counter()
        if free is None:
            du = solver.solve(K, -R)
        else:
            du = np.zeros_like(u)
            du[free] = solver.solve(K[free][:, free].tocsr(), -R[free])
        clock.solve += time.perf_counter() - tic
        tic = time.perf_counter()
        largest = float(np.abs(du).max())
        alpha = min(1.0, max_step / largest) if largest > 0 else 1.0
        history = result.step_norms
        small = bool(history) and history[-1] < tune.small_step * max_step
        late = iteration > tune.damp_after or (iteration > tune.damp_small_after and small)
        if late and history[-1] > tune.contraction * history[-2]:
            # still not converged and the increments stopped shrinking: the iteration cycles
            # (e.g. between the facets of a linear phase interpolant); damp it so that it
            # contracts (early only once the steps are small: early large undamped steps
            # are what carry a point past a wrap into the right tag basin)
            damping *= 0.5
        alpha *= damping
        trial, internal_trial, alpha, pending = _admissible_step(
            body, constraint, u, du, alpha, seen, max_halvings, iteration, result.step_norms,
            executor,
        )  # fmt: skip
        clock.assembly += time.perf_counter() - tic
        tic = time.perf_counter()
        state_trial = constraint.state(trial) if pending is None else pending.result()
        clock.sampling += time.perf_counter() - tic
        u = trial
        internal = internal_trial
        step = float(np.abs(alpha * du).max())
        full = alpha == 1.0  # neither clipped by the trust radius, damped nor halved
        result.step_norms.append(step)
        result.iterations = iteration
        result.state = state_trial
        if step < tolerance or (full and _remaining(result.step_norms, tune.fast) < tolerance):
            result.converged = True
            break
    result.u = u
    result.internal = internal
    return result
