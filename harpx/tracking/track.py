"""Track a finite-element body through harmonic-phase images, frame by frame.

This is the method of the paper (§3): a hyperelastic model of the organ, in its reference
configuration at frame 0, is pulled through the phase images by the phase-conservation
constraint (:mod:`harpx.tracking.constraint`) with the penalty or the augmented-Lagrangian
strategy, each frame started from the last (optionally extrapolated). Before the first frame
the tracker works out what the tags can see (:mod:`harpx.tracking.observability`) and the
noise floor of the residual that the images allow (:mod:`harpx.tracking.noise`). The
result is a self-contained ``tracked/1`` dataset.
"""

from __future__ import annotations

import time as _time
import warnings
from collections.abc import Sequence
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np
import xarray as xr

from harpx._progress import progress_bar
from harpx._typing import BoolArray
from harpx.errors import ElementInversionError, HarpxWarning, SchemaError, user_stacklevel
from harpx.imaging.coverage import explain_missing_data, phase_direction_mismatch
from harpx.imaging.phase_parameters import PhaseParameters, warn_spamm_dc
from harpx.imaging.tag_frequency import tag_frequency_flag, tags_unmeasured
from harpx.mechanics.assembly import internal_forces
from harpx.mechanics.linsolve import LinearSolver
from harpx.schema import GRID_DIMS, grid_step, validate
from harpx.tracking.augmented import track_frame_augmented
from harpx.tracking.blur import blur_models, lazily_deblurred
from harpx.tracking.constraint import PhaseConstraint
from harpx.tracking.equilibrium import Timings, split_dirichlet
from harpx.tracking.frame import FrameGoal, FrameOutcome, FrameProblem
from harpx.tracking.image_fit import background_fraction, check_coverage, check_fits_image
from harpx.tracking.observability import describe_direction
from harpx.tracking.penalty import track_frame_penalty
from harpx.tracking.results import tracked_dataset
from harpx.tracking.settings import SolverTuning, TrackingSettings
from harpx.tracking.wall import (
    MIN_CELLS_ACROSS,
    cells_across_wall,
    smooth_along_wall,
    transmural_depth,
    wall_smoother,
)

__all__ = ["track"]

STRATEGIES = {"penalty": track_frame_penalty, "augmented-lagrangian": track_frame_augmented}
#: Constraint points from which a worker thread samples the images while the solve
#: assembles (:func:`~harpx.tracking.equilibrium.equilibrate`): below this the arrays are
#: small, the two threads mostly wait for the interpreter lock, and one thread is faster
#: (measured in benchmarks/results/tracking_speed.md).
_OVERLAP_POINTS = 50_000


def _as_phase(ds: xr.Dataset) -> xr.Dataset:
    kind = ds.attrs.get("harpx_schema")
    if kind == "tagged/1":
        from harpx.imaging.harp import extract_phase

        return extract_phase(ds)
    validate(ds, "phase")
    return ds


def _predict(
    body: Any,
    constraint: PhaseConstraint,
    last: np.ndarray,
    before: np.ndarray,
    tuning: SolverTuning,
    executor: Executor | None = None,
) -> np.ndarray:
    """Start of a frame: u(n−1) + α (u(n−1) − u(n−2)), the steady motion first.

    The largest factor α of ``tuning.predictor_factors`` whose start does not fold the mesh
    starts the frame unless a smaller one lowers the phase residual by more than
    ``tuning.predictor_margin`` (relative): wrapped phase repeats every tag period, so
    starts a quarter period short of and beyond the motion have the same residual, and such
    a tie carries no information. With no admissible factor the frame starts from u(n−1).
    With an ``executor`` the candidates' phase residuals are sampled on it while the mesh
    checks run here.
    """
    step = last - before
    alphas = sorted(set(tuning.predictor_factors), reverse=True)
    guesses = [last + alpha * step for alpha in alphas]
    # one image sampling per candidate, on the worker while the fold checks run here
    pending = [executor.submit(constraint.epsilon_at, g) for g in guesses] if executor else None
    best, best_eps = last, np.inf
    chosen = False
    for k, (alpha, guess) in enumerate(zip(alphas, guesses, strict=True)):
        if alpha and internal_forces(body, guess, tangent=False).r is None:
            continue  # folds the mesh (or overstretches it): not a candidate
        eps = constraint.epsilon_at(guess) if pending is None else pending[k].result()
        eps = eps if np.isfinite(eps) else np.inf
        if not chosen or eps < (1.0 - tuning.predictor_margin) * best_eps:
            best, best_eps, chosen = guess, eps, True
    for job in pending or ():  # a folding candidate's sample: wait for it, then drop it
        if not job.cancel():
            job.result()
    return best


def _mechanical_force(body: Any, u: np.ndarray, terms: Sequence[Any]) -> np.ndarray:
    """Internal force plus further residual terms at ``u`` (mN): what the model resists."""
    internal = internal_forces(body, u, tangent=False)
    if internal.r is None:  # pragma: no cover - tracked states never invert (checked per step)
        raise SchemaError("a tracked state inverts cells; this is a bug, please report it")
    force = np.array(internal.r, dtype=np.float64)
    for term in terms:
        force += term.residual_tangent(body, u, 1.0)[0]
    return force


def _check_data(phase: xr.Dataset, constraint: PhaseConstraint) -> None:
    if not constraint.reference_valid.any():
        raise SchemaError(
            "no constraint point of the body lies inside the image data in frame 0: "
            + explain_missing_data(phase, constraint.points)
        )
    seen_by_tag = cast(BoolArray, constraint.reference_valid.any(axis=0))
    blind = [str(t) for t, seen in zip(phase["tag"].values, seen_by_tag, strict=True) if not seen]
    if blind:
        raise SchemaError(
            f"tag {blind!r} has no data at any constraint point of the body in frame 0 (its "
            "mask or field of view misses the mesh), so the body could not be tracked along "
            f"it; fix the tag's mask or drop it (ds.drop_sel(tag={blind!r}))"
        )


def _warn_unseen(constraint: PhaseConstraint) -> None:
    seen = constraint.observability
    assert seen is not None
    if seen.body_rank == 3:
        return
    tags = ", ".join(
        f"{label} ({d[0]:.2g}, {d[1]:.2g}, {d[2]:.2g})"
        for label, d in zip(constraint.phase["tag"].values, constraint.directions, strict=True)
    )
    unseen = " and ".join(describe_direction(a) for a in seen.unseen_axes)
    removed = (
        f"the rigid-body motion the tags cannot see ({'; '.join(seen.unseen_directions)}) was "
        "removed (held at zero mean)"
        if seen.unseen_directions
        else "the Dirichlet conditions hold its rigid-body part"
    )
    warnings.warn(
        f"no tag sees motion along {unseen} (tags: {tags}): there the tracked motion comes "
        f"from the mechanics alone; {removed}. 'observed_directions' per cell says what each "
        "cell's tags see. To measure it, add tags along it (e.g. long-axis slices with a "
        "through-plane tag); to set it, hold the body there with a Dirichlet condition.",
        HarpxWarning,
        stacklevel=user_stacklevel(),
    )


def _warn_wall_smoothing(across: float | None) -> None:
    """Warn when ``wall_smoothing`` has no pass to act on (``across`` None), or is asked of
    a wall fewer than ``MIN_CELLS_ACROSS`` cells thick (:mod:`harpx.tracking.wall`)."""
    if across is None:
        warnings.warn(
            "wall_smoothing has no effect: no blur-correction pass is made (blur_passes=0, "
            "a user-given epsilon without blur_passes, or phase images not from the disk "
            "band-pass)",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    elif across < MIN_CELLS_ACROSS:
        warnings.warn(
            f"wall_smoothing: the wall is about {across:.1f} cells thick (fewer than "
            f"{MIN_CELLS_ACROSS:g}): the depth keeps little of the thickening profile, so the "
            "blur correction may under-report radial strain; a finer mesh across the wall, "
            "or wall_smoothing=None (attrs['wall_cells_across'] keeps the count)",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )


def _warn_frames(phase: xr.Dataset, reached: np.ndarray, converged: np.ndarray,
                 eps: np.ndarray, target: np.ndarray, floor: np.ndarray) -> None:  # fmt: skip
    times = phase["time"].values
    missed = [n for n in range(1, len(reached)) if not reached[n]]
    if missed:
        detail = ", ".join(
            f"frame {n} (t={float(times[n]):g} ms: ε {eps[n]:.3g} vs target {target[n]:.3g}, "
            f"floor {floor[n]:.3g} rad)"
            for n in missed[:5]
        )
        warnings.warn(
            f"{len(missed)} frame(s) missed the tracking target: {detail}"
            f"{' …' if len(missed) > 5 else ''}. The penalty stopped rising there (its limit, or ε "
            "levelled off above what noise explains: the model cannot follow the data, or a "
            "tag jumped); 'target_reached' marks them. Pass a larger epsilon=, or a larger "
            "penalty_limit= if the penalty reached its limit.",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    stopped = [n for n in range(1, len(converged)) if not converged[n]]
    if stopped:
        warnings.warn(
            f"the Gauss–Newton solve stopped at its iteration limit in frame(s) "
            f"{stopped[:10]}{' …' if len(stopped) > 10 else ''} ('converged' marks them); "
            "raise max_iterations= or tolerance=, or track with more frames",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )


def track(
    ds: xr.Dataset,
    body: Any,
    *,
    settings: TrackingSettings | None = None,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    **overrides: Any,
) -> xr.Dataset:
    """Track a body through a phase (or tagged) image series with the phase constraint.

    Parameters
    ----------
    ds : xarray.Dataset
        ``phase/1`` dataset, or ``tagged/1`` (its phase is extracted with defaults first).
    body : Body
        Finite-element model in the reference configuration of frame 0 (mm).
    settings : TrackingSettings, optional
        All tracking settings as one validated object (default: ``TrackingSettings()``),
        documented with units and defaults on
        :class:`~harpx.tracking.settings.TrackingSettings`. By default the target ε is
        ``epsilon_factor`` times the noise floor the images allow in each frame (never below
        ``epsilon_min``), each point's pull is weighted robustly (``robust_scale``), and
        after a first pass over all frames the band-pass blur predicted from it is removed
        from the images and every frame tracked again (``blur_passes``,
        :mod:`harpx.tracking.blur`). When such a pass follows, the first pass's Gauss–Newton
        solves stop at ``tuning.first_pass_voxels`` of a phase-grid voxel
        (``first_pass_tolerance``, never below ``tolerance``), as every frame it reaches is
        solved again to ``tolerance`` on the corrected images; a frame it misses is tracked
        again at ``tolerance`` before it is kept.
    dirichlet : sequence, optional
        Prescribed displacements (:class:`harpx.mechanics.loads.Fixed`, ``Prescribed``).
    terms : sequence, optional
        Further residual terms (pressure, body force).
    **overrides
        Any field of :class:`~harpx.tracking.settings.TrackingSettings` (``epsilon=0.1``,
        ``method="augmented-lagrangian"``, ``progress=True`` …), applied on top of
        ``settings`` (:meth:`TrackingSettings.build`).

    Returns
    -------
    xarray.Dataset
        ``tracked/1`` with displacement, strain, fibre stretch (if fibres), per-frame
        diagnostics ``epsilon``, ``epsilon_target``, ``epsilon_floor``, ``epsilon_cell``,
        ``penalty``, ``iterations``, ``stages``, ``wall_time``, ``target_reached``,
        ``plateau``, ``converged``, ``blur_correction``; observability
        ``observed_directions`` (cell) and
        ``observed_fraction`` (cell, axis) with the unseen rigid motions in the attribute
        ``unseen_directions``; ``displacement_grid`` on the phase grid. Constraint points
        outside the field of view or the mask carry no force; a point inside some tags'
        masks only (e.g. short-axis but not long-axis slices) is pulled by those tags alone,
        along the directions they see. ``first_pass_tolerance`` (mm) is the Gauss–Newton
        tolerance of the first pass, ``iterations_per_pass`` the Gauss–Newton iterations of
        each pass. The run time is recorded in attributes, s:
        ``time_total`` (the whole call) and by stage ``time_phase``, ``time_setup``,
        ``time_first_pass``, ``time_blur`` (predicting the blur), ``time_correction_pass``
        and ``time_output`` (strain and the grid displacement), with the Gauss–Newton parts
        ``time_sampling``, ``time_assembly`` and ``time_solve``
        (:class:`~harpx.tracking.equilibrium.Timings`).

    Raises
    ------
    TypeError
        If a keyword is not a tracking setting (names it), or ``settings`` is not a
        :class:`~harpx.tracking.settings.TrackingSettings`.
    ValueError
        If a setting is out of range (names it).
    SchemaError
        If no constraint point lies in the image data at frame 0, a tag has data at none
        of them, or a later frame has no valid phase at any of them (an all-zero or fully
        masked frame).
    ElementInversionError
        If a Gauss–Newton step inverts elements even after step halving (names the
        frame and the cells).

    Warns
    -----
    HarpxWarning
        When the tags leave a direction of the body's motion unseen (names it), when a
        frame misses its target ε, when a Gauss–Newton solve stops at its iteration limit,
        or when the phase's measured tag peak misses a tag's ``tag_frequency`` or
        ``tag_direction`` (:func:`~harpx.imaging.tag_frequency.tag_frequency_flag`; recorded
        as ``attrs["tags_off_frequency"]``; the tags nothing could check as
        ``attrs["tags_frequency_unmeasured"]``).

    Notes
    -----
    The constraint force is paper eq. 5, its tangent eq. 6; see
    :mod:`harpx.tracking.constraint` for the wrap-safe form used here.

    Examples
    --------
    A rigid translation by (0.8, -0.5, 0.3) mm, imaged with CSPAMM tags along x, y and z
    and tracked with a block of 4 × 4 × 2 hexahedra:

    >>> from harpx.imaging.harp import extract_phase
    >>> from harpx.imaging.synth import synthesize_tagged
    >>> from harpx.mechanics.body import Body
    >>> from harpx.mechanics.materials import NeoHookean
    >>> from harpx.mechanics.mesh import box
    >>> from harpx.tracking.results import tracking_error
    >>> shift = np.array([0.8, -0.5, 0.3])  # mm at t = 20 ms
    >>> tagged = synthesize_tagged(
    ...     lambda X, t: np.broadcast_to(shift * t / 20.0, X.shape), shape=(12, 24, 24),
    ...     spacing=(1.5, 1.5, 1.5), times=[0.0, 20.0], tags=("x", "y", "z"), snr=None,
    ...     oversample=1)
    >>> body = Body(box((12.0, 12.0, 6.0), (4, 4, 2), origin=(-6.0, -6.0, -3.0)),
    ...             NeoHookean(c1=1.0, kappa=100.0))
    >>> result = track(extract_phase(tagged), body)
    >>> result.displacement.isel(time=-1).mean("node").round(2).values.tolist()
    [0.8, -0.5, 0.3]
    >>> bool(tracking_error(result, tagged).max_all < 0.05)  # mm, against the truth
    True
    """
    settings = TrackingSettings.build(settings, **overrides)
    timings = Timings()
    clock = entry = _time.perf_counter()
    phase = _as_phase(ds)
    setup_start = _time.perf_counter()
    timings.phase = setup_start - clock
    swapped = phase_direction_mismatch(phase)
    if swapped:
        raise SchemaError(swapped)
    off_frequency = tag_frequency_flag(phase, "FE tracking")
    warn_spamm_dc(phase, "FE tracking")
    check_fits_image(body, phase)  # units and size, before anything large is allocated
    constraint = PhaseConstraint(
        body, phase, intorder=settings.intorder, robust_scale=settings.effective_robust_scale
    )
    _check_data(phase, constraint)
    outside = check_coverage(
        phase, constraint.points, constraint.volume, constraint.reference_valid
    )
    fixed, _ = split_dirichlet(body, dirichlet)
    seen = constraint.observe(fixed)
    _warn_unseen(constraint)
    # PARDISO on MKL's threads (the sampling worker below waits while it solves), which sleep
    # as soon as each call returns, so that they do not spin on the worker's core
    solver = LinearSolver(
        settings.linear_solver,
        reuse=settings.tuning.step_accuracy,
        reuse_measure="step",
        release_cores=True,
        factors=settings.tuning.factor_precision if settings.tuning.step_accuracy else "double",
    )
    # one worker samples the images at each trial step while the solve assembles there
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="harpx-sampling") as pool:
        overlap = constraint.points.shape[0] >= _OVERLAP_POINTS
        problem = FrameProblem(body, constraint, settings, solver, dirichlet, terms, timings,
                               executor=pool if overlap else None)  # fmt: skip
        plan = _BlurPlan.of(body, phase, settings)  # before the first pass: it needs the wall
        result = _track_frames(problem, phase, setup_start, loose=plan.first_tolerance)
        wall = result.wall.copy()  # per frame, over every pass
        timings.first_pass = float(wall[1:].sum())
        pass_iterations = [int(result.iterations.sum())]
        correction_mean = np.zeros(phase.sizes["time"])
        for _ in range(plan.passes):
            result, correction_mean = _correction_pass(problem, phase, result, plan.smoother)
            wall[1:] += result.wall[1:]
            timings.correction_pass += float(result.wall[1:].sum())
            pass_iterations.append(int(result.iterations.sum()))
    wall[0] = timings.setup + timings.blur  # frame 0: every pass's set-up and the corrections
    _warn_frames(phase, result.reached, result.converged, result.eps, result.target, result.floor)
    constraint.release_frame()  # the last frame's sampler buffers, before the output's
    clock = _time.perf_counter()
    attrs = {
        "method": settings.method,
        "epsilon_target": "auto" if settings.epsilon is None else float(settings.epsilon),
        "penalty_start": float(settings.penalty),
        **settings.as_attrs(),
        "constraint_intorder": -1 if constraint.intorder is None else constraint.intorder,
        "constraint_points_per_cell": constraint.points_per_cell,
        "constraint_points": int(constraint.points.shape[0]),
        "penalty_scale": constraint.penalty_scale(),
        "linear_solver": problem.solver.method,
        "seen_directions": int(seen.body_rank),
        "unseen_directions": "; ".join(seen.unseen_directions) or "none",
        "rigid_modes_removed": int(seen.unseen_modes.shape[0]),
        "outside_fraction": float(outside),
        "background_fraction": background_fraction(
            phase, constraint.points, constraint.volume, constraint.reference_valid
        ),
        "tags_off_frequency": off_frequency,
        "tags_frequency_unmeasured": " ".join(tags_unmeasured(phase)) or "none",
        "blur_passes_applied": int(plan.passes),
        **({} if plan.across is None else {"wall_cells_across": round(plan.across, 2)}),
        "first_pass_tolerance": float(plan.first_tolerance),
        **_blur_model_attrs(phase, plan.passes),
        "iterations_per_pass": np.asarray(pass_iterations, dtype=np.int64),
        **timings.as_attrs(),
    }
    diagnostics = _diagnostics(result, correction_mean, wall, seen)
    out = tracked_dataset(body, result.U, phase, diagnostics, attrs)
    timings.output = _time.perf_counter() - clock
    timings.total = _time.perf_counter() - entry
    out.attrs.update(timings.as_attrs())
    return out


@dataclass(frozen=True)
class _BlurPlan:
    """The blur-correction passes of a run and what they need (:func:`track`)."""

    passes: int  # correction passes after the first (0 without a disk band-pass)
    first_tolerance: float  # the first pass's step tolerance, mm (looser when passes follow)
    smoother: Any  # the along-wall smoother of the predicted motion (``wall_smoothing``)
    across: float | None  # cells across the wall (``wall_smoothing``), None otherwise

    @classmethod
    def of(cls, body: Any, phase: xr.Dataset, settings: TrackingSettings) -> _BlurPlan:
        disk = PhaseParameters.from_dataset(phase).disk_bandpass  # the correction models it
        passes = settings.effective_blur_passes if disk else 0
        smoother, across = None, None
        if settings.wall_smoothing is not None:
            if passes:
                depth = transmural_depth(body)
                smoother = wall_smoother(body, settings.wall_smoothing, depth)
                across = cells_across_wall(body, depth)
            _warn_wall_smoothing(across)
        first_tolerance = settings.tolerance
        if passes:  # a correction pass re-converges every frame: the first pass less tightly
            first_tolerance = max(
                settings.tolerance, settings.tuning.first_pass_voxels * _voxel(phase)
            )
        return cls(passes, first_tolerance, smoother, across)


def _correction_pass(
    problem: FrameProblem, phase: xr.Dataset, result: _Pass, smoother: Any
) -> tuple[_Pass, np.ndarray]:
    """One blur-correction pass: the images ``phase`` corrected for the blur of the motion
    tracked so far (smoothed along the wall with ``smoother``), every frame tracked again
    from ``result``; and the mean correction per frame (rad)."""
    body, constraint, timings = problem.body, problem.constraint, problem.timings
    clock = _time.perf_counter()
    constraint.release_frame()  # the last frame's sampler buffers, before the blur's
    # the corrected images, built frame by frame when the constraint reads them
    motion = result.U if smoother is None else smooth_along_wall(body, result.U, smoother)
    corrected, correction_mean = lazily_deblurred(phase, body, motion)
    constraint.replace_images(corrected)  # frame 0 is uncorrected: its samples stay
    del corrected  # the constraint holds it
    timings.blur += _time.perf_counter() - clock
    return _track_frames(problem, constraint.phase, _time.perf_counter(), result), correction_mean


def _diagnostics(
    result: _Pass, correction_mean: np.ndarray, wall: np.ndarray, seen: Any
) -> dict[str, Any]:
    """The per-frame and per-cell diagnostics of a tracked result (``tracked/1``)."""
    return {
        "epsilon": result.eps,
        "epsilon_target": result.target,
        "epsilon_floor": result.floor,
        "epsilon_cell": result.eps_cell,
        "penalty": result.penalty,
        "iterations": result.iterations,
        "stages": result.stages,
        "target_reached": result.reached,
        "converged": result.converged,
        "plateau": result.plateau,
        "blur_correction": correction_mean,
        "wall_time": wall,
        "observed_directions": (("cell",), seen.cell_rank),
        "observed_fraction": (("cell", "axis"), seen.cell_seen),
    }


@dataclass
class _Pass:
    """Arrays of one pass over every frame (:func:`_track_frames`)."""

    U: np.ndarray
    eps: np.ndarray
    floor: np.ndarray
    target: np.ndarray
    eps_cell: np.ndarray
    penalty: np.ndarray
    iterations: np.ndarray
    stages: np.ndarray
    reached: np.ndarray
    converged: np.ndarray
    plateau: np.ndarray
    wall: np.ndarray
    #: augmented-Lagrangian multipliers per frame (time, nq, ntag), kPa/rad; None otherwise
    multipliers: np.ndarray | None = None


def _voxel(phase: xr.Dataset) -> float:
    """Finest spacing of the phase grid, mm (over the axes with more than one voxel; 0 if none)."""
    steps = (grid_step(phase, d) for d in GRID_DIMS)
    return min((abs(h) for h in steps if h is not None), default=0.0)


def _track_frames(
    problem: FrameProblem,
    phase: xr.Dataset,
    start: float,
    earlier: _Pass | None = None,
    loose: float | None = None,
) -> _Pass:
    """Track every frame of ``phase`` in order, each started from the last (one pass).

    ``loose`` (mm, a first pass only): the Gauss–Newton tolerance of the pass in place of
    ``settings.tolerance``; a frame that misses its target with it is tracked again from the
    same start with ``settings.tolerance``, so a miss, kept by the later passes, is as
    converged as without ``loose``.

    A later pass (``earlier`` given) starts each frame from the earlier pass's result and
    penalty for it (and, with the augmented-Lagrangian method, its multipliers), which the
    blur correction moves only a little. A frame the earlier pass missed keeps that pass's
    result and stays a miss: its correction is predicted from the missed fit, and tracking
    the corrected images would only confirm that fit, meeting the target far from the true
    motion (``benchmarks/results/tracking_defaults.md``).
    """
    body, constraint, settings = problem.body, problem.constraint, problem.settings
    timings, terms = problem.timings, problem.terms
    ntime = phase.sizes["time"]
    out = _Pass(
        U=np.zeros((ntime, body.ndof)), eps=np.zeros(ntime), floor=np.zeros(ntime),
        target=np.zeros(ntime), eps_cell=np.full((ntime, body.ncell), np.nan),
        penalty=np.zeros(ntime), iterations=np.zeros(ntime, dtype=np.int64),
        stages=np.zeros(ntime, dtype=np.int64), reached=np.ones(ntime, dtype=bool),
        converged=np.ones(ntime, dtype=bool), plateau=np.zeros(ntime, dtype=bool),
        wall=np.zeros(ntime),
    )  # fmt: skip
    if settings.method == "augmented-lagrangian":  # each frame's multipliers, for later passes
        out.multipliers = np.zeros((ntime, *constraint.multipliers.shape))
    U = out.U
    constraint.set_frame(0)
    st0 = constraint.state(U[0])
    out.eps[0] = st0.epsilon()
    out.floor[0] = constraint.epsilon_floor(U[0])
    out.target[0] = settings.target(out.floor[0])
    out.eps_cell[0] = constraint.epsilon_cell(st0)
    out.wall[0] = _time.perf_counter() - start
    timings.setup += out.wall[0]
    lam = settings.penalty
    relaxed = None
    if loose is not None and loose != settings.tolerance:
        relaxed = TrackingSettings.build(settings, tolerance=loose)
    desc = "tracking" if earlier is None else "tracking (blur correction)"
    for n in progress_bar(range(1, ntime), progress=settings.progress, desc=desc, unit="frame"):
        if earlier is not None and not earlier.reached[n]:
            _keep(out, earlier, n)
            continue
        begin = _time.perf_counter()
        # the images prepared around where the frame starts (the whole grid if it goes further)
        constraint.set_frame(n, near=U[n - 1] if earlier is None else earlier.U[n])
        clock = _time.perf_counter()
        timings.prefilter += clock - begin
        u0 = U[n - 1]
        if earlier is not None:
            u0, lam = earlier.U[n], max(settings.penalty, float(earlier.penalty[n]))
            if earlier.multipliers is not None:
                # the frame's own, not those the earlier pass ended its last frame with
                constraint.multipliers = earlier.multipliers[n].copy()
        elif settings.predictor == "linear" and n >= 2:
            u0 = _predict(body, constraint, U[n - 1], U[n - 2], settings.tuning, problem.executor)
        if settings.regularization == "increment":
            problem.offset = -_mechanical_force(body, U[n - 1], terms)
        out.floor[n] = constraint.epsilon_floor(u0)
        out.target[n] = settings.target(out.floor[n])
        timings.prediction += _time.perf_counter() - clock
        goal = FrameGoal(
            target=float(out.target[n]), penalty=lam,
            plateau=settings.accepted_plateau(out.floor[n]), warm=earlier is not None,
        )  # fmt: skip
        extrapolated = not np.array_equal(u0, U[n - 1]) and earlier is None
        outcome = _solve_frame(
            problem, goal, u0, relaxed, fallback=U[n - 1] if extrapolated else None
        )
        if not np.isfinite(outcome.epsilon) or outcome.state is None:
            where = explain_missing_data(phase, constraint.current_points(u0), n)
            raise SchemaError(
                f"frame {n} (time={float(phase['time'][n])!r} ms) has no valid phase at any "
                f"constraint point of the body: {where}"
            )
        U[n] = outcome.u
        out.eps[n] = outcome.epsilon
        out.eps_cell[n] = constraint.epsilon_cell(outcome.state)
        out.penalty[n] = outcome.penalty
        lam = max(settings.penalty, outcome.penalty)
        out.iterations[n] = outcome.iterations
        out.stages[n] = outcome.stages
        out.reached[n] = outcome.reached
        out.converged[n] = outcome.converged
        out.plateau[n] = outcome.plateau
        if out.multipliers is not None:
            out.multipliers[n] = constraint.multipliers
        out.wall[n] = _time.perf_counter() - begin
    return out


def _solve_frame(
    problem: FrameProblem,
    goal: FrameGoal,
    u0: np.ndarray,
    relaxed: TrackingSettings | None,
    fallback: np.ndarray | None,
) -> FrameOutcome:
    """Track one frame from ``u0``; again from ``fallback`` if that does not meet the target.

    ``relaxed``: the settings of a loose first pass (:func:`_track_frames`); a miss with them
    is solved again from ``u0`` at the full tolerance. ``fallback`` (the previous frame's
    fit, when ``u0`` extrapolated the motion): a frame that still ends above its target (a
    miss, or a plateau) is tracked again from it, and the fit with the lower ε is kept
    (one that meets the target first). Where the motion turns, as at end systole, the
    extrapolated start can leave part of the body in a neighbouring tag's basin; the
    penalty raise then levels off above the target with that part stopped across a wrap,
    and a blur correction predicted from it pulls the body the rest of the way. A retry
    that would invert an element (:class:`~harpx.errors.ElementInversionError`) leaves the
    first attempt's fit in place; every attempt starts from the frame's starting
    multipliers (augmented Lagrangian).
    """
    strategy = STRATEGIES[problem.settings.method]
    constraint = problem.constraint
    start = constraint.multipliers.copy()  # every attempt starts from the frame's multipliers

    def attempt(on: FrameProblem, u: np.ndarray) -> tuple[FrameOutcome, np.ndarray]:
        constraint.multipliers = start.copy()
        outcome = strategy(on, u, goal)
        return outcome, constraint.multipliers

    def retry(on: FrameProblem, u: np.ndarray) -> tuple[FrameOutcome, np.ndarray] | None:
        try:
            return attempt(on, u)
        except ElementInversionError:  # the first attempt's fit stands
            return None

    if relaxed is not None:
        loose_problem = replace(problem, settings=relaxed)  # this frame's offset included
        outcome, multipliers = attempt(loose_problem, u0)
        tight = None if outcome.reached else retry(problem, u0)  # kept by the later passes
        if tight is not None:
            tight[0].iterations += outcome.iterations
            outcome, multipliers = tight
    else:
        outcome, multipliers = attempt(problem, u0)
    again = None
    if fallback is not None and not (outcome.reached and not outcome.plateau):
        again = retry(problem, fallback)
    if again is not None:
        spent = outcome.iterations + again[0].iterations
        if (again[0].reached and not again[0].plateau) or again[0].epsilon < outcome.epsilon:
            outcome, multipliers = again
        outcome.iterations = spent
    constraint.multipliers = multipliers  # the kept fit's, which the next frame starts from
    return outcome


def _blur_model_attrs(phase: xr.Dataset, passes: int) -> dict[str, str]:
    """``blur_model`` ("slice-profile", "in-plane", "mixed" across tags, "none" without a
    pass) and ``blur_model_per_tag`` ("x: slice-profile; ..."), :mod:`harpx.tracking.blur`."""
    if not passes:
        return {"blur_model": "none", "blur_model_per_tag": "none"}
    models = blur_models(phase)
    kind = models[0] if len(set(models)) == 1 else "mixed"
    tags = [str(t) for t in phase["tag"].values]
    per_tag = "; ".join(f"{t}: {m}" for t, m in zip(tags, models, strict=True))
    return {"blur_model": kind, "blur_model_per_tag": per_tag}


def _keep(out: _Pass, earlier: _Pass, n: int) -> None:
    """Frame ``n`` of ``out`` as the ``earlier`` pass left it (no time spent in this pass)."""
    for name in ("U", "eps", "floor", "target", "eps_cell", "penalty", "iterations", "stages",
                 "reached", "converged", "plateau"):  # fmt: skip
        getattr(out, name)[n] = getattr(earlier, name)[n]
    if out.multipliers is not None and earlier.multipliers is not None:
        out.multipliers[n] = earlier.multipliers[n]
