"""The tracking settings as one validated, immutable object.

:class:`TrackingSettings` is built once (by :func:`harpx.tracking.track.track` from its
keywords, or by the user) and travels unchanged from the accessor down to the Gauss–Newton
solves, so every value is checked in one place and recorded in the result's attributes.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, Literal

import numpy as np

__all__ = ["SolverTuning", "TrackingSettings"]

Method = Literal["penalty", "augmented-lagrangian"]
Predictor = Literal["none", "linear"]
Regularization = Literal["increment", "total"]

METHODS: tuple[str, ...] = ("penalty", "augmented-lagrangian")
PREDICTORS: tuple[str, ...] = ("none", "linear")
REGULARIZATIONS: tuple[str, ...] = ("increment", "total")


#: Mean |wrapped residual| of phase uniform in [−π, π), rad: what ε is when the body matches
#: nothing, so a target at or above it is met by noise.
_NOISE_EPSILON = 0.5 * math.pi


def _is_number(value: Any) -> bool:
    """A real scalar: Python or numpy int/float (numpy scalars come from arrays), not bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def _not_a_number(name: str, value: Any, what: str) -> TypeError:
    hint = ""
    if isinstance(value, np.ndarray):
        hint = " (a scalar, not an array: e.g. value.item())"
    return TypeError(f"{name}={value!r} must be {what}, not {type(value).__name__}{hint}")


def _positive(name: str, value: Any, *, allow_none: bool = False) -> float | None:
    if value is None and allow_none:
        return None
    if not _is_number(value):
        raise _not_a_number(name, value, "a number")
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name}={value!r} must be a positive finite number")
    return float(value)


def _count(name: str, value: Any, *, minimum: int) -> int:
    if not _is_number(value):
        raise _not_a_number(name, value, "a whole number")
    if not math.isfinite(value) or value != int(value) or value < minimum:
        raise ValueError(f"{name}={value!r} must be a whole number ≥ {minimum}")
    return int(value)


@dataclass(frozen=True)
class SolverTuning:
    """Inner constants of the tracking solver: the one place they are set.

    Users rarely change these; they are here (rather than scattered through the solver's
    modules) so that a study can record and vary them like any other setting.

    Parameters
    ----------
    stall : float, default 0.03
        Relative decrease of ε below which raising the penalty is judged to have stalled
        (the residual has reached what the data allow), dimensionless in (0, 1).
    ramp_iterations : int, default 3
        Gauss–Newton iterations of the intermediate (continuation) stages of the penalty
        ramp (≥ 1).
    damp_after : int, default 10
        Iterations after which a cycling Gauss–Newton iteration is damped, whatever its
        steps (≥ 1).
    damp_small_after : int, default 3
        Iterations after which cycling with small steps (below ``small_step`` of the trust
        radius) is damped: such steps no longer search for a tag basin (≥ 1).
    small_step : float, default 0.1
        Fraction of the trust radius below which a step counts as small, in (0, 1).
    contraction : float, default 0.8
        Increments that do not shrink below this fraction of the last one count as
        cycling, in (0, 1).
    fast : float, default 0.5
        Contraction per iteration below which the increments still to come are bounded by
        the geometric series ρ s / (1 − ρ), so that a solve may stop once that bound is
        below the tolerance, in (0, 1).
    predictor_factors : tuple of float, default (0.0, 0.5, 1.0)
        Extrapolation factors α of the linear predictor u(n−1) + α (u(n−1) − u(n−2)) (each
        ≥ 0, at least one). The largest that does not fold the mesh (α = 1: the last
        frame's velocity kept) starts the frame unless a smaller one lowers the phase
        residual ε by more than ``predictor_margin``.
    predictor_margin : float, default 0.05
        Relative decrease of ε (dimensionless, in [0, 1)) by which a factor that carries
        less of the last velocity must beat the one chosen so far. Wrapped phase repeats
        every tag period, so a start a quarter period short of the motion and one a
        quarter period beyond it have the same ε: such a tie carries no information, and
        the steady motion decides.
    raise_move : float, default 0.5
        Largest move of a constraint point, in tag periods of phase along a tag that sees
        it, that one doubling of the penalty may make (> 0). A doubling refines a converged
        fit; one that moves a point half a period or more has dragged it into another tag
        basin, so the raise stops at the fit before it and the frame is a miss
        (:mod:`harpx.tracking.penalty`).
    first_pass_voxels : float, default 0.1
        Gauss–Newton tolerance of the first pass when a blur-correction pass follows, in
        voxels of the phase grid (its finest spacing; > 0), never below ``tolerance``: the
        correction pass solves every frame the first pass reached again to ``tolerance``,
        and the blur predicted from the first pass changes with its state by a fraction of
        the correction's change across a voxel. Looser first passes keep the errors of
        ordinary scenes but can let a frame whose penalty raise would drag the body across
        a wrap pass as reached (``tests/test_stability.py``).
    step_accuracy : float or None, default 0.01
        Relative error, in (0, 1), to which each Gauss–Newton step is solved iteratively,
        preconditioned with the factorisation of an earlier tangent
        (:class:`~harpx.mechanics.linsolve.LinearSolver` with ``reuse_measure="step"``: a
        bounded conjugate-gradient loop that falls back to a fresh factorisation); None
        factorises every tangent. An inexact Newton method converges with such steps
        (Dembo, Eisenstat & Steihaug 1982): the increments that decide convergence stop at
        ``tolerance``, where a 1 % error of the step is far below it.
    factor_precision : {"single", "double"}, default "single"
        Precision of those factorisations (``LinearSolver(factors=...)``): single-precision
        factors halve the bytes every preconditioning solve reads, and a fresh
        factorisation's step is refined in double precision to ``step_accuracy``, so the
        steps are as accurate as with double-precision factors; a tangent too
        ill-conditioned for that turns the solver to double precision. Ignored without
        ``step_accuracy`` (every tangent is then factorised and solved in double precision).

    Raises
    ------
    ValueError, TypeError
        Naming the constant that is out of range.

    Examples
    --------
    >>> SolverTuning(stall=0.05).stall
    0.05
    >>> SolverTuning(fast=1.5)
    Traceback (most recent call last):
    ...
    ValueError: fast=1.5 must lie in (0, 1)
    """

    stall: float = 0.03
    ramp_iterations: int = 3
    damp_after: int = 10
    damp_small_after: int = 3
    small_step: float = 0.1
    contraction: float = 0.8
    fast: float = 0.5
    predictor_factors: tuple[float, ...] = (0.0, 0.5, 1.0)
    predictor_margin: float = 0.05
    raise_move: float = 0.5
    first_pass_voxels: float = 0.1
    step_accuracy: float | None = 0.01
    factor_precision: Literal["single", "double"] = "single"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in ("stall", "small_step", "contraction", "fast"):
            value = _positive(name, getattr(self, name))
            assert value is not None
            if value >= 1.0:
                raise ValueError(f"{name}={value!r} must lie in (0, 1)")
            set_(self, name, value)
        margin = self.predictor_margin
        if not _is_number(margin):
            raise _not_a_number("predictor_margin", margin, "a number")
        if not (math.isfinite(margin) and 0.0 <= margin < 1.0):
            raise ValueError(f"predictor_margin={margin!r} must lie in [0, 1)")
        set_(self, "predictor_margin", float(margin))
        for name in ("raise_move", "first_pass_voxels"):
            set_(self, name, _positive(name, getattr(self, name)))
        accuracy = _positive("step_accuracy", self.step_accuracy, allow_none=True)
        if accuracy is not None and accuracy >= 1.0:
            raise ValueError(f"step_accuracy={accuracy!r} must lie in (0, 1), or be None")
        set_(self, "step_accuracy", accuracy)
        if self.factor_precision not in ("single", "double"):
            raise ValueError(
                f"factor_precision={self.factor_precision!r} is not 'single' or 'double'"
            )
        for name in ("ramp_iterations", "damp_after", "damp_small_after"):
            set_(self, name, _count(name, getattr(self, name), minimum=1))
        factors = tuple(float(a) for a in self.predictor_factors)
        if not factors or not all(math.isfinite(a) and a >= 0 for a in factors):
            raise ValueError(
                f"predictor_factors={self.predictor_factors!r} must be one or more finite "
                "numbers ≥ 0"
            )
        set_(self, "predictor_factors", factors)


@dataclass(frozen=True)
class TrackingSettings:
    r"""How a body is pulled through the phase images (paper §3.2).

    Parameters
    ----------
    method : {"penalty", "augmented-lagrangian"}, default "penalty"
        Constraint enforcement: a penalty λ ramped within each frame and raised until ε meets
        its target, or per-point multipliers updated at a fixed penalty.
    epsilon : float, optional
        Target tracking residual ε, the weighted mean of
        :math:`|W(\varphi(x, t) - \varphi_0(X))|` over the constrained volume, rad.
        Default (None): ``epsilon_factor`` times the noise floor the images allow in each
        frame (``epsilon_floor`` in the result, :mod:`harpx.tracking.noise`), but never
        below ``epsilon_min``, so that the penalty is not raised to fit noise. A number
        keeps full control; it must be below π/2, the mean of ``|W(·)|`` over phase that
        matches nothing (uniform in [−π, π)): a target there is met by any displacement.
    epsilon_factor : float, default 1.5
        Default target relative to the estimated phase-noise floor (dimensionless, ≥ 1).
        The residual at the true motion exceeds the noise alone (the band-pass blur the
        correction leaves, partial volume), so a target a little above the floor avoids
        fitting noise; a looser fit under-reports wall thickening, the only cue the model
        has for motion no tag sees. Why 1.5: ``benchmarks/results/tracking_defaults.md``.
    plateau_factor : float, default 2.0
        With the default target only: a frame whose ε levels off above the target
        (doubling λ lowers it by less than 3 %: the images' own residual, e.g. the band-pass
        filter's blur at the tissue's edges, not noise) has reached what the data allow if
        ε is within ``plateau_factor`` times the target (dimensionless, ≥ 1); it is marked
        ``plateau`` and counts as reached. Above that it is a miss (warned), and so is a
        frame whose penalty reaches ``penalty_limit`` while ε is still falling, whatever
        its ε. A user-given ``epsilon`` is never relaxed.
    epsilon_min : float, default 0.03
        Lowest default target, rad (0.5 % of a tag period; below π/2, as ``epsilon``): on
        clean data (an estimated floor near 0) the target is this; on noisy images the
        floor decides. About the phase the band-pass blur correction leaves at a wall: a
        tighter default fit follows that leftover instead of the tissue (wall thickening
        under-reported on noise-free images; user guide, "Wall thickening").
    penalty : float, default 1.0
        Starting λ_max relative to material stiffness and tag wavenumber (dimensionless;
        1 makes the data stiffness λ|k|² equal to μ/h² at the element scale h). The tracker
        raises it, frame by frame, until ε reaches its target, so the start only sets how
        softly the first frame begins.
    penalty_limit : float, default 1e4
        Largest relative penalty the automatic raise may reach (dimensionless).
    ramp : int, default 2
        Linear penalty stages per frame, λ_max/ramp … λ_max (penalty method).
    multiplier_tolerance : float, default 0.1
        λ_tol of the augmented-Lagrangian updates: relative change ‖ΔΛ‖/‖Λ‖ (dimensionless).
    max_updates : int, default 10
        Multiplier updates per penalty level (augmented Lagrangian, ≥ 1).
    predictor : {"none", "linear"}, default "linear"
        Start each frame from the previous displacement, or from the linear extrapolation
        u(n−1) + α (u(n−1) − u(n−2)): α = 1 (the last velocity kept) unless a smaller
        factor of ``tuning.predictor_factors`` lowers the phase residual by more than
        ``tuning.predictor_margin`` (wrapped phase repeats every tag period, so near-ties
        carry no information and the steady motion decides). A frame that ends above its
        target from an extrapolated start (a miss, or a plateau) is tracked again from
        u(n−1), and the fit with the lower ε is kept: where the motion turns, as at end
        systole, the extrapolation can start part of the body in a neighbouring tag's basin.
    robust_scale : float or None, default 0.5
        Residual scale :math:`r_0` (rad) of the Cauchy loss on each constraint point's
        phase mismatch :math:`r` (:class:`harpx.tracking.constraint.PhaseConstraint`): a
        point pulls with the weight :math:`1/(1 + (r/r_0)^2)` of its quadratic force, so
        points whose phase lies in a neighbouring tag's basin (:math:`|r|` near π) cannot
        drag the body across a wrap while the penalty rises, and the bulk
        (:math:`|r| \ll r_0`) is fitted as by least squares. None: the paper's quadratic
        penalty. Penalty method only: the augmented-Lagrangian multiplier update
        :math:`\Lambda \leftarrow \Lambda + \lambda r` assumes the quadratic form, so that
        method keeps it.
    regularization : {"total", "increment"}, default "total"
        What the tracking model resists. ``"total"`` (the paper's formulation): the stored
        energy of the whole deformation from frame 0. ``"increment"``: each frame starts
        stress-free from the previous frame's tracked state (the previous mechanical force
        is balanced), so the model regularises only the frame-to-frame increment while the
        phase constraint still matches every frame to φ0(X). The activation estimate of
        :mod:`harpx.inverse` needs ``"total"`` (fibre stretch drifts under the increment).
    blur_passes : int, optional
        Passes of the band-pass blur correction (:mod:`harpx.tracking.blur`, ≥ 0): after
        tracking every frame, the phase the band-pass filter adds under the tracked motion
        is predicted, removed from the images, and every frame is tracked again, each
        started from the previous pass's result. 0 is the paper's formulation (the blurred
        phase as it is). Default (None): one pass with the default target, none when
        ``epsilon`` is given (the prediction is only as good as the fit it comes from).
        Applied only to phase images that say they come from the disk band-pass
        (``bandpass="disk"``, as :func:`~harpx.imaging.harp.extract_phase` writes); the
        result records the passes made (``blur_passes_applied``, ``iterations_per_pass``).
    wall_smoothing : float, optional
        Predict each blur-correction pass from the tracked motion averaged along the wall
        over this length, mm (:mod:`harpx.tracking.wall`; the motion itself stays as
        tracked). Needs a body with ``"endo"`` and ``"epi"`` boundaries. None (default): the
        prediction uses the tracked motion as it is.
    tolerance : float, default 0.01
        Gauss–Newton convergence, mm: the largest nodal increment is below it, or the
        increments contract so fast (``tuning.fast``, full steps) that those still to come
        sum to less than it (a geometric bound).
    max_iterations : int, default 20
        Gauss–Newton iterations per full penalty stage (≥ 1); a solve that needs more is
        reported (``converged`` False and a warning).
    intorder : int, optional
        Gauss order of the constraint quadrature (≥ 1); default: points at most a voxel apart.
    linear_solver : str, default "auto"
        See :class:`harpx.mechanics.linsolve.LinearSolver`.
    progress : bool or None, default None
        A progress bar over the frames of each pass (``"tracking"``, then
        ``"tracking (blur correction)"``). None: shown when someone watches (a Jupyter
        notebook or a terminal) once tracking has run a few seconds, never in logs or
        pipes (:mod:`harpx._progress`); True or False force it.
    tuning : SolverTuning, optional
        The solver's inner constants (stall threshold, ramp iterations, damping, predictor
        factors); the defaults suit every scene measured.

    Raises
    ------
    ValueError, TypeError
        Naming the setting that is out of range or of the wrong type.

    Examples
    --------
    >>> TrackingSettings(epsilon=0.1).target(0.2)
    0.1
    >>> round(TrackingSettings().target(0.1), 3), TrackingSettings().target(0.0)
    (0.15, 0.03)
    >>> TrackingSettings(ramp=float("nan"))
    Traceback (most recent call last):
    ...
    ValueError: ramp=nan must be a whole number ≥ 1
    """

    method: Method = "penalty"
    epsilon: float | None = None
    epsilon_factor: float = 1.5
    plateau_factor: float = 2.0
    epsilon_min: float = 0.03
    penalty: float = 1.0
    penalty_limit: float = 1e4
    ramp: int = 2
    multiplier_tolerance: float = 0.1
    max_updates: int = 10
    predictor: Predictor = "linear"
    robust_scale: float | None = 0.5
    regularization: Regularization = "total"
    blur_passes: int | None = None
    wall_smoothing: float | None = None
    tolerance: float = 0.01
    max_iterations: int = 20
    intorder: int | None = None
    linear_solver: str = "auto"
    progress: bool | None = None
    tuning: SolverTuning = SolverTuning()

    def __post_init__(self) -> None:
        for name, allowed in (
            ("method", METHODS),
            ("predictor", PREDICTORS),
            ("regularization", REGULARIZATIONS),
        ):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name}={getattr(self, name)!r}; expected one of {allowed!r}")
        set_ = object.__setattr__
        set_(self, "epsilon", _positive("epsilon", self.epsilon, allow_none=True))
        set_(self, "robust_scale", _positive("robust_scale", self.robust_scale, allow_none=True))
        set_(self, "wall_smoothing",
             _positive("wall_smoothing", self.wall_smoothing, allow_none=True))  # fmt: skip
        for name in ("epsilon_factor", "plateau_factor", "epsilon_min", "penalty", "penalty_limit",
                     "multiplier_tolerance", "tolerance"):  # fmt: skip
            set_(self, name, _positive(name, getattr(self, name)))
        for name in ("epsilon", "epsilon_min"):
            value = getattr(self, name)
            if value is not None and value >= _NOISE_EPSILON:
                raise ValueError(
                    f"{name}={value!r} rad is at or above π/2 ({_NOISE_EPSILON:.4f} rad), the "
                    "mean |wrapped phase residual| of phase that matches nothing: noise meets "
                    "such a target at any displacement. Give a target well below it (the "
                    f"residual at the true motion is near the images' noise floor), or omit "
                    f"{name} for its default"
                )
        if self.epsilon_factor < 1.0:
            raise ValueError(
                f"epsilon_factor={self.epsilon_factor!r} must be ≥ 1: a target below the "
                "images' noise floor cannot be reached"
            )
        if self.plateau_factor < 1.0:
            raise ValueError(f"plateau_factor={self.plateau_factor!r} must be ≥ 1")
        if self.penalty_limit < self.penalty:
            raise ValueError(
                f"penalty_limit={self.penalty_limit!r} is below penalty={self.penalty!r}"
            )
        set_(self, "ramp", _count("ramp", self.ramp, minimum=1))
        set_(self, "max_updates", _count("max_updates", self.max_updates, minimum=1))
        if self.blur_passes is not None:
            set_(self, "blur_passes", _count("blur_passes", self.blur_passes, minimum=0))
        set_(self, "max_iterations", _count("max_iterations", self.max_iterations, minimum=1))
        if self.intorder is not None:
            set_(self, "intorder", _count("intorder", self.intorder, minimum=1))
        if not isinstance(self.linear_solver, str):
            raise TypeError(f"linear_solver={self.linear_solver!r} must be a string")
        set_(self, "progress", None if self.progress is None else bool(self.progress))
        if not isinstance(self.tuning, SolverTuning):
            raise TypeError(f"tuning={self.tuning!r} must be a SolverTuning")

    @classmethod
    def build(cls, settings: TrackingSettings | None = None, **overrides: Any) -> TrackingSettings:
        """``settings`` (default: the defaults) with the keyword ``overrides`` applied.

        The one way the accessor, :func:`~harpx.tracking.track.track`, the batch runner
        and the CLI turn user input into settings.

        Parameters
        ----------
        settings : TrackingSettings, optional
            Settings to start from; None (default): ``TrackingSettings()``.
        **overrides
            Settings to replace, by field name (e.g. ``epsilon=0.1``); each is validated as
            in the constructor.

        Returns
        -------
        TrackingSettings
            ``settings`` itself when there are no overrides, otherwise a new object.

        Raises
        ------
        TypeError
            If ``settings`` is not a :class:`TrackingSettings`, or a keyword is not a
            setting (naming it and listing the settings).

        Examples
        --------
        >>> TrackingSettings.build(epsilon=0.1).epsilon
        0.1
        >>> TrackingSettings.build(TrackingSettings(ramp=3), epsilon=0.1).ramp
        3
        >>> TrackingSettings.build(epsilom=0.1)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        TypeError: 'epsilom' is not a tracking setting; the settings are: method, ...
        """
        base = cls() if settings is None else settings
        if not isinstance(base, TrackingSettings):
            raise TypeError(f"settings={settings!r} must be a TrackingSettings")
        names = [f.name for f in fields(cls)]
        unknown = [k for k in overrides if k not in names]
        if unknown:
            raise TypeError(
                f"{unknown[0]!r} is not a tracking setting; the settings are: {', '.join(names)}"
            )
        return replace(base, **overrides) if overrides else base

    @property
    def effective_robust_scale(self) -> float | None:
        """The Cauchy scale the constraint uses: ``robust_scale`` for the penalty method,
        None (quadratic) for the augmented Lagrangian."""
        return self.robust_scale if self.method == "penalty" else None

    @property
    def effective_blur_passes(self) -> int:
        """Blur-correction passes to make: ``blur_passes``, or 1 with the default target and
        0 with a user-given ``epsilon``."""
        if self.blur_passes is not None:
            return int(self.blur_passes)
        return 1 if self.epsilon is None else 0

    def target(self, floor: float) -> float:
        """Tracking residual to reach in a frame whose noise floor is ``floor``.

        Parameters
        ----------
        floor : float
            The frame's estimated phase-noise floor of ε (:mod:`harpx.tracking.noise`), rad.

        Returns
        -------
        float
            ``epsilon`` if given, else ``max(epsilon_min, epsilon_factor * floor)``, rad.
        """
        if self.epsilon is not None:
            return float(self.epsilon)
        return float(max(self.epsilon_min, self.epsilon_factor * floor))

    def accepted_plateau(self, floor: float) -> float:
        """Highest ε at which a levelled-off penalty raise still counts as reached, rad.

        ``plateau_factor`` times the frame's target for the default target; the target
        itself when the user gave ``epsilon`` (a plateau above it is then always a miss).

        Parameters
        ----------
        floor : float
            The frame's estimated phase-noise floor of ε, rad, as in :meth:`target`.

        Returns
        -------
        float
            Highest accepted ε, rad.

        Examples
        --------
        >>> round(TrackingSettings().accepted_plateau(0.03), 3)
        0.09
        >>> TrackingSettings(epsilon=0.1).accepted_plateau(0.03)
        0.1
        """
        if self.epsilon is not None:
            return float(self.epsilon)
        return float(self.plateau_factor * self.target(floor))

    def as_attrs(self) -> dict[str, Any]:
        """The settings as NetCDF-safe attributes.

        Returns
        -------
        dict of str to object
            One ``setting_<name>`` entry per field, the :class:`SolverTuning` fields as
            ``setting_tuning_<name>``; None is written as ``"auto"`` or ``"none"`` (``-1``
            for ``intorder``), booleans as 0 or 1 and tuples as lists.
        """
        out: dict[str, Any] = {}
        items = asdict(self)
        tuning = items.pop("tuning")
        items.update({f"tuning_{k}": v for k, v in tuning.items()})
        for key, value in items.items():
            if isinstance(value, tuple):
                value = list(value)
            if value is None:
                value = {
                    "epsilon": "auto",
                    "robust_scale": "none",
                    "blur_passes": "auto",
                    "wall_smoothing": "none",
                    "progress": "auto",
                    "tuning_step_accuracy": "none",
                }.get(key, -1)
            elif isinstance(value, bool):
                value = int(value)
            out[f"setting_{key}"] = value
        return out
