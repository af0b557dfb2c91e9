"""Re-simulation with estimated activations, compared with tracking element by element.

:func:`resimulate` runs the tracking model forward with the per-muscle estimates
(:func:`harpx.physiology.active.simulate_activation`) and compares simulated and tracked
fibre stretch per element and per muscle (paper Fig. 3c;
:func:`harpx.plotting.plot_stretch_agreement`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from harpx.inverse._common import (
    attrs,
    pearson,
    region_table,
    time_index,
    tracked_u,
    weighted_stats,
)
from harpx.mechanics.body import Body
from harpx.mechanics.fiber_laws import ActiveContraction
from harpx.physiology.active import (
    default_law,
    fibred_body,
    missing_regions,
    region_values,
    simulate_activation,
    with_active_law,
)
from harpx.schema import standard_attrs

__all__ = ["resimulate"]


def resimulate(
    body: Body,
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
        Activation per region, kPa, >= 0 (e.g. ``estimate["t_max"]``); NaN (no estimate)
        counts as 0, with a warning, and is flagged in ``t_max_missing``.
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
        (region) and their values over all regions (``*_all``); ``t_max_missing``
        (region, bool) marks the regions whose level was NaN and that were simulated at
        rest.

    Raises
    ------
    ValueError
        For an unknown region, a negative or infinite level, a body without fibres or a
        ``tracked`` dataset of another model.
    ConvergenceError
        If the forward solve fails.

    Warns
    -----
    HarpxWarning
        If a level is NaN (:func:`harpx.physiology.active.region_values`).
    """
    fibred_body(body)
    law = default_law(body, law)
    missing = missing_regions(t_max_by_region)
    values = region_values(body, t_max_by_region)
    active = with_active_law(body, law)
    loads = [*dirichlet, *terms]
    result = simulate_activation(active, values, loads=loads, steps=steps)
    lam_sim = active.fiber_stretch(result.u)
    names, label = region_table(body)
    w = body.cell_volume
    t_region = np.array([values.get(n, 0.0) for n in names])
    ds = xr.Dataset(
        {
            "fiber_stretch_simulated": ("cell", lam_sim, attrs("fiber_stretch_simulated")),
            "displacement": (("node", "axis"), result.u.reshape(-1, 3), attrs("displacement")),
            "region_label": (
                "cell",
                label,
                attrs("region_label") | {"flag_meanings": " ".join(names)},
            ),
            "t_max": ("region", t_region, attrs("t_max")),
            "t_max_missing": ("region", np.isin(names, missing), attrs("t_max_missing")),
            "cell_volume": ("cell", w, {"units": "mm3", "long_name": "reference cell volume"}),
        },
        coords={
            "region": ("region", names, {"units": "1", "long_name": "muscle region"}),
            "axis": ("axis", ["x", "y", "z"], standard_attrs("axis")),
        },
        attrs={"newton_iterations": int(result.iterations), "solve_time": result.message},
    )
    stats = np.array([weighted_stats(lam_sim[body.regions[n]], w[body.regions[n]]) for n in names])
    ds["stretch_simulated"] = ("region", stats[:, 0], attrs("stretch_simulated"))
    ds["stretch_simulated_sd"] = ("region", stats[:, 1], attrs("stretch_simulated_sd"))
    if tracked is not None:
        index = time_index(tracked, time)
        tracked_u(tracked, body, index)  # checks that tracked belongs to body
        if "fiber_stretch" not in tracked:
            raise ValueError("'tracked' has no 'fiber_stretch'; track a body with fibers")
        lam_tr = np.asarray(tracked["fiber_stretch"].isel(time=index).values, dtype=np.float64)
        ds["fiber_stretch_tracked"] = ("cell", lam_tr, attrs("fiber_stretch_tracked"))
        tstats = np.array(
            [weighted_stats(lam_tr[body.regions[n]], w[body.regions[n]]) for n in names]
        )
        ds["stretch_tracked"] = ("region", tstats[:, 0], attrs("stretch_tracked"))
        ds["stretch_tracked_sd"] = ("region", tstats[:, 1], attrs("stretch_tracked_sd"))
        corr, mad = [], []
        for n in names:  # loop over the few regions
            ids = body.regions[n]
            corr.append(pearson(lam_tr[ids], lam_sim[ids]))
            mad.append(float(np.mean(np.abs(lam_tr[ids] - lam_sim[ids]))))
        ds["correlation"] = ("region", np.array(corr), attrs("correlation"))
        ds["mean_abs_difference"] = ("region", np.array(mad), attrs("mean_abs_difference"))
        cells = np.concatenate([body.regions[n] for n in names])
        ds["correlation_all"] = ((), pearson(lam_tr[cells], lam_sim[cells]), attrs("correlation"))
        ds["mean_abs_difference_all"] = (
            (),
            float(np.mean(np.abs(lam_tr[cells] - lam_sim[cells]))),
            attrs("mean_abs_difference"),
        )
        ds.attrs["time_index"] = index
    return ds
