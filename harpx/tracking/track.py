"""Track a finite-element body through harmonic-phase images, frame by frame.

This is the method of the paper (§3): a hyperelastic model of the organ, in its reference
configuration at frame 0, is pulled through the phase images by the phase-conservation
constraint (:mod:`harpx.tracking.constraint`) with the penalty or the augmented-Lagrangian
strategy, each frame started from the last (optionally extrapolated). The result is a
self-contained ``tracked/1`` dataset (DESIGN §3).
"""

from __future__ import annotations

import time as _time
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import xarray as xr
from tqdm.auto import tqdm

from harpx.errors import SchemaError
from harpx.imaging.coverage import explain_missing_data, phase_direction_mismatch
from harpx.mechanics.assembly import internal_forces
from harpx.mechanics.linsolve import LinearSolver
from harpx.schema import validate
from harpx.tracking.augmented import track_frame_augmented
from harpx.tracking.constraint import PhaseConstraint
from harpx.tracking.equilibrium import Timings
from harpx.tracking.penalty import FrameOutcome, track_frame_penalty
from harpx.tracking.results import tracked_dataset

Method = Literal["penalty", "augmented-lagrangian"]
Predictor = Literal["none", "linear"]


def _as_phase(ds: xr.Dataset) -> xr.Dataset:
    kind = ds.attrs.get("harpx_schema")
    if kind == "tagged/1":
        from harpx.imaging.harp import extract_phase

        return extract_phase(ds)
    validate(ds, "phase")
    return ds


PREDICTOR_FACTORS = (0.0, 0.5, 1.0)


def _predict(
    body: Any, constraint: PhaseConstraint, last: np.ndarray, before: np.ndarray
) -> np.ndarray:
    """Extrapolated start of a frame with the smallest phase residual (see ``predictor``)."""
    best, best_eps = last, np.inf
    for alpha in PREDICTOR_FACTORS:  # three candidates, each one image sampling
        guess = last + alpha * (last - before)
        if alpha and internal_forces(body, guess, tangent=False).r is None:
            continue  # folds the mesh (or overstretches it): not a candidate
        eps = constraint.epsilon_at(guess)
        if eps < best_eps:
            best, best_eps = guess, eps
    return best


def track(
    ds: xr.Dataset,
    body: Any,
    *,
    method: Method = "penalty",
    epsilon: float = 0.05,
    penalty: float = 1.0,
    penalty_limit: float = 1e4,
    ramp: int = 2,
    multiplier_tolerance: float = 0.1,
    max_updates: int = 10,
    predictor: Predictor = "linear",
    tolerance: float = 0.01,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    intorder: int | None = None,
    linear_solver: str = "auto",
    progress: bool = False,
) -> xr.Dataset:
    """Track a body through a phase (or tagged) image series with the phase constraint.

    Parameters
    ----------
    ds : xarray.Dataset
        ``phase/1`` dataset, or ``tagged/1`` (its phase is extracted with defaults first).
    body : Body
        Finite-element model in the reference configuration of frame 0 (mm).
    method : {"penalty", "augmented-lagrangian"}, default "penalty"
        Constraint enforcement (paper §3.2 "Solution Strategy").
    epsilon : float, default 0.05
        Target tracking residual ε, mean |W(φ(x, t) − φ0(X))| over the constrained
        volume, rad.
    penalty : float, default 1.0
        Starting λ_max relative to material stiffness and tag wavenumber (dimensionless;
        1 makes the data stiffness λ|k|² equal μ/h²).
    penalty_limit : float, default 1e4
        Largest relative penalty the automatic raise may reach (dimensionless).
    ramp : int, default 2
        Linear penalty stages per frame, λ_max/ramp … λ_max (penalty method). Across frames
        λ_max itself rises automatically until ε meets its target. On the paper phantom
        ``ramp=1`` and ``ramp=3`` give the same error (0.113 mm mean over the first six
        frames) with 37 and 50 Gauss–Newton iterations.
    multiplier_tolerance : float, default 0.1
        λ_tol of the augmented-Lagrangian updates (relative change of the multipliers).
    max_updates : int, default 10
        Multiplier updates per penalty level (augmented Lagrangian).
    predictor : {"none", "linear"}, default "linear"
        Start each frame from the previous displacement (``"none"``), or from the linear
        extrapolation u(n−1) + α (u(n−1) − u(n−2)) whose phase residual ε is smallest
        among α ∈ {0, ½, 1} (``"linear"``): the images themselves pick how much of the
        last frame's velocity to carry, which keeps a decelerating motion from
        overshooting into the neighbouring tag's basin.
    tolerance : float, default 0.01
        Gauss–Newton convergence: largest nodal increment, mm (1/75 of a 0.75 mm voxel).
    dirichlet : sequence, optional
        Prescribed displacements (:class:`harpx.mechanics.loads.Fixed`, ``Prescribed``).
    terms : sequence, optional
        Further residual terms (pressure, body force).
    intorder : int, optional
        Gauss order of the constraint quadrature; default: points at most a voxel apart.
    linear_solver : str, default "auto"
        See :class:`harpx.mechanics.linsolve.LinearSolver`.
    progress : bool, default False
        Show a progress bar over frames.

    Returns
    -------
    xarray.Dataset
        ``tracked/1`` with displacement, strain, fibre stretch (if fibres), and per-frame
        diagnostics ``epsilon``, ``epsilon_cell``, ``penalty``, ``iterations``,
        ``wall_time``, ``target_reached``; ``displacement_grid`` on the phase grid.
        Constraint points outside the field of view or the mask carry no force; a point
        inside some tags' masks only (e.g. short-axis but not long-axis slices) is pulled
        by those tags alone. Cells with no data left have ``epsilon_cell`` NaN and follow
        the mechanics.

    Raises
    ------
    SchemaError
        If no constraint point lies in the image data at frame 0, a tag has data at none
        of them, or a later frame has no valid phase at any of them (an all-zero or fully
        masked frame).
    ElementInversionError
        If a Gauss–Newton step inverts elements even after step halving (names the
        frame and the cells).

    Notes
    -----
    The constraint force is paper eq. 5, its tangent eq. 6; see
    :mod:`harpx.tracking.constraint` for the wrap-safe form used here.
    """
    if method not in ("penalty", "augmented-lagrangian"):
        raise ValueError(f"method={method!r}; expected 'penalty' or 'augmented-lagrangian'")
    if predictor not in ("none", "linear"):
        raise ValueError(f"predictor={predictor!r}; expected 'none' or 'linear'")
    for name, value in (("epsilon", epsilon), ("penalty", penalty), ("tolerance", tolerance)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name}={value!r} must be a positive number")
    if penalty_limit < penalty:
        raise ValueError(f"penalty_limit={penalty_limit!r} is below penalty={penalty!r}")
    if int(ramp) < 1:
        raise ValueError(f"ramp={ramp!r} must be at least 1")
    timings = Timings()
    clock = _time.perf_counter()
    phase = _as_phase(ds)
    ntime = phase.sizes["time"]
    setup_start = _time.perf_counter()
    timings.phase = setup_start - clock
    swapped = phase_direction_mismatch(phase)
    if swapped:
        raise SchemaError(swapped)
    constraint = PhaseConstraint(body, phase, intorder=intorder)
    if not constraint.reference_valid.any():
        raise SchemaError(
            "no constraint point of the body lies inside the image data in frame 0: "
            + explain_missing_data(phase, constraint.points)
        )
    blind = [str(t) for t, seen in zip(phase["tag"].values, constraint.reference_valid.any(axis=0),
                                       strict=True) if not seen]  # fmt: skip
    if blind:
        raise SchemaError(
            f"tag {blind!r} has no data at any constraint point of the body in frame 0 (its "
            "mask or field of view misses the mesh), so the body could not be tracked along "
            f"it; fix the tag's mask or drop it (ds.drop_sel(tag={blind!r}))"
        )
    solver = LinearSolver(linear_solver)
    U = np.zeros((ntime, body.ndof))
    eps = np.zeros(ntime)
    eps_cell = np.full((ntime, body.ncell), np.nan)
    lam_used = np.zeros(ntime)
    iterations = np.zeros(ntime, dtype=np.int64)
    stages = np.zeros(ntime, dtype=np.int64)
    reached = np.ones(ntime, dtype=bool)
    wall = np.zeros(ntime)
    constraint.set_frame(0)
    st0 = constraint.state(U[0])
    eps[0] = st0.epsilon()
    eps_cell[0] = constraint.epsilon_cell(st0)
    wall[0] = _time.perf_counter() - setup_start
    timings.setup = wall[0]
    lam = float(penalty)
    for n in tqdm(range(1, ntime), disable=not progress, desc="tracking", unit="frame"):
        start = _time.perf_counter()
        constraint.set_frame(n)
        clock = _time.perf_counter()
        timings.prefilter += clock - start
        u0 = U[n - 1]
        if predictor == "linear" and n >= 2:
            u0 = _predict(body, constraint, U[n - 1], U[n - 2])
        timings.prediction += _time.perf_counter() - clock
        common = dict(
            target=epsilon,
            penalty=lam,
            penalty_limit=penalty_limit,
            solver=solver,
            dirichlet=dirichlet,
            terms=terms,
            timings=timings,
            tolerance=tolerance,
        )
        outcome: FrameOutcome
        if method == "penalty":
            outcome = track_frame_penalty(body, constraint, u0, ramp=int(ramp), **common)
        else:
            outcome = track_frame_augmented(
                body,
                constraint,
                u0,
                multiplier_tolerance=multiplier_tolerance,
                max_updates=int(max_updates),
                **common,
            )
        if not np.isfinite(outcome.epsilon):  # no constraint point saw data: ε is 0/0
            raise SchemaError(
                f"frame {n} (time={float(phase['time'][n])!r} ms) has no valid phase at any "
                f"constraint point of the body: {explain_missing_data(phase, constraint.points, n)}"
            )
        U[n] = outcome.u
        eps[n] = outcome.epsilon
        eps_cell[n] = constraint.epsilon_cell(outcome.state)
        lam_used[n] = outcome.penalty
        lam = max(float(penalty), outcome.penalty)
        iterations[n] = outcome.iterations
        stages[n] = outcome.stages
        reached[n] = outcome.reached
        wall[n] = _time.perf_counter() - start
    clock = _time.perf_counter()
    settings = {
        "method": method,
        "epsilon_target": float(epsilon),
        "penalty_start": float(penalty),
        "penalty_limit": float(penalty_limit),
        "ramp": int(ramp),
        "multiplier_tolerance": float(multiplier_tolerance),
        "predictor": predictor,
        "tolerance": float(tolerance),
        "constraint_intorder": -1 if constraint.intorder is None else constraint.intorder,
        "constraint_points_per_cell": constraint.points_per_cell,
        "constraint_points": int(constraint.points.shape[0]),
        "penalty_scale": constraint.penalty_scale(),
        "linear_solver": solver.method,
        **timings.as_attrs(),
    }
    diagnostics = {
        "epsilon": eps,
        "epsilon_cell": eps_cell,
        "penalty": lam_used,
        "iterations": iterations,
        "stages": stages,
        "target_reached": reached,
        "wall_time": wall,
    }
    out = tracked_dataset(body, U, phase, diagnostics, settings)
    timings.output = _time.perf_counter() - clock
    out.attrs.update(timings.as_attrs())
    return out
