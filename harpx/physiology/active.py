"""Forward simulation of active bodies: activation ramps and activation histories.

:func:`simulate_activation` solves the static equilibrium of a body with an active fibre
law (:class:`~harpx.mechanics.fiber_laws.ActiveContraction`) at a target activation,
ramping it over load steps with cut-back; :func:`simulate_history` runs an activation that
rises over frames, each frame continuing the last. The helpers turn per-region activations
into the body's per-cell levels (:func:`region_values`) and make an active copy of a
passive model (:func:`with_active_law`) without touching it.
"""

from __future__ import annotations

import time as _time
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx._typing import FloatArray
from harpx.errors import ConvergenceError, HarpxWarning, user_stacklevel
from harpx.mechanics.body import Body
from harpx.mechanics.fiber_laws import ActiveContraction
from harpx.mechanics.newton import SolveResult, equilibrate

__all__ = [
    "default_law",
    "fibred_body",
    "NEGATIVE_TOLERANCE",
    "missing_regions",
    "region_values",
    "simulate_activation",
    "simulate_history",
    "with_active_law",
]


#: Activation levels (kPa) between minus this and 0 are the round-off of a resting muscle's
#: estimate (the uniaxial closed form at a stretch of 1 to the solver's tolerance): taken
#: as 0, neither refused nor warned about as negative
NEGATIVE_TOLERANCE = 1e-6


def fibred_body(body: object) -> Body:
    """``body`` itself, checked to be a :class:`~harpx.mechanics.body.Body` with fibres.

    Parameters
    ----------
    body : object
        The model to check.

    Returns
    -------
    Body
        ``body``, unchanged.

    Raises
    ------
    TypeError
        If ``body`` is not a Body.
    ValueError
        If it has no fibres (activation acts along them).
    """
    if not isinstance(body, Body):
        raise TypeError(
            f"body must be a harpx.mechanics.Body, got {type(body).__name__!r}; pass the "
            "model that was tracked"
        )
    if body.fibers_qp is None:
        raise ValueError(
            "the body has no fibers; activation needs fibre directions: build it from a "
            "mesh with fibers (e.g. harpx.anatomy.tongue_mesh.tongue) or pass fibers="
        )
    return body


def region_values(body: Body, t_max: Any) -> dict[str, float]:
    """Activation per region (kPa) from a dict or a DataArray over ``region``; NaN -> 0, warned.

    NaN stands for a region without an estimate (no data, or fibres shortened past the active
    law's range); it becomes 0 (the region at rest) with a
    :class:`~harpx.errors.HarpxWarning` that names it. A negative or infinite level is
    refused: a negative activation would lengthen the muscle actively.

    Parameters
    ----------
    body : Body
        The model whose regions (``body.regions``) the names must be.
    t_max : dict of str to float or xarray.DataArray over ``region``
        Activation per region, kPa (e.g. ``estimate["t_max"]`` of the activation estimate).

    Returns
    -------
    dict of str to float
        Activation per named region, kPa; NaN becomes 0.

    Raises
    ------
    ValueError
        For a region the body does not have, a negative or infinite level, or a DataArray
        with other dims.
    TypeError
        For any other kind of ``t_max``.

    Warns
    -----
    HarpxWarning
        If a level is NaN (the region is simulated at rest); :func:`missing_regions` lists
        them.
    """
    if isinstance(t_max, xr.DataArray):
        if t_max.dims != ("region",):
            raise ValueError(
                f"t_max has dims {t_max.dims!r}; expected ('region',) as in the "
                "estimate_activation output (e.g. estimate['t_max'])"
            )
        t_max = dict(zip(t_max["region"].values.tolist(), t_max.values.tolist(), strict=True))
    if not isinstance(t_max, Mapping):
        raise TypeError(
            f"t_max must be a dict region -> kPa or a DataArray over 'region', got "
            f"{type(t_max).__name__!r}"
        )
    out = {}
    for name, value in t_max.items():
        if name not in body.regions:
            raise ValueError(
                f"t_max names region {name!r}, which is not one of {sorted(body.regions)!r}"
            )
        v = float(value)
        if np.isinf(v):
            raise ValueError(f"t_max of region {name!r} is {v!r} kPa; expected a finite level")
        if v < -NEGATIVE_TOLERANCE:
            raise ValueError(
                f"t_max of region {name!r} is {v!r} kPa; an activation must be >= 0 (a "
                "negative one would lengthen the muscle actively). A negative estimate "
                "means lengthened or passively shortened fibres: pass 0 for that region, "
                "or correct the estimate (harpx.inverse.correct_activation)"
            )
        out[str(name)] = 0.0 if np.isnan(v) else max(v, 0.0)  # round-off of rest: 0
    missing = missing_regions(t_max)
    if missing:
        warnings.warn(
            f"t_max is NaN (no estimate) for region(s) {missing!r}; they are simulated at "
            "rest (0 kPa). An estimate is NaN where the region has no data or its fibres "
            "are shortened past the active law's range (see the estimate's "
            "'out_of_range_cells'); pass a level for them to simulate them activated",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return out


def missing_regions(t_max: Any) -> list[str]:
    """Names of the regions whose level in ``t_max`` is NaN (no estimate).

    Parameters
    ----------
    t_max : dict of str to float or xarray.DataArray over ``region``
        Activation per region, kPa.

    Returns
    -------
    list of str
        The regions with a NaN level, in the order of ``t_max``; empty for other kinds.
    """
    if isinstance(t_max, xr.DataArray) and t_max.dims == ("region",):
        t_max = dict(zip(t_max["region"].values.tolist(), t_max.values.tolist(), strict=True))
    if not isinstance(t_max, Mapping):
        return []
    return [str(k) for k, v in t_max.items() if np.isnan(float(v))]


def with_active_law(body: Body, law: ActiveContraction) -> Body:
    """The same model with an active fibre law (t_max = 0), leaving ``body`` untouched.

    Parameters
    ----------
    body : Body
        The model: its mesh, material, fibres, regions, element, growth, boundaries and
        volumetric setting are carried over.
    law : ActiveContraction
        Active fibre law of the copy.

    Returns
    -------
    Body
        A new body with ``active=law`` and ``t_max = 0`` (kPa) in every cell.
    """
    return Body(
        body.mesh, body.material, fibers=body.fibers_qp, regions=body.regions,
        element=body.element, active=law, t_max=0.0, growth=body.growth,
        boundaries=body.boundaries, volumetric=body.volumetric,
    )  # fmt: skip


def default_law(body: Body, law: ActiveContraction | None) -> ActiveContraction:
    """``law``, else the body's active law, else ``ActiveContraction()``; checked.

    Parameters
    ----------
    body : Body
        The model whose ``active`` law is the fallback.
    law : ActiveContraction or None
        The law asked for; None to take the body's (or the default law).

    Returns
    -------
    ActiveContraction
        The chosen law (an object with ``t_max_for_tension`` and ``activation_factor``).

    Raises
    ------
    TypeError
        If the chosen law lacks ``t_max_for_tension`` or ``activation_factor``.
    """
    law = (
        law
        if law is not None
        else (body.active if body.active is not None else ActiveContraction())
    )
    if not hasattr(law, "t_max_for_tension") or not hasattr(law, "activation_factor"):
        raise TypeError(
            f"law must be an ActiveContraction-like law with t_max_for_tension and "
            f"activation_factor, got {type(law).__name__!r}"
        )
    return law


def simulate_activation(
    body: Body,
    t_max: Any,
    *,
    loads: Sequence[Any] = (),
    steps: int = 4,
    u0: ArrayLike | None = None,
    t_start: Any = None,
    max_cutbacks: int = 6,
    min_step: float = 1e-6,
    tol: float = 1e-8,
    linear_solver: str = "auto",
) -> SolveResult:
    """Static equilibrium of an active body, ramping the activation over load steps.

    Parameters
    ----------
    body : Body
        Body with an active law (``body.active``); its ``t_max`` is set to the target.
    t_max : float, dict of str to float, DataArray over ``region`` or array of shape (ncell,)
        Target activation, kPa, >= 0 (per region: other cells 0).
    loads : sequence, optional
        Dirichlet conditions and residual terms (ramped with the same factor).
    steps : int, default 4
        Equal activation increments.
    u0 : array_like, shape (ndof,), optional
        Equilibrium displacement (mm) at ``t_start`` to continue from; default zeros.
    t_start : same kinds as ``t_max``, optional
        Activation of ``u0``, kPa; default 0 (rest).
    max_cutbacks : int, default 6
        Consecutive halvings of a failing increment before giving up.
    min_step : float, default 1e-6
        Smallest activation increment (fraction of the ramp from ``t_start`` to ``t_max``)
        before giving up: increments that alternately converge and fail shrink towards a
        limit point of the ramp, past which no equilibrium exists.
    tol : float, default 1e-8
        Relative Newton tolerance (see :func:`harpx.mechanics.newton.solve`).
    linear_solver : str, default "auto"
        See :mod:`harpx.mechanics.linsolve`.

    Returns
    -------
    SolveResult
        Converged displacement (mm) and iteration counts.

    Raises
    ------
    ValueError
        If the body has no active law, ``steps < 1``, ``min_step`` is not in (0, 1), or an
        activation (``t_max`` or ``t_start``) is negative or not finite.
    ConvergenceError
        If an increment fails ``max_cutbacks`` times in a row, or the increment falls below
        ``min_step`` (the message names the fraction of the target reached).
    """
    if getattr(body, "active", None) is None:
        raise ValueError(
            "simulate_activation needs a body with an active law; build it with "
            "Body(..., active=ActiveContraction(...))"
        )
    if int(steps) < 1:
        raise ValueError(f"steps={steps!r} must be >= 1")
    if not 0.0 < float(min_step) < 1.0:
        raise ValueError(f"min_step={min_step!r} must lie in (0, 1) (a fraction of the ramp)")
    if isinstance(t_max, xr.DataArray):
        t_max = region_values(body, t_max)
    if isinstance(t_start, xr.DataArray):
        t_start = region_values(body, t_start)
    body.set_t_max(0.0 if t_start is None else t_start)
    first = np.array(body.t_max, copy=True)
    body.set_t_max(t_max)
    target = np.array(body.t_max, copy=True)
    for what, level in (("t_start", first), ("t_max", target)):
        bad = ~(np.isfinite(level) & (level >= 0.0))
        if bad.any():
            raise ValueError(
                f"{what} is {float(level[bad][0])!r} kPa in {int(bad.sum())} cell(s) (e.g. cell "
                f"{int(np.flatnonzero(bad)[0])}); an activation must be finite and >= 0 (a "
                "negative one would lengthen the muscle actively)"
            )
    start = _time.perf_counter()
    u = np.zeros(body.ndof) if u0 is None else np.array(u0, dtype=np.float64, copy=True)
    if u.shape != (body.ndof,):
        raise ValueError(f"u0 has shape {u.shape!r}; expected ({body.ndof},) dofs")
    nominal = 1.0 / int(steps)
    ds, done, failures = nominal, 0.0, 0
    result = SolveResult(u=u, converged=False)
    while done < 1.0 - 1e-12:  # loop over activation increments
        s = min(1.0, done + ds)
        body.set_t_max(first + s * (target - first))
        step = equilibrate(
            body, loads, u, s, tol=tol, linear_solver=linear_solver, raise_on_failure=False
        )
        result.iterations += step.iterations
        result.time_assembly += step.time_assembly
        result.time_solve += step.time_solve
        if step.converged:
            u = step.u
            done = s
            failures = 0
            result.step_iterations.extend(step.step_iterations)
            result.residual_history.extend(step.residual_history)
            result.load_factors.append(s)
            result.min_jacobian = step.min_jacobian
            ds = min(2.0 * ds, nominal)
            continue
        failures += 1
        result.cutbacks += 1
        if failures > max_cutbacks:
            body.set_t_max(target)
            raise ConvergenceError(
                f"activation ramp failed at factor {s:.4g} after {max_cutbacks} cut-backs "
                f"({step.message}); use more steps or a smaller t_max",
                step.residual_history[-1] if step.residual_history else [],
            )
        ds *= 0.5
        if ds < min_step:
            body.set_t_max(target)
            raise ConvergenceError(
                f"activation ramp stalled at factor {done:.6g} of the target (increment "
                f"{ds:.2g} < min_step={min_step!r}; {step.message}): no equilibrium was found "
                "past it, so the target lies beyond a limit point of the ramp (the loads or "
                "the activation exceed what the body can carry); use a smaller t_max or "
                "check the loads",
                step.residual_history[-1] if step.residual_history else [],
            )
    body.set_t_max(target)
    result.u = u
    result.converged = True
    result.message = f"{_time.perf_counter() - start:.3f} s"
    return result


def simulate_history(
    body: Body,
    t_max_by_region: Any,
    frames: int,
    *,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    law: ActiveContraction | None = None,
    fractions: ArrayLike | None = None,
) -> FloatArray:
    """Displacement history of the model under an activation that rises over the frames.

    Parameters
    ----------
    body : Body
        The model (not modified; an active copy is solved).
    t_max_by_region : dict of str to float or DataArray over ``region``
        Final activation per region, kPa, >= 0.
    frames : int
        Number of frames (frame 0 at rest).
    dirichlet, terms : sequence, optional
        Boundary conditions and further loads.
    law : ActiveContraction, optional
        Active law; default ``body.active`` or ``ActiveContraction()``.
    fractions : array_like of shape (frames,), optional
        Activation fraction of each frame (0 at frame 0, 1 at the last); default linear.

    Returns
    -------
    ndarray, shape (frames, ndof)
        Displacement per frame, mm; each frame continues from the previous one.

    Raises
    ------
    ValueError
        If ``frames`` is below 2, ``fractions`` is not one fraction per frame starting at 0,
        or a level is negative, infinite or of an unknown region (:func:`region_values`).

    Warns
    -----
    HarpxWarning
        If a level is NaN (the region stays at rest; :func:`region_values`).
    """
    fibred_body(body)
    law = default_law(body, law)
    values = region_values(body, t_max_by_region)
    if int(frames) < 2:
        raise ValueError(f"frames={frames!r} must be >= 2 (rest and activated)")
    f = np.linspace(0.0, 1.0, int(frames)) if fractions is None else np.asarray(fractions, float)
    if f.shape != (int(frames),) or f[0] != 0.0:
        raise ValueError(
            f"fractions={fractions!r} must hold one activation fraction per frame, 0 first"
        )
    active = with_active_law(body, law)
    loads = [*dirichlet, *terms]
    U = np.zeros((int(frames), body.ndof))
    for n in range(1, int(frames)):  # loop over frames, each continuing the last
        U[n] = simulate_activation(
            active,
            {k: f[n] * v for k, v in values.items()},
            loads=loads,
            steps=1,
            u0=U[n - 1],
            t_start={k: f[n - 1] * v for k, v in values.items()},
        ).u
    return U
