"""Augmented-Lagrangian strategy: per-point multipliers updated at a fixed penalty.

Paper §3.2: "an iterative approximation to its local values to a given tolerance". Each
constraint point carries multipliers Λ (one per tag); after every equilibrium solve they are
updated, Λ ← Λ + λ W(φ − φ0), until their relative change falls below ``multiplier_tolerance``
(λ_tol) or ε meets its target. If neither happens within ``max_updates``, λ is doubled (up to
``penalty_limit``) while that still lowers ε by the penalty method's stall margin.
Multipliers carry over from frame to frame as a warm start; a blur-correction pass starts
each frame from the multipliers that frame ended with in the pass before.
"""

from __future__ import annotations

from harpx._typing import FloatArray
from harpx.tracking.frame import FrameGoal, FrameOutcome, FrameProblem


def track_frame_augmented(problem: FrameProblem, u: FloatArray, goal: FrameGoal) -> FrameOutcome:
    """Track one frame with the augmented-Lagrangian method.

    Parameters
    ----------
    problem, u
        As in :func:`~harpx.tracking.penalty.track_frame_penalty`; of the settings, this
        method also reads ``multiplier_tolerance`` and ``max_updates``.
    goal : FrameGoal
        Target ε, the fixed relative penalty λ and the accepted plateau (``goal.warm`` is
        part of the strategies' common goal; this method has no ramp to skip).

    Returns
    -------
    FrameOutcome
    """
    settings = problem.settings
    constraint = problem.constraint
    scale = constraint.penalty_scale()
    lam = float(goal.penalty)
    outcome = FrameOutcome.start(u)
    best = float("inf")
    while True:
        constraint.penalty = lam * scale
        for _ in range(settings.max_updates):  # max_updates ≥ 1 (TrackingSettings)
            outcome.add(problem.solve(outcome.u, settings.max_iterations, outcome.last), lam, True)
            if outcome.epsilon <= goal.target:
                return outcome.finish(reached=True)
            assert outcome.state is not None  # set by add()
            change = constraint.update_multipliers(outcome.state)
            if change < settings.multiplier_tolerance:
                break
        stall = settings.tuning.stall
        if 2.0 * lam > settings.penalty_limit or outcome.epsilon > (1.0 - stall) * best:
            return outcome.finish_raise(best, stall, goal.accepted)
        best = min(best, outcome.epsilon)
        lam *= 2.0
