"""Shared pieces of the activation steps: output attributes, tracked-data checks, statistics."""

from __future__ import annotations

import numpy as np
import xarray as xr

from harpx._typing import FloatArray, IntArray
from harpx.mechanics.body import Body
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


def attrs(name: str) -> dict[str, str]:
    return dict(ATTRS[name])


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
