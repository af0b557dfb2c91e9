"""Shared pieces of the activation steps: output attributes, tracked-data checks, statistics."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import BoolArray, FloatArray, IntArray
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.mechanics.body import Body
from harpx.physiology.active import NEGATIVE_TOLERANCE
from harpx.schema import standard_attrs

ATTRS: dict[str, dict[str, str]] = {
    "t_max_cell": {"units": "kPa", "long_name": "direct T_max estimate per cell"},
    "active_tension_cell": {"units": "kPa", "long_name": "active fiber tension T_a per cell"},
    "fiber_stretch": standard_attrs("fiber_stretch"),
    "t_max": {"units": "kPa", "long_name": "T_max per region"},
    "t_max_direct": {"units": "kPa", "long_name": "direct (uncorrected) T_max per region"},
    "t_max_mean": {"units": "kPa", "long_name": "volume-weighted mean of the cell T_max"},
    "t_max_q25": {"units": "kPa", "long_name": "25th percentile of the cell T_max"},
    "t_max_q75": {"units": "kPa", "long_name": "75th percentile of the cell T_max"},
    "valid_cells": {"units": "1", "long_name": "cells with a finite T_max estimate"},
    "negative_cells": {
        "units": "1",
        "long_name": "cells with a negative T_max estimate (fibres lengthened or passively "
        "shortened)",
    },
    "out_of_range_cells": {
        "units": "1",
        "long_name": "cells whose fibres are shortened past the law's active range (g = 0): "
        "no estimate",
    },
    "t_max_undetermined": {
        "units": "1",
        "long_name": "the tracked stretches do not determine T_max of the region (NaN)",
    },
    "t_max_missing": {
        "units": "1",
        "long_name": "T_max was NaN (no estimate): the region was simulated at rest",
    },
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


#: attrs of an estimate's ``fiber_stretch``: the stretch the law was evaluated at
STRETCH_NOTE = {"comment": "elastic fibre stretch |Fe f0| (growth divided out), as in the law"}


def attrs(name: str) -> dict[str, str]:
    return dict(ATTRS[name])


def region_statistics(
    body: Body, names: list[str], t_cell: FloatArray, out_of_range: BoolArray, aggregate: str
) -> dict[str, FloatArray | IntArray]:
    """Per-region aggregate, mean, quartiles and cell counts of the cell estimates (kPa)."""
    w = body.cell_volume
    agg, mean, q25, q75 = (np.full(len(names), np.nan) for _ in range(4))
    valid, negative, beyond = (np.zeros(len(names), dtype=np.int64) for _ in range(3))
    for k, name in enumerate(names):  # loop over the few regions
        ids = body.regions[name]
        vals = t_cell[ids]
        ok = np.isfinite(vals)
        valid[k], beyond[k] = ok.sum(), out_of_range[ids].sum()
        negative[k] = np.count_nonzero(vals[ok] < -NEGATIVE_TOLERANCE)
        if not ok.any():
            continue
        mean[k] = weighted_stats(vals, w[ids])[0]
        q25[k], agg[k], q75[k] = np.percentile(vals[ok], [25, 50, 75])
        if aggregate == "mean":
            agg[k] = mean[k]
    return {
        "t_max": agg,
        "t_max_mean": mean,
        "t_max_q25": q25,
        "t_max_q75": q75,
        "valid_cells": valid,
        "negative_cells": negative,
        "out_of_range_cells": beyond,
    }


def warn_doubtful_regions(estimate: xr.Dataset, body: Body, law: Any) -> None:
    """Warn about regions whose estimate is negative or NaN, naming them and the cause."""
    names = [str(n) for n in estimate["region"].values]
    t = np.asarray(estimate["t_max"].values, dtype=np.float64)
    negative = {
        n: round(float(v), 4) for n, v in zip(names, t, strict=True) if v < -NEGATIVE_TOLERANCE
    }
    if negative:
        warnings.warn(
            f"the activation estimate is negative in region(s) {negative!r} (kPa): their "
            "fibres are lengthened, or shortened less than their passive stress needs (e.g. "
            "squeezed from the side), so they are not actively contracting as the uniaxial "
            "estimate assumes; 'negative_cells' counts such cells per region. A negative "
            "level cannot be simulated (region_values refuses it): correct the estimate "
            "(correct_activation) or treat these regions as passive",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    missing = [k for k, v in enumerate(t) if np.isnan(v)]
    if not missing:
        return
    beyond = estimate["out_of_range_cells"].values
    limit = ""
    if getattr(law, "law", None) == "calcium":
        limit = f", fibre stretch <= l0/lr = {law.l0 / law.lr:.4g}"
    causes = []
    for k in missing:  # loop over the few regions without an estimate
        n = int(np.asarray(body.regions[names[k]]).size)
        if n == 0:
            why = "no cells"
        elif int(beyond[k]) == n:
            why = f"fibres shortened past the law's active range in all {n} cells"
        else:
            why = (
                f"{int(beyond[k])} of {n} cells shortened past the law's active range, "
                f"{n - int(beyond[k])} without data (NaN stretch or tension)"
            )
        causes.append(f"{names[k]!r}: {why}")
    warnings.warn(
        f"no activation estimate (NaN) for region(s) {'; '.join(causes)}. Past the law's "
        f"active range (g(lambda) = 0{limit}) the law has no active tension, so no T_max "
        "fits the stretch: it is not 'no activation' - the most contracted muscle lands "
        "there. Simulating such a region needs a level (region_values would use 0 kPa, "
        "with a warning); 'out_of_range_cells' counts the cells per region",
        HarpxWarning,
        stacklevel=user_stacklevel(),
    )


def matching_regions(estimate: xr.Dataset, body: Body) -> list[str]:
    """The body's region names, checked against those of an activation estimate."""
    names = list(body.regions)
    if list(estimate["region"].values) != names:
        raise ValueError(
            f"regions differ: estimate has {list(estimate['region'].values)!r}, the body "
            f"has {names!r}; pass the body the estimate was computed for"
        )
    return names


def time_index(tracked: xr.Dataset, time: int) -> int:
    n = tracked.sizes.get("time", 0)
    if not isinstance(time, int | np.integer) or not -n <= int(time) < n:
        raise ValueError(
            f"time={time!r} is not an index into the {n} frames of 'tracked'; pass an "
            f"integer in [{-n}, {n - 1}] (default -1, the last frame)"
        )
    return int(time) % n


def tracked_u(tracked: xr.Dataset, body: Body, index: int) -> FloatArray:
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


def region_table(body: Body) -> tuple[list[str], IntArray]:
    names = list(body.regions)
    label = np.full(body.ncell, -1, dtype=np.int64)
    for code, name in enumerate(names):  # loop over the few named regions
        label[body.regions[name]] = code
    return names, label


def weighted_stats(values: FloatArray, weights: FloatArray) -> tuple[float, float]:
    ok = np.isfinite(values)
    if not ok.any():
        return float("nan"), float("nan")
    w = weights[ok] / weights[ok].sum()
    mean = float(np.sum(w * values[ok]))
    return mean, float(np.sqrt(np.sum(w * (values[ok] - mean) ** 2)))


def region_means(body: Body, names: list[str], values: FloatArray) -> FloatArray:
    w = body.cell_volume
    return np.array([weighted_stats(values[body.regions[n]], w[body.regions[n]])[0] for n in names])


def pearson(a: FloatArray, b: FloatArray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])
