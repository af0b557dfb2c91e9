r"""Direct estimate of muscle activation from tracked fibre stretch (paper §4.3).

The paper estimates the contractile stress of each tongue muscle *directly* from the
image-derived fibre shortening, by solving the active-contraction law of its reference [1]
for :math:`T_{max}` (the "Eq. 4" the paper cites is that law, not its phase equation),
instead of running an optimisation loop of forward simulations. This module does that, plus two
optional closed-form corrections, as plain functions:

1. :func:`estimate_activation` — the paper's direct estimate: per element, the inversion
   below; per muscle, the median (or volume-weighted mean) of the element values with
   their spread.
2. :func:`correct_activation` — *one* linear equilibrium correction at the tracked
   configuration for the load that neighbouring muscles and attachments carry (a linear
   system of the size of the number of muscles).
3. :func:`calibrate_activation` — *one* per-muscle scaling for the attenuation of the
   measurement chain (imaging, phase filtering, regularised tracking), measured by passing a
   re-simulation with the estimate through the same chain.
4. :func:`resimulate` — a forward simulation of the tracking model with the per-muscle
   estimates, compared with the tracked fibre stretch element by element and per muscle
   (paper Fig. 3c; :func:`plot_stretch_agreement`).

None of them iterates: there is no objective function and no search.

Per-element equation (uniaxial fibre equilibrium)
-------------------------------------------------
The tissue is hyperelastic with an active fibre stress of Guccione--McCulloch type in
second Piola--Kirchhoff form (:class:`harpx.mechanics.materials.ActiveContraction`),

.. math::

    S = S_{iso}(C) + p\,J C^{-1} + T_a f_0 \otimes f_0, \qquad
    T_a = T_{max}\, g(\lambda), \quad \lambda = |F f_0|,

with :math:`g` the length-dependent calcium factor (:math:`g = 1` for the prescribed law).
In Cauchy form, with the deformed unit fibre :math:`\hat a = F f_0/\lambda`,
:math:`\sigma = \sigma_{iso} + p I + (T_a \lambda^2 / J)\, \hat a \otimes \hat a`.

*Assumption:* each element is a muscle segment in **uniaxial stress along its fibre**: no
traction on planes parallel to the fibre (the mean lateral normal stress vanishes) and no
net fibre traction (an unloaded muscle whose active stress is balanced by its own passive
stress). The lateral condition fixes the hydrostatic pressure,
:math:`p = -\sigma^{iso}_{\perp}` with :math:`\sigma^{iso}_{\perp} = \tfrac12(\operatorname{tr}
\sigma_{iso} - \sigma^{iso}_{ff})` and :math:`\sigma^{iso}_{ff} = \hat a \cdot \sigma_{iso}
\hat a`; the fibre condition then gives

.. math::

    T_a = -\frac{J}{\lambda^2}\,\big(\sigma^{iso}_{ff} - \sigma^{iso}_{\perp}\big), \qquad
    T_{max} = \frac{T_a}{g(\lambda)} ,

evaluated from the tracked deformation gradient at every Gauss point (volume-averaged per
cell) and the tracked cell fibre stretch. Only the *deviatoric* passive stress enters,
which the tracked kinematics determine well; the pressure of a nearly incompressible solid
(:math:`\kappa \ln J / J`), which a tracked :math:`J` cannot resolve, drops out. For the
uncoupled neo-Hookean solid in isochoric uniaxial stretch this is
:math:`T_a = 2 C_1 (\lambda^{-3} - 1)`. The result is exact for a homogeneous muscle in
uniaxial stress (tested to 1e-6), for any bulk modulus.

*Limits.* Inside an organ a muscle is not in uniaxial stress: neighbouring muscles and
the attachments (mandible, hyoid) carry part of the active load, and passive tissue
stretched by other muscles has :math:`T_a < 0` by this formula. The element estimates are
therefore biased low where a muscle works against stiff surroundings and scattered near
muscle borders; they become NaN where :math:`g(\lambda) = 0` (calcium law with
:math:`l_r\lambda \le l_0`, any :math:`T_{max}` fits) and ill-conditioned where
:math:`g` is small. The per-muscle median damps the scatter, not the bias.

One linear correction (not an optimisation loop)
------------------------------------------------
In a whole organ the element estimates are biased low (by about half for the tongue
scene: each muscle works against its neighbours and the attachments). :func:`correct_activation`
removes that bias with the model itself, without a search: at the tracked configuration
:math:`u` it takes one Newton step of the forward model with the per-muscle activations
:math:`t` as unknowns, :math:`\delta u = -K^{-1}(R_p(u) + \sum_m t_m B_m(u))`, and requires
that the step leaves every muscle's mean fibre stretch where the images put it,

.. math::

    \sum_m S_{km}\, t_m = -r_k, \qquad S_{km} = -D_k K^{-1} B_m, \qquad r_k = -D_k K^{-1} R_p,

a linear system of the size of the number of muscles (:math:`D_k` = derivative of muscle
:math:`k`'s mean stretch, :math:`R_p` the passive residual, :math:`B_m` the residual of a
unit :math:`T_{max}` in muscle :math:`m`, :math:`K` the tangent at :math:`u` with the direct
estimates). It is exact when the tracked motion is an equilibrium of the model, needs one
factorisation, and propagates tracking errors like any stretch-matching estimate,
:math:`\delta t = -S^{-1}\delta\bar\lambda`.

References
----------
.. [1] Guccione JM, McCulloch AD. Mechanics of active contraction in cardiac muscle:
   Part I. J Biomech Eng 115:72--81, 1993.
.. [2] Maas SA et al. FEBio theory manual, section 5.12 (active contraction).
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.sparse import linalg as spla

from harpx._typing import FloatArray, IntArray
from harpx.errors import ConvergenceError
from harpx.mechanics.assembly import internal_forces
from harpx.mechanics.body import Body
from harpx.mechanics.kinematics import split_growth
from harpx.mechanics.materials import ActiveContraction
from harpx.mechanics.newton import SolveResult, equilibrate
from harpx.schema import standard_attrs

__all__ = [
    "calibrate_activation",
    "correct_activation",
    "estimate_activation",
    "plot_stretch_agreement",
    "resimulate",
    "simulate_activation",
    "simulate_history",
    "uniaxial_active_tension",
]

Aggregate = Literal["median", "mean"]

_ATTRS: dict[str, dict[str, str]] = {
    "t_max_cell": {"units": "kPa", "long_name": "direct T_max estimate per cell"},
    "active_tension_cell": {"units": "kPa", "long_name": "active fiber tension T_a per cell"},
    "fiber_stretch": standard_attrs("fiber_stretch"),
    "t_max": {"units": "kPa", "long_name": "T_max per region"},
    "t_max_direct": {"units": "kPa", "long_name": "direct (uncorrected) T_max per region"},
    "t_max_mean": {"units": "kPa", "long_name": "volume-weighted mean of the cell T_max"},
    "t_max_q25": {"units": "kPa", "long_name": "25th percentile of the cell T_max"},
    "t_max_q75": {"units": "kPa", "long_name": "75th percentile of the cell T_max"},
    "valid_cells": {"units": "1", "long_name": "cells with a finite T_max estimate"},
    "fiber_stretch_simulated": {"units": "1", "long_name": "simulated fiber stretch"},
    "fiber_stretch_tracked": {"units": "1", "long_name": "tracked fiber stretch"},
    "displacement": standard_attrs("displacement"),
    "stretch_simulated": {
        "units": "1",
        "long_name": "volume-weighted mean simulated fiber stretch",
    },
    "stretch_tracked": {"units": "1", "long_name": "volume-weighted mean tracked fiber stretch"},
    "stretch_simulated_sd": {"units": "1", "long_name": "sd of the simulated cell fiber stretch"},
    "stretch_tracked_sd": {"units": "1", "long_name": "sd of the tracked cell fiber stretch"},
    "correlation": {
        "units": "1",
        "long_name": "Pearson correlation of tracked and simulated cell stretch",
    },
    "mean_abs_difference": {
        "units": "1",
        "long_name": "mean |tracked - simulated| cell fiber stretch",
    },
    "stretch_sensitivity": {
        "units": "1/kPa",
        "long_name": "mean stretch change of region per kPa T_max of source_region",
    },
    "stretch_recoil": {
        "units": "1",
        "long_name": "mean stretch change of region with every activation removed",
    },
    "t_max_linear": {"units": "kPa", "long_name": "corrected T_max before clipping at 0"},
    "t_max_uncalibrated": {
        "units": "kPa",
        "long_name": "T_max before the measurement-chain calibration",
    },
    "t_max_calibration_run": {
        "units": "kPa",
        "long_name": "estimate from the measured re-simulation",
    },
    "chain_transfer": {
        "units": "1",
        "long_name": "estimated / simulated T_max through the measurement chain",
    },
    "region_label": {"units": "1", "long_name": "region index of cell (-1: none)"},
}


def _attrs(name: str) -> dict[str, str]:
    return dict(_ATTRS[name])


# --------------------------------------------------------------------------------------
# numpy kernel
# --------------------------------------------------------------------------------------


def uniaxial_active_tension(
    material: Any, F: ArrayLike, fiber: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    r"""Active fibre tension that holds a segment in uniaxial stress along its fibre.

    Parameters
    ----------
    material : object
        Passive uncoupled material with ``isochoric_response(F, fiber)`` (e.g.
        :class:`~harpx.mechanics.materials.NeoHookean`).
    F : array_like, shape (..., 3, 3)
        (Elastic) deformation gradients, dimensionless, ``det F > 0``.
    fiber : array_like, shape (..., 3)
        Unit reference fibre directions, broadcasting against ``F``.

    Returns
    -------
    tension : ndarray, shape (...)
        :math:`T_a = -(J/\lambda^2)(\sigma^{iso}_{ff} - \sigma^{iso}_\perp)` in kPa (second
        Piola--Kirchhoff fibre component; see the module docstring).
    stretch : ndarray, shape (...)
        Fibre stretch :math:`\lambda = |F f_0|` (dimensionless).

    Examples
    --------
    >>> from harpx.inverse.activation import uniaxial_active_tension
    >>> from harpx.mechanics.materials import NeoHookean
    >>> lam = 0.9
    >>> F = np.diag([lam, lam**-0.5, lam**-0.5])
    >>> T, _ = uniaxial_active_tension(NeoHookean(c1=1.0, kappa=120.0), F, [1.0, 0.0, 0.0])
    >>> round(float(T), 12) == round(2.0 * (lam**-3 - 1.0), 12)  # 2 C1 (λ⁻³ - 1)
    True
    """
    F = np.asarray(F, dtype=np.float64)
    f = np.asarray(fiber, dtype=np.float64)
    f = np.broadcast_to(f, F.shape[:-1])
    P, _ = material.isochoric_response(F, f)
    J = np.linalg.det(F)
    sigma = np.matmul(P, np.swapaxes(F, -1, -2)) / J[..., None, None]
    a = np.einsum("...iJ,...J->...i", F, f)
    lam2 = np.einsum("...i,...i->...", a, a)
    s_ff = np.einsum("...i,...ij,...j->...", a, sigma, a) / lam2
    s_lat = 0.5 * (np.trace(sigma, axis1=-2, axis2=-1) - s_ff)
    return -(J / lam2) * (s_ff - s_lat), np.sqrt(lam2)


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------


def _cell_mean(body: Body, q: FloatArray) -> FloatArray:
    """Volume average over each cell of a Gauss-point field (ncell, nqp, ...)."""
    w = body.dV / body.cell_volume[:, None]
    return np.einsum("eq,eq...->e...", w, q)


def _check_body(body: Any) -> None:
    if not isinstance(body, Body):
        raise TypeError(
            f"body must be a harpx.mechanics.Body, got {type(body).__name__!r}; pass the "
            "model that was tracked"
        )
    if body.fibers_qp is None:
        raise ValueError(
            "the body has no fibers; activation needs fibre directions: build it from a "
            "mesh with fibers (e.g. harpx.mechanics.tongue_mesh.tongue) or pass fibers="
        )


def _matching_regions(estimate: xr.Dataset, body: Any) -> list[str]:
    """The body's region names, checked against those of an activation estimate."""
    names = list(body.regions)
    if list(estimate["region"].values) != names:
        raise ValueError(
            f"regions differ: estimate has {list(estimate['region'].values)!r}, the body "
            f"has {names!r}; pass the body the estimate was computed for"
        )
    return names


def _time_index(tracked: xr.Dataset, time: int) -> int:
    n = tracked.sizes.get("time", 0)
    if not isinstance(time, int | np.integer) or not -n <= int(time) < n:
        raise ValueError(
            f"time={time!r} is not an index into the {n} frames of 'tracked'; pass an "
            f"integer in [{-n}, {n - 1}] (default -1, the last frame)"
        )
    return int(time) % n


def _tracked_u(tracked: xr.Dataset, body: Body, index: int) -> FloatArray:
    missing = [v for v in ("displacement", "points") if v not in tracked]
    if missing:
        raise ValueError(
            f"'tracked' lacks {missing!r}; pass the tracked/1 dataset returned by "
            "harpx.tracking.track.track"
        )
    pts = np.asarray(tracked["points"].values, dtype=np.float64)
    if pts.shape != body.dof_points.shape or not np.allclose(pts, body.dof_points, atol=1e-6):
        raise ValueError(
            f"'tracked' has {pts.shape[0]} nodes that do not match the body's "
            f"{body.dof_points.shape[0]} dof nodes; pass the same Body (mesh and element) "
            "that was tracked"
        )
    disp = tracked["displacement"].transpose("time", "node", "axis")
    return np.asarray(disp.isel(time=index).values, dtype=np.float64).reshape(-1)


def _region_table(body: Body) -> tuple[list[str], IntArray]:
    names = list(body.regions)
    label = np.full(body.ncell, -1, dtype=np.int64)
    for code, name in enumerate(names):  # loop over the few named regions
        label[body.regions[name]] = code
    return names, label


def _weighted_stats(values: FloatArray, weights: FloatArray) -> tuple[float, float]:
    ok = np.isfinite(values)
    if not ok.any():
        return float("nan"), float("nan")
    w = weights[ok] / weights[ok].sum()
    mean = float(np.sum(w * values[ok]))
    return mean, float(np.sqrt(np.sum(w * (values[ok] - mean) ** 2)))


def _as_region_values(body: Body, t_max: Any) -> dict[str, float]:
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
        out[str(name)] = 0.0 if not np.isfinite(v) else v
    return out


def _active_copy(body: Body, law: ActiveContraction) -> Body:
    """The same model with an active fibre law (t_max = 0), leaving ``body`` untouched."""
    return Body(
        body.mesh,
        body.material,
        fibers=body.fibers_qp,
        regions=body.regions,
        element=body.element,  # type: ignore[arg-type]
        active=law,
        t_max=0.0,
        growth=body.growth,
        boundaries=body.boundaries,
        volumetric=body.volumetric,  # type: ignore[arg-type]
    )


def _default_law(body: Body, law: ActiveContraction | None) -> ActiveContraction:
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


# --------------------------------------------------------------------------------------
# 1. direct estimate
# --------------------------------------------------------------------------------------


def estimate_activation(
    tracked: xr.Dataset,
    body: Any,
    *,
    time: int = -1,
    law: ActiveContraction | None = None,
    aggregate: Aggregate = "median",
) -> xr.Dataset:
    r"""Direct per-element estimate of :math:`T_{max}` from tracked motion, per muscle.

    Parameters
    ----------
    tracked : xarray.Dataset
        ``tracked/1`` result of :func:`harpx.tracking.track.track` (uses ``points``,
        ``displacement`` and, if present, ``fiber_stretch``).
    body : Body
        The model that was tracked, with fibres and named regions (muscles).
    time : int, default -1
        Index of the frame (along ``time``) to invert, e.g. the activated frame.
    law : ActiveContraction, optional
        Active-contraction law to invert; default ``body.active`` or
        ``ActiveContraction()`` (Guccione--McCulloch calcium law, FEBio defaults).
    aggregate : {"median", "mean"}, default "median"
        Per-region statistic of the cell estimates: median, or volume-weighted mean.

    Returns
    -------
    xarray.Dataset
        ``t_max_cell`` (cell) kPa, NaN where :math:`g(\lambda) = 0`; ``active_tension_cell``
        (cell) kPa; ``fiber_stretch`` (cell); ``region_label`` (cell); per ``region``:
        ``t_max`` (the aggregate), ``t_max_mean``, ``t_max_q25``, ``t_max_q75`` (kPa) and
        ``valid_cells``. attrs record the method, frame and law.

    Raises
    ------
    ValueError
        If ``tracked`` does not belong to ``body``, ``time`` is out of range, the body has
        no fibres or ``aggregate`` is unknown.

    Notes
    -----
    Per element :math:`T_a = -(J/\lambda^2)(\sigma^{iso}_{ff} - \sigma^{iso}_\perp)` (uniaxial
    fibre equilibrium) and :math:`T_{max} = T_a / g(\lambda)`, i.e. the active-contraction
    law solved for :math:`T_{max}` (paper §4.3). Derivation, assumption and limits: module
    docstring.
    """
    _check_body(body)
    if aggregate not in ("median", "mean"):
        raise ValueError(f"aggregate={aggregate!r}; expected 'median' or 'mean'")
    law = _default_law(body, law)
    index = _time_index(tracked, time)
    u = _tracked_u(tracked, body, index)
    F = body.deformation_gradient(u)
    if body.growth_tensor is not None:
        F = split_growth(F, body.growth_tensor)
    T_qp, lam_qp = uniaxial_active_tension(body.material, F, body.fibers_qp)
    T_cell = _cell_mean(body, T_qp)
    if "fiber_stretch" in tracked:
        lam = np.asarray(tracked["fiber_stretch"].isel(time=index).values, dtype=np.float64)
        if lam.shape != (body.ncell,):
            raise ValueError(
                f"tracked 'fiber_stretch' has shape {lam.shape!r}; expected ({body.ncell},) "
                "cells of the body"
            )
    else:
        lam = _cell_mean(body, lam_qp)
    t_cell = np.asarray(law.t_max_for_tension(lam, T_cell), dtype=np.float64)

    names, label = _region_table(body)
    w = body.cell_volume
    agg, mean, q25, q75, count = (np.full(len(names), np.nan) for _ in range(5))
    for k, name in enumerate(names):  # loop over the few regions
        ids = body.regions[name]
        vals = t_cell[ids]
        ok = np.isfinite(vals)
        count[k] = ok.sum()
        if not ok.any():
            continue
        mean[k] = _weighted_stats(vals, w[ids])[0]
        q25[k], agg[k], q75[k] = np.percentile(vals[ok], [25, 50, 75])
        if aggregate == "mean":
            agg[k] = mean[k]
    ds = xr.Dataset(
        {
            "t_max_cell": ("cell", t_cell, _attrs("t_max_cell")),
            "active_tension_cell": ("cell", T_cell, _attrs("active_tension_cell")),
            "fiber_stretch": ("cell", lam, _attrs("fiber_stretch")),
            "region_label": (
                "cell",
                label,
                _attrs("region_label") | {"flag_meanings": " ".join(names)},
            ),
            "t_max": ("region", agg, _attrs("t_max")),
            "t_max_mean": ("region", mean, _attrs("t_max_mean")),
            "t_max_q25": ("region", q25, _attrs("t_max_q25")),
            "t_max_q75": ("region", q75, _attrs("t_max_q75")),
            "valid_cells": ("region", count.astype(np.int64), _attrs("valid_cells")),
        },
        coords={"region": ("region", names, {"units": "1", "long_name": "muscle region"})},
        attrs={
            "method": "direct: uniaxial fibre equilibrium per element",
            "aggregate": aggregate,
            "time_index": index,
            "law": repr(law),
        },
    )
    if "time" in tracked.coords:
        ds.attrs["time"] = float(tracked["time"].values[index])
    return ds


# --------------------------------------------------------------------------------------
# forward simulation
# --------------------------------------------------------------------------------------


def simulate_activation(
    body: Any,
    t_max: Any,
    *,
    loads: Sequence[Any] = (),
    steps: int = 4,
    u0: ArrayLike | None = None,
    t_start: Any = None,
    max_cutbacks: int = 6,
    tol: float = 1e-8,
    linear_solver: str = "auto",
) -> SolveResult:
    """Static equilibrium of an active body, ramping the activation over load steps.

    Parameters
    ----------
    body : Body
        Body with an active law (``body.active``); its ``t_max`` is set to the target.
    t_max : float, dict of str to float, DataArray over ``region`` or array of shape (ncell,)
        Target activation, kPa (per region: other cells 0).
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
        If the body has no active law or ``steps < 1``.
    ConvergenceError
        If an increment fails ``max_cutbacks`` times in a row.
    """
    if getattr(body, "active", None) is None:
        raise ValueError(
            "simulate_activation needs a body with an active law; build it with "
            "Body(..., active=ActiveContraction(...))"
        )
    if int(steps) < 1:
        raise ValueError(f"steps={steps!r} must be >= 1")
    if isinstance(t_max, xr.DataArray):
        t_max = _as_region_values(body, t_max)
    if isinstance(t_start, xr.DataArray):
        t_start = _as_region_values(body, t_start)
    body.set_t_max(0.0 if t_start is None else t_start)
    first = np.array(body.t_max, copy=True)
    body.set_t_max(t_max)
    target = np.array(body.t_max, copy=True)
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
    body.set_t_max(target)
    result.u = u
    result.converged = True
    result.message = f"{_time.perf_counter() - start:.3f} s"
    return result


def _stretch_derivative(body: Body, u: FloatArray, du: FloatArray) -> FloatArray:
    """Cell-averaged ``dλ`` for displacement directions ``du`` (m, ndof) -> (m, ncell)."""
    F = body.deformation_gradient(u)
    f0 = body.fibers_qp
    a = np.einsum("eqiJ,eqJ->eqi", F, f0)
    lam = np.linalg.norm(a, axis=-1)
    out = []
    for d in du:  # loop over the few regions
        dF = body.deformation_gradient(d) - np.eye(3)
        dlam = np.einsum("eqi,eqiJ,eqJ->eq", a, dF, f0) / lam
        out.append(_cell_mean(body, dlam))
    return np.asarray(out)


def resimulate(
    body: Any,
    t_max_by_region: Any,
    *,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    tracked: xr.Dataset | None = None,
    time: int = -1,
    law: ActiveContraction | None = None,
    steps: int = 4,
) -> xr.Dataset:
    r"""Forward-simulate the model with per-muscle activations and compare with tracking.

    Parameters
    ----------
    body : Body
        The tracking model (fibres, regions); it is not modified (an active copy is solved).
    t_max_by_region : dict of str to float or DataArray over ``region``
        Activation per region, kPa (e.g. ``estimate["t_max"]``); NaN counts as 0.
    dirichlet : sequence, optional
        Boundary conditions, e.g. ``[Fixed("mandible"), Fixed("base")]`` — the same as
        for tracking.
    terms : sequence, optional
        Further loads (pressure, body force).
    tracked : xarray.Dataset, optional
        ``tracked/1`` result to compare with, frame ``time``.
    time : int, default -1
        Frame index of ``tracked``.
    law : ActiveContraction, optional
        Active law; default ``body.active`` or ``ActiveContraction()``.
    steps : int, default 4
        Activation increments of the forward solve.

    Returns
    -------
    xarray.Dataset
        ``fiber_stretch_simulated`` (cell), ``displacement`` (node, axis) mm, ``t_max``
        (region) kPa, ``stretch_simulated`` and ``stretch_simulated_sd`` (region,
        volume-weighted over the region's cells); with ``tracked``: also
        ``fiber_stretch_tracked`` (cell), ``stretch_tracked``, ``stretch_tracked_sd``,
        ``correlation`` (Pearson r of the cell stretches), ``mean_abs_difference``
        (region) and their values over all regions (``*_all``).

    Raises
    ------
    ValueError
        For an unknown region, a body without fibres or a ``tracked`` dataset of another
        model.
    ConvergenceError
        If the forward solve fails.
    """
    _check_body(body)
    law = _default_law(body, law)
    values = _as_region_values(body, t_max_by_region)
    active = _active_copy(body, law)
    loads = [*dirichlet, *terms]
    result = simulate_activation(active, values, loads=loads, steps=steps)
    lam_sim = active.fiber_stretch(result.u)
    names, label = _region_table(body)
    w = body.cell_volume
    t_region = np.array([values.get(n, 0.0) for n in names])
    ds = xr.Dataset(
        {
            "fiber_stretch_simulated": ("cell", lam_sim, _attrs("fiber_stretch_simulated")),
            "displacement": (("node", "axis"), result.u.reshape(-1, 3), _attrs("displacement")),
            "region_label": (
                "cell",
                label,
                _attrs("region_label") | {"flag_meanings": " ".join(names)},
            ),
            "t_max": ("region", t_region, _attrs("t_max")),
            "cell_volume": ("cell", w, {"units": "mm3", "long_name": "reference cell volume"}),
        },
        coords={
            "region": ("region", names, {"units": "1", "long_name": "muscle region"}),
            "axis": ("axis", ["x", "y", "z"], standard_attrs("axis")),
        },
        attrs={"newton_iterations": int(result.iterations), "solve_time": result.message},
    )
    stats = np.array([_weighted_stats(lam_sim[body.regions[n]], w[body.regions[n]]) for n in names])
    ds["stretch_simulated"] = ("region", stats[:, 0], _attrs("stretch_simulated"))
    ds["stretch_simulated_sd"] = ("region", stats[:, 1], _attrs("stretch_simulated_sd"))
    if tracked is not None:
        index = _time_index(tracked, time)
        _tracked_u(tracked, body, index)  # checks that tracked belongs to body
        if "fiber_stretch" not in tracked:
            raise ValueError("'tracked' has no 'fiber_stretch'; track a body with fibers")
        lam_tr = np.asarray(tracked["fiber_stretch"].isel(time=index).values, dtype=np.float64)
        ds["fiber_stretch_tracked"] = ("cell", lam_tr, _attrs("fiber_stretch_tracked"))
        tstats = np.array(
            [_weighted_stats(lam_tr[body.regions[n]], w[body.regions[n]]) for n in names]
        )
        ds["stretch_tracked"] = ("region", tstats[:, 0], _attrs("stretch_tracked"))
        ds["stretch_tracked_sd"] = ("region", tstats[:, 1], _attrs("stretch_tracked_sd"))
        corr, mad = [], []
        for n in names:  # loop over the few regions
            ids = body.regions[n]
            corr.append(_pearson(lam_tr[ids], lam_sim[ids]))
            mad.append(float(np.mean(np.abs(lam_tr[ids] - lam_sim[ids]))))
        ds["correlation"] = ("region", np.array(corr), _attrs("correlation"))
        ds["mean_abs_difference"] = ("region", np.array(mad), _attrs("mean_abs_difference"))
        cells = np.concatenate([body.regions[n] for n in names])
        ds["correlation_all"] = ((), _pearson(lam_tr[cells], lam_sim[cells]), _attrs("correlation"))
        ds["mean_abs_difference_all"] = (
            (),
            float(np.mean(np.abs(lam_tr[cells] - lam_sim[cells]))),
            _attrs("mean_abs_difference"),
        )
        ds.attrs["time_index"] = index
    return ds


def _region_means(body: Body, names: list[str], values: FloatArray) -> FloatArray:
    w = body.cell_volume
    return np.array(
        [_weighted_stats(values[body.regions[n]], w[body.regions[n]])[0] for n in names]
    )


def _pearson(a: FloatArray, b: FloatArray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


# --------------------------------------------------------------------------------------
# 3. one linear correction
# --------------------------------------------------------------------------------------


def correct_activation(
    estimate: xr.Dataset,
    tracked: xr.Dataset,
    body: Any,
    *,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    time: int | None = None,
    law: ActiveContraction | None = None,
) -> xr.Dataset:
    r"""Refine a direct activation estimate with one linear equilibrium correction.

    Parameters
    ----------
    estimate : xarray.Dataset
        Output of :func:`estimate_activation` (``t_max`` over ``region``, kPa); its values
        only set the linearisation point.
    tracked : xarray.Dataset
        The ``tracked/1`` result the estimate came from.
    body : Body
        The tracked model (fibres, regions); not modified.
    dirichlet : sequence, optional
        Boundary conditions of the model, e.g. ``[Fixed("mandible"), Fixed("base")]``.
    terms : sequence, optional
        Further loads (pressure, body force) acting in the tracked frame.
    time : int, optional
        Frame index of ``tracked``; default the estimate's ``time_index``.
    law : ActiveContraction, optional
        Active law; default ``body.active`` or ``ActiveContraction()``.

    Returns
    -------
    xarray.Dataset
        ``estimate`` with ``t_max`` (region) replaced by the corrected values (clipped at
        0; unclipped in ``t_max_linear``), the direct values kept in ``t_max_direct``, and
        the linear system: ``stretch_sensitivity`` (region, source_region), 1/kPa, and
        ``stretch_recoil`` (region). attrs ``method`` is updated.

    Raises
    ------
    ValueError
        If ``tracked`` does not belong to ``body`` or the regions differ from the
        estimate's.

    Notes
    -----
    At the tracked configuration :math:`u` take *one* Newton step of the forward model
    with unknown per-muscle activations :math:`t`:
    :math:`\delta u = -K^{-1}\big(R_p(u) + \sum_m t_m B_m(u)\big)`, with :math:`R_p` the
    passive residual, :math:`B_m` the residual of a unit :math:`T_{max}` in muscle
    :math:`m` (the residual is linear in each :math:`T_{max}`) and :math:`K` the consistent
    tangent at :math:`u` (activations of ``estimate``; Dirichlet dofs held). Require that
    the step leaves each muscle's volume-weighted mean fibre stretch :math:`\bar\lambda_k`
    unchanged — the model holds the tracked shortening:

    .. math::

        \sum_m S_{km} t_m = -r_k, \qquad
        S_{km} = -D_k K^{-1} B_m, \quad r_k = -D_k K^{-1} R_p ,

    with :math:`D_k = \partial\bar\lambda_k/\partial u`. :math:`r_k` is the (linearised)
    recoil of muscle :math:`k` if every activation were switched off and :math:`S_{km}`
    the shortening per kPa of muscle :math:`m`. This is one linear solve of size
    (number of muscles), not an optimisation loop; it is exact when the tracked motion is
    an equilibrium of the model (tested), and its error propagation is that of the
    tracked mean stretches, :math:`\delta t = -S^{-1} \delta\bar\lambda`. Equivalently it
    is the virtual-fields method with the adjoint fields of the muscle-mean stretches as
    virtual fields.
    """
    _check_body(body)
    law = _default_law(body, law)
    names = _matching_regions(estimate, body)
    index = _time_index(
        tracked, int(estimate.attrs.get("time_index", -1)) if time is None else time
    )
    u = _tracked_u(tracked, body, index)
    t0 = np.nan_to_num(np.asarray(estimate["t_max"].values, dtype=np.float64))
    active = _active_copy(body, law)
    active.set_t_max(dict(zip(names, t0.tolist(), strict=True)))
    internal = internal_forces(active, u, tangent=True)
    if internal.K is None:
        raise ValueError(
            f"the tracked frame {index} has inverted cells {internal.inverted_cells[:10]!r}; "
            "the activation cannot be corrected there"
        )
    K = internal.K
    R_extra = np.zeros(body.ndof)
    for term in terms:  # the few extra loads
        r_t, K_t = term.residual_tangent(active, u, 1.0)
        R_extra += np.asarray(r_t, dtype=np.float64)
        if K_t is not None:
            K = K + K_t
    active.set_t_max(0.0)
    R_p = internal_forces(active, u, tangent=False).r + R_extra
    rhs = [R_p]
    for name in names:  # residual per unit T_max of each region (linear in T_max)
        active.set_t_max({name: 1.0})
        rhs.append(internal_forces(active, u, tangent=False).r + R_extra - R_p)
    fixed = [np.asarray(d.dofs(body), dtype=np.int64) for d in dirichlet]
    is_fixed = np.zeros(body.ndof, dtype=bool)
    if fixed:
        is_fixed[np.concatenate(fixed)] = True
    free = np.nonzero(~is_fixed)[0]
    K_ff = sparse.csc_matrix(sparse.csr_matrix(K)[free][:, free])
    X = spla.splu(K_ff).solve(np.asarray(rhs)[:, free].T)
    du = np.zeros((len(rhs), body.ndof))
    du[:, free] = -X.T
    dcell = _stretch_derivative(body, u, du)  # (1 + nregion, ncell)
    D = np.array([_region_means(body, names, d) for d in dcell])  # (1 + nregion, nregion)
    recoil, S = D[0], D[1:].T  # S[k, m]: stretch change of region k per kPa in region m
    t1 = np.linalg.lstsq(S, -recoil, rcond=None)[0]
    out = estimate.copy()
    out = out.assign_coords(
        source_region=("source_region", names, {"units": "1", "long_name": "activated region"})
    )
    out["t_max_direct"] = ("region", np.asarray(estimate["t_max"].values), _attrs("t_max_direct"))
    out["t_max_linear"] = ("region", t1, _attrs("t_max_linear"))
    out["t_max"] = ("region", np.maximum(t1, 0.0), _attrs("t_max"))
    out["stretch_sensitivity"] = (("region", "source_region"), S, _attrs("stretch_sensitivity"))
    out["stretch_recoil"] = ("region", recoil, _attrs("stretch_recoil"))
    out.attrs["method"] = (
        "direct (uniaxial fibre equilibrium per element) + one linear equilibrium correction "
        "at the tracked configuration"
    )
    return out


# --------------------------------------------------------------------------------------
# 3. calibration through the measurement chain
# --------------------------------------------------------------------------------------


def simulate_history(
    body: Any,
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
        Final activation per region, kPa.
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
    """
    _check_body(body)
    law = _default_law(body, law)
    values = _as_region_values(body, t_max_by_region)
    if int(frames) < 2:
        raise ValueError(f"frames={frames!r} must be >= 2 (rest and activated)")
    f = np.linspace(0.0, 1.0, int(frames)) if fractions is None else np.asarray(fractions, float)
    if f.shape != (int(frames),) or f[0] != 0.0:
        raise ValueError(
            f"fractions={fractions!r} must hold one activation fraction per frame, 0 first"
        )
    active = _active_copy(body, law)
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


def calibrate_activation(
    estimate: xr.Dataset,
    tracked: xr.Dataset,
    body: Any,
    *,
    measure: Callable[[Any, FloatArray], xr.Dataset],
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    law: ActiveContraction | None = None,
) -> xr.Dataset:
    r"""Undo the measurement chain's attenuation of an activation estimate, per muscle.

    Imaging, harmonic-phase filtering and regularised tracking all smooth the motion, so the
    tracked fibre shortening — and every activation estimate built on it — is smaller than
    the truth (by 20--45 % per muscle in the tongue scene). This step measures that
    attenuation on a motion whose activations are known: the model is run forward with the
    estimate :math:`t` itself, the result is passed through the same chain (``measure``:
    image synthesis, phase extraction and tracking with the same settings), the same
    estimator is applied to it, giving :math:`t^{cal}`, and each muscle's estimate is
    divided by its transfer :math:`r_m = t^{cal}_m / t_m`:

    .. math::

        t^{(2)}_m = t_m / r_m = t_m^2 / t^{cal}_m .

    One forward simulation and one pass through the chain; a closed-form per-muscle
    scaling, not repeated (no optimisation loop).

    Parameters
    ----------
    estimate : xarray.Dataset
        Output of :func:`estimate_activation`, or of :func:`correct_activation` (then the
        calibration run is corrected the same way).
    tracked : xarray.Dataset
        The ``tracked/1`` data the estimate came from (frames and times are reused).
    body : Body
        The tracked model.
    measure : callable
        ``measure(body, U) -> tracked/1``: images the displacement history ``U``
        (ntime, ndof) of ``body`` with the acquisition of the data (same grid, tags,
        slices, SNR) and tracks it with the same settings as the data.
    dirichlet, terms : sequence, optional
        Boundary conditions and loads of the model (as for tracking).
    law : ActiveContraction, optional
        Active law; default ``body.active`` or ``ActiveContraction()``.

    Returns
    -------
    xarray.Dataset
        ``estimate`` with ``t_max`` replaced by the calibrated values, the input values in
        ``t_max_uncalibrated``, the transfer in ``chain_transfer`` (region) and the
        calibration run's estimate in ``t_max_calibration_run``; attrs ``method`` updated
        and ``calibration_epsilon`` (the calibration run's last tracking residual, rad).

    Raises
    ------
    ValueError
        If ``measure`` does not return a tracked dataset of ``body`` with the data's frames.

    Notes
    -----
    Exact if the chain maps activations linearly and without mixing muscles; its
    attenuation is measured at the estimate's own amplitude and pattern, which keeps the
    error of that assumption small when the estimate is close (e.g. after
    :func:`correct_activation`). A muscle whose transfer is not positive keeps its input.
    """
    _check_body(body)
    law = _default_law(body, law)
    names = _matching_regions(estimate, body)
    index = int(estimate.attrs.get("time_index", tracked.sizes["time"] - 1))
    t1 = np.nan_to_num(np.asarray(estimate["t_max"].values, dtype=np.float64))
    frames = int(tracked.sizes["time"])
    U = simulate_history(
        body,
        dict(zip(names, t1.tolist(), strict=True)),
        frames,
        dirichlet=dirichlet,
        terms=terms,
        law=law,
    )
    observed = measure(body, U)
    if not isinstance(observed, xr.Dataset) or observed.sizes.get("time") != frames:
        raise ValueError(
            f"measure(body, U) must return a tracked/1 dataset with the data's {frames} "
            "frames (image U with the data's acquisition and track it like the data)"
        )
    run = estimate_activation(
        observed, body, time=index, law=law, aggregate=estimate.attrs.get("aggregate", "median")
    )
    corrected = "t_max_direct" in estimate
    if corrected:
        run = correct_activation(run, observed, body, dirichlet=dirichlet, terms=terms, law=law)
    t_cal = np.asarray(run["t_max"].values, dtype=np.float64)
    transfer = np.full_like(t1, np.nan)
    np.divide(t_cal, t1, out=transfer, where=t1 > 0)
    ok = np.isfinite(transfer) & (transfer > 0)
    t2 = np.where(ok, t1 / np.where(ok, transfer, 1.0), t1)
    out = estimate.copy()
    out["t_max_uncalibrated"] = ("region", t1, _attrs("t_max_uncalibrated"))
    out["t_max_calibration_run"] = ("region", t_cal, _attrs("t_max_calibration_run"))
    out["chain_transfer"] = ("region", transfer, _attrs("chain_transfer"))
    out["t_max"] = ("region", t2, _attrs("t_max"))
    out.attrs["method"] = str(estimate.attrs.get("method", "direct")) + (
        " + calibration of the measurement chain with one re-simulation"
    )
    if "epsilon" in observed:
        out.attrs["calibration_epsilon"] = float(observed["epsilon"].values[-1])
    return out


# --------------------------------------------------------------------------------------
# figure (paper Fig. 3c)
# --------------------------------------------------------------------------------------


def plot_stretch_agreement(
    comparison: xr.Dataset,
    *,
    path: str | Path | None = None,
    truth: Mapping[str, float] | None = None,
) -> Any:
    """Tracked against simulated fibre stretch per muscle and per element (paper Fig. 3c).

    Parameters
    ----------
    comparison : xarray.Dataset
        Output of :func:`resimulate` with ``tracked=``.
    path : str or Path, optional
        Save the figure there (PNG, 150 dpi).
    truth : dict of str to float, optional
        True mean fibre stretch per region, drawn as a third bar.

    Returns
    -------
    matplotlib.figure.Figure
        Left: bars of the volume-weighted mean fibre strain λ − 1 per muscle in % (error
        bars: sd over the muscle's cells); right: element-by-element scatter of the stretch
        with the identity line.

    Raises
    ------
    ValueError
        If ``comparison`` has no tracked stretch.
    """
    if "stretch_tracked" not in comparison:
        raise ValueError(
            "'comparison' has no tracked stretch; run resimulate(..., tracked=tracked)"
        )
    from matplotlib.figure import Figure

    names = [str(n) for n in comparison["region"].values]
    fig = Figure(figsize=(10.0, 4.0), layout="constrained")
    ax, ax2 = fig.subplots(1, 2)
    x = np.arange(len(names))
    bars = [
        (
            "tracked (images)",
            comparison["stretch_tracked"].values,
            comparison["stretch_tracked_sd"].values,
        ),
        (
            "simulated (estimate)",
            comparison["stretch_simulated"].values,
            comparison["stretch_simulated_sd"].values,
        ),
    ]
    if truth:
        bars.append(("ground truth", np.array([truth.get(n, np.nan) for n in names]), None))
    width = 0.8 / len(bars)
    for k, (label, mean, sd) in enumerate(bars):  # two or three bar groups
        ax.bar(
            x + width * (k - (len(bars) - 1) / 2),
            100.0 * (mean - 1.0),
            width,
            yerr=None if sd is None else 100.0 * sd,
            capsize=3,
            label=label,
        )
    ax.axhline(0.0, color="0.3", lw=0.8)
    ax.set_xticks(x, names)
    ax.set_ylabel("mean fibre strain λ − 1 (%)")
    ax.set_title("fibre stretch per muscle")
    ax.legend(fontsize=8, loc="lower right")
    label = comparison["region_label"].values
    tr = comparison["fiber_stretch_tracked"].values
    sim = comparison["fiber_stretch_simulated"].values
    for k, n in enumerate(names):  # one colour per muscle
        sel = label == k
        ax2.scatter(tr[sel], sim[sel], s=8, label=n)
    both = np.concatenate([tr, sim])
    lim = (float(np.nanmin(both)) - 0.01, float(np.nanmax(both)) + 0.01)
    ax2.plot(lim, lim, color="0.3", lw=0.8)
    ax2.set_xlim(lim)
    ax2.set_ylim(lim)
    ax2.set_xlabel("tracked fibre stretch")
    ax2.set_ylabel("simulated fibre stretch")
    r = float(comparison["correlation_all"]) if "correlation_all" in comparison else np.nan
    ax2.set_title(f"per element (r = {r:.2f})")
    ax2.legend(fontsize=8, markerscale=2)
    if path is not None:
        fig.savefig(Path(path), dpi=150)
    return fig
