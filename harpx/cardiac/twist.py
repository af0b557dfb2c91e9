"""Rotation of the short-axis levels, twist and torsion (:func:`harpx.cardiac.strain.lv_measures`).

A level (basal: AHA 1–6, apical: 13–16) is measured on the points of its segments that
have data (coverage at least ``min_coverage``, as a segment value needs), and only when
those fill at least ``min_coverage`` of the level's template volume: a level imaged in a
sliver would otherwise give a rotation, and a twist, that look measured.

Units: mm, mm³, degrees.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from harpx._typing import BoolArray, FloatArray, IntArray
from harpx.errors import HarpxWarning, user_stacklevel

__all__: list[str] = []

#: the AHA segments of each short-axis level
LEVEL_SEGMENTS = {"base": np.arange(1, 7), "apex": np.arange(13, 17)}


def _levels(
    segment: IntArray,
    data: BoolArray,
    has: BoolArray,
    volume: FloatArray,
    template_volume: FloatArray,
    min_coverage: float,
) -> tuple[dict[str, BoolArray], FloatArray, BoolArray]:
    """Points of each level (in its segments with data), the level's coverage (volume of
    those segments' points with data over the level's template volume) and whether it
    reaches ``min_coverage``; a level below it has no points."""
    masks, coverage = {}, np.zeros(len(LEVEL_SEGMENTS))
    for k, (name, segs) in enumerate(LEVEL_SEGMENTS.items()):  # two levels
        kept = segs[has[segs - 1]]
        masks[name] = np.isin(segment, kept) & data
        coverage[k] = volume[kept - 1].sum() / template_volume[segs - 1].sum()
    ok = (coverage >= min_coverage) & np.array([m.any() for m in masks.values()])
    return {n: m & ok[k] for k, (n, m) in enumerate(masks.items())}, coverage, ok


def _rotation(q0: FloatArray, current: FloatArray, template: Any) -> FloatArray:
    """Cardiac rotation (degrees, counter-clockwise seen from the apex), (time, n)."""
    q = np.stack([template.to_local(c) for c in current])  # a few frames
    cross = q0[None, :, 0] * q[..., 1] - q0[None, :, 1] * q[..., 0]
    dot = q0[None, :, 0] * q[..., 0] + q0[None, :, 1] * q[..., 1]
    return -np.rad2deg(np.arctan2(cross, dot))


def _level_rotation(
    q0: FloatArray,
    current: FloatArray,
    template: Any,
    levels: dict[str, BoolArray],
    w: FloatArray,
    seen: FloatArray,
) -> tuple[FloatArray, float, FloatArray]:
    """Rotation (time, level) of each short-axis level's points (degrees, volume-weighted),
    the distance between the levels along the axis (mm), and per level the smallest
    fraction of the in-plane directions the tags see (NaN for a level without points)."""

    def level_mean(values: FloatArray, m: BoolArray) -> FloatArray:
        """Volume-weighted mean over the points ``m`` along the last axis (NaN if none)."""
        if not m.any():
            return np.full(values.shape[:-1], np.nan)
        return np.asarray((values[..., m] * w[m]).sum(axis=-1) / w[m].sum())

    rot = _rotation(q0, current, template)
    level_rot = np.stack([level_mean(rot, m) for m in levels.values()], axis=1)
    height = [float(level_mean(q0[:, 2], m)) for m in levels.values()]
    # rotation needs the in-plane motion and which material sits in the plane (longitudinal)
    level_seen = np.array([np.min(level_mean(seen[:, 1:].T, m)) for m in levels.values()])
    return level_rot, height[0] - height[1], level_seen


def _warn_levels(coverage: FloatArray, ok: BoolArray, min_coverage: float) -> str:
    """Warn about levels without enough data (their rotation, twist and torsion are NaN);
    their names, space-separated ("" when none)."""
    names = [n for n, good in zip(LEVEL_SEGMENTS, ok, strict=True) if not good]
    if names:
        named = ", ".join(
            f"{n} (AHA {LEVEL_SEGMENTS[n][0]}-{LEVEL_SEGMENTS[n][-1]}: {c:.3f})"
            for n, c, good in zip(LEVEL_SEGMENTS, coverage, ok, strict=True)
            if not good
        )
        one = len(names) == 1
        warnings.warn(
            f"twist and torsion are NaN: too little image data at the {named} "
            f"level{'' if one else 's'} (level coverage, the fraction of the level's template "
            f"volume in its segments with data, below min_coverage {min_coverage:g}), so "
            f"{'its rotation is' if one else 'their rotations are'} NaN too (coordinate "
            "'level_coverage', attrs['levels_without_data'], source 'no data'); image "
            f"{'that level' if one else 'those levels'} (e.g. short-axis slices out to the "
            "apex and the base) to measure twist",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return " ".join(names)
