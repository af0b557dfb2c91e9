"""Penalty strategy: ramp λ linearly within a frame and raise it until ε meets its target.

Paper §3.2 "Solution Strategy": a global penalty λ(t) increasing linearly, with its maximum
adjusted to a desired tracking residual ε. Here the ramp restarts every frame from a soft
penalty, so the parts of the body whose phase is unambiguous pull the model first and the
mechanics carries it past wrap ambiguities; the frame stops at the first stage whose ε meets
the target. When the ramp's top does not reach it, λ_max is doubled (up to ``penalty_limit``)
while each doubling still lowers ε by at least 3 %; past that the residual is at the noise
floor of the data, and raising λ would only fit noise. The λ_max that worked starts the next
frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from harpx._typing import FloatArray
from harpx.mechanics.linsolve import LinearSolver
from harpx.tracking.constraint import ConstraintState, PhaseConstraint
from harpx.tracking.equilibrium import Timings, equilibrate

#: Relative decrease of ε below which raising the penalty is judged to have stalled (the
#: residual has reached the noise floor of the data).
STALL = 0.03
#: Gauss–Newton iterations of the intermediate (continuation) stages of the ramp.
RAMP_ITERATIONS = 3


@dataclass
class FrameOutcome:
    """What tracking one frame produced.

    Attributes
    ----------
    u : ndarray, shape (ndof,)
        Tracked displacement, mm.
    state : ConstraintState
        Constraint at ``u``.
    epsilon : float
        Tracking residual ε reached, rad.
    penalty : float
        Final relative penalty (dimensionless; see :mod:`harpx.tracking.constraint`).
    iterations : int
        Gauss–Newton iterations over all stages.
    stages : int
        Penalty stages (penalty method) or multiplier updates (augmented Lagrangian).
    reached : bool
        Whether ε met the target.
    """

    u: FloatArray
    state: ConstraintState
    epsilon: float
    penalty: float
    iterations: int
    stages: int
    reached: bool


def track_frame_penalty(
    body: Any,
    constraint: PhaseConstraint,
    u: FloatArray,
    *,
    target: float,
    penalty: float,
    penalty_limit: float,
    ramp: int,
    solver: LinearSolver,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    tolerance: float = 1e-3,
    max_iterations: int = 10,
    timings: Timings | None = None,
) -> FrameOutcome:
    """Track one frame with the penalty method.

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
        Relative λ_max at the top of the ramp (dimensionless).
    penalty_limit : float
        Largest relative λ_max the automatic raise may use.
    ramp : int
        Number of linear stages from λ_max/ramp to λ_max.
    solver : LinearSolver
        Linear solver reused across solves.
    dirichlet, terms : sequences, optional
        Prescribed displacements and further residual terms.
    tolerance : float, default 1e-3
        Gauss–Newton increment tolerance, mm.
    timings : Timings, optional
        Accumulates sampling, assembly and solve times.
    max_iterations : int, default 10
        Gauss–Newton iterations per stage.

    Returns
    -------
    FrameOutcome
    """
    scale = constraint.penalty_scale()
    constraint.multipliers[:] = 0.0
    iterations = stages = 0
    lam_max = float(penalty)
    fractions = np.arange(1, ramp + 1) / ramp
    levels = list(lam_max * fractions)
    best = np.inf
    while True:
        for stage, lam in enumerate(levels):
            constraint.penalty = lam * scale
            # stages below the ramp's top only continue the path: a few iterations suffice
            last = stage == len(levels) - 1
            res = equilibrate(
                body,
                constraint,
                u,
                dirichlet=dirichlet,
                terms=terms,
                solver=solver,
                tolerance=tolerance,
                max_iterations=max_iterations if last else min(max_iterations, RAMP_ITERATIONS),
                timings=timings,
            )
            u, state = res.u, res.state
            iterations += res.iterations
            stages += 1
            eps = state.epsilon()
            if eps <= target:
                return FrameOutcome(u, state, eps, lam, iterations, stages, True)
        if 2.0 * lam_max > penalty_limit or eps > (1.0 - STALL) * best:
            # the limit, or the data's noise floor: doubling λ no longer lowers ε
            return FrameOutcome(u, state, eps, lam_max, iterations, stages, False)
        best = min(best, eps)
        lam_max *= 2.0
        levels = [lam_max]
