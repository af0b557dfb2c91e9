"""Penalty strategy: ramp λ linearly within a frame and raise it until ε meets its target.

Paper §3.2 "Solution Strategy": a global penalty λ(t) increasing linearly, with its maximum
adjusted to a desired tracking residual ε. Here the ramp restarts every frame from a soft
penalty, so the parts of the body whose phase is unambiguous pull the model first and the
mechanics carries it past wrap ambiguities; the frame stops at the first stage whose ε meets
the target. When the ramp's top does not reach it, λ_max is doubled (up to ``penalty_limit``)
while each doubling still lowers ε by at least 3 %; past that the residual is at the noise
floor of the data, and raising λ would only fit noise: a plateau within the accepted level
(:meth:`~harpx.tracking.settings.TrackingSettings.accepted_plateau`) counts as reached. A
raise that reaches ``penalty_limit`` while ε still falls has not levelled off: the frame is
a miss (:meth:`~harpx.tracking.frame.FrameOutcome.finish_raise`). The λ_max that worked
starts the next frame.

A doubling refines a fit that has converged at the λ before it, so it moves the body little
(well under half a tag period on every scene; ``benchmarks/results/tracking_defaults.md``).
One that moves a constraint point by ``tuning.raise_move`` (half a tag period) or more has
pulled it into another tag's basin: the data overpower the model, and raising further
crushes cells and meets the target far from the true motion. The raise then stops at the
state before that doubling and the frame is a miss, never a fit reached by dragging the
body across a wrap.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from harpx._typing import FloatArray
from harpx.tracking.frame import FrameGoal, FrameOutcome, FrameProblem


def phase_step(constraint: Any, u: FloatArray, v: FloatArray) -> float:
    """Largest change of a tag's phase between displacements ``u`` and ``v``, tag periods.

    Over the constraint points, along each tag that has data at the point in frame 0
    (``constraint``: a :class:`~harpx.tracking.constraint.PhaseConstraint`).
    """
    moved = constraint.current_points(u) - constraint.current_points(v)
    cycles = np.abs(moved @ constraint.wavevectors.T) / (2.0 * np.pi)  # (point, tag)
    return float(cycles[constraint.reference_valid].max(initial=0.0))


def track_frame_penalty(problem: FrameProblem, u: FloatArray, goal: FrameGoal) -> FrameOutcome:
    """Track one frame with the penalty method.

    Parameters
    ----------
    problem : FrameProblem
        Body, constraint (targeted at the frame), loads, solver and settings.
    u : ndarray, shape (ndof,)
        Starting displacement, mm.
    goal : FrameGoal
        Target ε, relative λ_max at the top of the ramp, accepted plateau, and whether ``u``
        is an earlier pass's result (then the ramp is skipped).

    Returns
    -------
    FrameOutcome
        Not reached (``stalled`` and ``plateau`` False) at the state before a doubling that
        moved a point by ``tuning.raise_move`` tag periods or more (module notes).
    """
    settings = problem.settings
    constraint = problem.constraint
    scale = constraint.penalty_scale()
    constraint.multipliers[:] = 0.0
    outcome = FrameOutcome.start(u)
    lam_max = float(goal.penalty)
    ramp = settings.ramp
    levels = [lam_max] if goal.warm else list(lam_max * np.arange(1, ramp + 1) / ramp)
    best = np.inf
    before: FrameOutcome | None = None  # the converged fit a doubling starts from
    while True:
        for stage, lam in enumerate(levels):
            constraint.penalty = lam * scale
            # stages below the ramp's top only continue the path: a few iterations suffice
            last = stage == len(levels) - 1
            iterations = settings.max_iterations
            outcome.add(
                problem.solve(
                    outcome.u,
                    iterations if last else min(iterations, settings.tuning.ramp_iterations),
                    outcome.last,
                ),
                lam,
                last,
            )
            if before is not None and (
                phase_step(constraint, outcome.u, before.u) >= settings.tuning.raise_move
            ):
                # the doubling relocated the body across a wrap: keep the fit before it
                kept = replace(before, iterations=outcome.iterations, stages=outcome.stages)
                return kept.finish(reached=False)
            if outcome.epsilon <= goal.target:
                return outcome.finish(reached=True)
        stall = settings.tuning.stall
        if 2.0 * lam_max > settings.penalty_limit or outcome.epsilon > (1.0 - stall) * best:
            # the limit, or the data's noise floor: doubling λ no longer lowers ε
            return outcome.finish_raise(best, stall, goal.accepted)
        best = min(best, outcome.epsilon)
        before = replace(outcome)
        lam_max *= 2.0
        levels = [lam_max]
