"""Augmented-Lagrangian strategy: per-point multipliers updated at a fixed penalty.

Paper §3.2: "an iterative approximation to its local values to a given tolerance". Each
constraint point carries multipliers Λ (one per tag); after every equilibrium solve they are
updated, Λ ← Λ + λ W(φ − φ0), until their relative change falls below ``multiplier_tolerance``
(λ_tol) or ε meets its target. If neither happens within ``max_updates``, λ is doubled (up to
``penalty_limit``). Multipliers carry over from frame to frame as a warm start.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from harpx._typing import FloatArray
from harpx.mechanics.linsolve import LinearSolver
from harpx.tracking.constraint import PhaseConstraint
from harpx.tracking.equilibrium import Timings, equilibrate
from harpx.tracking.penalty import STALL, FrameOutcome


def track_frame_augmented(
    body: Any,
    constraint: PhaseConstraint,
    u: FloatArray,
    *,
    target: float,
    penalty: float,
    penalty_limit: float,
    multiplier_tolerance: float,
    max_updates: int,
    solver: LinearSolver,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    tolerance: float = 1e-3,
    max_iterations: int = 10,
    timings: Timings | None = None,
) -> FrameOutcome:
    """Track one frame with the augmented-Lagrangian method.

    Parameters
    ----------
    body : Body
        The finite-element body.
    constraint : PhaseConstraint
        Constraint targeted at the frame (``set_frame`` called).
    u : ndarray, shape (ndof,)
        Starting displacement, mm.
    target : float
        Tracking residual ε to reach, rad.
    penalty : float
        Relative penalty λ (dimensionless).
    penalty_limit : float
        Largest relative penalty the automatic raise may use.
    multiplier_tolerance : float
        λ_tol: stop when ‖ΔΛ‖/‖Λ‖ falls below it (dimensionless).
    max_updates : int
        Multiplier updates before the penalty is raised.
    solver : LinearSolver
        Linear solver reused across solves.
    dirichlet, terms : sequences, optional
        Prescribed displacements and further residual terms.
    tolerance : float, default 1e-3
        Gauss–Newton increment tolerance, mm.
    timings : Timings, optional
        Accumulates sampling, assembly and solve times.
    max_iterations : int, default 10
        Gauss–Newton iterations per solve.

    Returns
    -------
    FrameOutcome
    """
    scale = constraint.penalty_scale()
    lam = float(penalty)
    iterations = stages = 0
    best = float("inf")
    while True:
        constraint.penalty = lam * scale
        for _ in range(max_updates):
            res = equilibrate(
                body,
                constraint,
                u,
                dirichlet=dirichlet,
                terms=terms,
                solver=solver,
                tolerance=tolerance,
                max_iterations=max_iterations,
                timings=timings,
            )
            u, state = res.u, res.state
            iterations += res.iterations
            stages += 1
            eps = state.epsilon()
            if eps <= target:
                return FrameOutcome(u, state, eps, lam, iterations, stages, True)
            change = constraint.update_multipliers(state)
            if change < multiplier_tolerance:
                break
        if 2.0 * lam > penalty_limit or eps > (1.0 - STALL) * best:
            return FrameOutcome(u, state, eps, lam, iterations, stages, False)
        best = min(best, eps)
        lam *= 2.0
