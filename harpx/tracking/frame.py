"""One frame of tracking: the problem both strategies solve and what they report.

The penalty (:mod:`harpx.tracking.penalty`) and augmented-Lagrangian
(:mod:`harpx.tracking.augmented`) strategies differ only in how they set the penalty and
the multipliers between equilibrium solves; everything else — the body, the constraint
targeted at the frame, the loads, the linear solver, the settings and the timings — is the
:class:`FrameProblem` they share; each aims at a :class:`FrameGoal` and returns a
:class:`FrameOutcome`.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from harpx._typing import FloatArray
from harpx.mechanics.linsolve import LinearSolver
from harpx.tracking.constraint import ConstraintState, PhaseConstraint
from harpx.tracking.equilibrium import EquilibriumResult, Timings, equilibrate
from harpx.tracking.settings import TrackingSettings


@dataclass
class FrameProblem:
    """Everything an equilibrium solve of one frame needs.

    Attributes
    ----------
    body : Body
        The finite-element body.
    constraint : PhaseConstraint
        The phase constraint, targeted at the frame.
    settings : TrackingSettings
        The validated tracking settings.
    solver : LinearSolver
        Linear solver, reused across solves.
    dirichlet, terms : sequences
        Prescribed displacements and further residual terms.
    timings : Timings
        Accumulated wall time per part.
    offset : ndarray, shape (ndof,), optional
        Constant force added to the residual (minus the previous frame's mechanical force
        when only the increment is regularised), mN.
    executor : concurrent.futures.Executor, optional
        A worker that samples the images while the solves assemble
        (:func:`~harpx.tracking.equilibrium.equilibrate`); None: one thread does both.
    """

    body: Any
    constraint: PhaseConstraint
    settings: TrackingSettings
    solver: LinearSolver
    dirichlet: Sequence[Any] = ()
    terms: Sequence[Any] = ()
    timings: Timings = field(default_factory=Timings)
    offset: FloatArray | None = None
    executor: Executor | None = None

    def solve(
        self, u: FloatArray, max_iterations: int, start: EquilibriumResult | None = None
    ) -> EquilibriumResult:
        """Gauss–Newton equilibrium from ``u`` at the constraint's current λ and Λ.

        ``start``: the frame's previous solve, if it ended at ``u`` (its evaluations there
        are reused).
        """
        return equilibrate(
            self.body, self.constraint, u, dirichlet=self.dirichlet, terms=self.terms,
            solver=self.solver, tolerance=self.settings.tolerance, max_iterations=max_iterations,
            offset=self.offset, timings=self.timings, start=start, tuning=self.settings.tuning,
            executor=self.executor,
        )  # fmt: skip


@dataclass(frozen=True)
class FrameGoal:
    """What a strategy aims at in one frame, and the penalty it starts from.

    Attributes
    ----------
    target : float
        Tracking residual ε to reach, rad.
    penalty : float
        Relative penalty to start from (dimensionless; see
        :mod:`harpx.tracking.constraint`): λ_max at the top of the penalty method's ramp,
        the fixed λ of the augmented-Lagrangian method.
    plateau : float, optional
        Highest ε at which a levelled-off penalty raise counts as reached, rad (default: the
        target; :meth:`~harpx.tracking.settings.TrackingSettings.accepted_plateau`).
    warm : bool, default False
        The starting displacement is an earlier pass's result for this frame: the penalty
        method starts at the top of its ramp (the augmented-Lagrangian method has no ramp).
    """

    target: float
    penalty: float
    plateau: float | None = None
    warm: bool = False

    @property
    def accepted(self) -> float:
        """Highest ε at which a levelled-off raise counts as reached, rad."""
        return self.target if self.plateau is None else self.plateau


@dataclass
class FrameOutcome:
    """What tracking one frame produced.

    Attributes
    ----------
    u : ndarray, shape (ndof,)
        Tracked displacement, mm.
    state : ConstraintState or None
        Constraint at ``u`` (None before the first solve).
    last : EquilibriumResult or None
        The last solve of this frame (None before the first), which ended at ``u``.
    epsilon : float
        Tracking residual ε reached, rad.
    penalty : float
        Final relative penalty (dimensionless; see :mod:`harpx.tracking.constraint`).
    iterations : int
        Gauss–Newton iterations over all stages.
    stages : int
        Penalty stages (penalty method) or multiplier updates (augmented Lagrangian).
    reached : bool
        Whether ε met the target, or levelled off within the accepted plateau.
    converged : bool
        Whether the last full Gauss–Newton solve met its increment tolerance (rather than
        stopping at its iteration limit).
    stalled : bool
        Whether the penalty raise stopped because ε no longer fell (the data's plateau)
        rather than at ``penalty_limit``.
    plateau : bool
        Whether the frame counts as reached above its target: ε levelled off (``stalled``)
        within the accepted level. A raise stopped at ``penalty_limit`` while ε still fell
        is a miss, never a plateau.
    """

    u: FloatArray
    state: ConstraintState | None = None
    last: EquilibriumResult | None = None
    epsilon: float = float("inf")
    penalty: float = 0.0
    iterations: int = 0
    stages: int = 0
    reached: bool = False
    converged: bool = True
    stalled: bool = False
    plateau: bool = False

    @classmethod
    def start(cls, u: FloatArray) -> FrameOutcome:
        """An outcome that has not solved anything yet, at displacement ``u``."""
        return cls(u=np.asarray(u, dtype=np.float64))

    def add(self, result: EquilibriumResult, penalty: float, final_stage: bool) -> None:
        """Take in one equilibrium solve at relative penalty ``penalty``."""
        self.u, self.state, self.last = result.u, result.state, result
        self.epsilon = result.state.epsilon()
        self.penalty = float(penalty)
        self.iterations += result.iterations
        self.stages += 1
        if final_stage:
            self.converged = bool(result.converged)

    def finish_raise(self, best: float, stall: float, accepted: float) -> FrameOutcome:
        """End a penalty raise that did not meet the target (limit or plateau).

        The raise stalled if the last ε fell by less than the fraction ``stall`` below the
        ``best`` before it: ε has levelled off at what the data allow, and an ε of at most
        ``accepted`` counts as reached (``plateau``). Otherwise it stopped at
        ``penalty_limit`` while ε was still falling (or the first level was already the
        limit, so nothing shows it levelled off): a higher penalty would have lowered it,
        so the frame is a miss whatever its ε, as is a plateau above ``accepted``.
        """
        self.stalled = bool(self.epsilon > (1.0 - stall) * best)
        self.plateau = self.stalled and self.epsilon <= accepted
        return self.finish(reached=self.plateau)

    def finish(self, *, reached: bool) -> FrameOutcome:
        """Mark whether the target was met and return self."""
        self.reached = bool(reached)
        return self
