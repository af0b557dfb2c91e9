"""Frames that ``tracking_error`` leaves out of its statistics are named, never silent.

A uniform displacement along x on a 2 x 3 x 4 grid (every voxel in the body) with a known
error per frame, so every statistic is a closed form:

* a failed frame (tracked displacement NaN everywhere) would otherwise drop out of
  ``mean_all`` and make the result look better than one that tracked every frame;
* truth frames that were not tracked, and tracked frames the truth lacks, are left out too.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.errors import HarpxWarning
from harpx.tracking.results import tracking_error

GRID = {"z": [0.0, 2.0], "y": [0.0, 2.0, 4.0], "x": [0.0, 2.0, 4.0, 6.0]}
DIMS = ("time", "axis", "z", "y", "x")
TIMES = [0.0, 10.0, 20.0, 30.0]


def _field(name: str, times: list[float], ux: list[float]) -> xr.Dataset:
    """A uniform displacement ``ux`` (mm, one per frame) along x on a 2 x 3 x 4 grid."""
    u = np.zeros((len(times), 3, 2, 3, 4))
    u[:, 0] = np.asarray(ux)[:, None, None, None]
    return xr.Dataset({name: (DIMS, u)}, coords={"time": times, "axis": ["x", "y", "z"], **GRID})


TRUTH = _field("displacement_true", TIMES, [0.1 * t for t in TIMES])
# errors 0, 0.1, 0.2, 0.6 mm: the worst frame is the last
TRACKED = _field("displacement_grid", TIMES, [0.0, 1.1, 2.2, 3.6])


def test_every_frame_scored_without_a_warning() -> None:
    err = tracking_error(TRACKED, TRUTH)  # pyproject: a HarpxWarning would fail here
    np.testing.assert_allclose(err["mean_all"], 0.3, atol=1e-12)  # (0.1 + 0.2 + 0.6) / 3
    assert err.attrs["frames_without_estimate"].tolist() == []
    assert err.attrs["frames_without_truth"].tolist() == []


def test_a_failed_frame_is_named_and_flagged() -> None:
    failed = TRACKED.copy(deep=True)
    failed["displacement_grid"][-1] = np.nan  # the tracker gave nothing at 30 ms
    with pytest.warns(HarpxWarning, match=r"NaN at every body voxel .* t = 30 ms.*only the 2"):
        err = tracking_error(failed, TRUTH)
    # the statistics over the frames that have both (0.1 and 0.2 mm) are still reported,
    # but the dropped worst frame is recorded, so 0.15 mm is not mistaken for 0.3 mm
    np.testing.assert_allclose(err["mean_all"], 0.15, atol=1e-12)
    np.testing.assert_allclose(err["mean"].values[:3], [0.0, 0.1, 0.2], atol=1e-12)
    assert np.isnan(err["mean"].values[3])
    assert err.attrs["frames_without_estimate"].tolist() == [30.0]
    assert err.attrs["frames_without_truth"].tolist() == []


def test_untracked_truth_frames_are_named_and_flagged() -> None:
    first = TRACKED.sel(time=[0.0, 10.0])  # only the first two frames tracked
    with pytest.warns(HarpxWarning, match=r"t = 20, 30 ms were not tracked"):
        err = tracking_error(first, TRUTH)
    np.testing.assert_allclose(err["mean_all"], 0.1, atol=1e-12)
    assert err.attrs["frames_without_estimate"].tolist() == [20.0, 30.0]


def test_tracked_frames_without_truth_are_named_and_flagged() -> None:
    with pytest.warns(HarpxWarning, match=r"no frame at tracked t = 10, 30 ms"):
        err = tracking_error(TRACKED, TRUTH.sel(time=[0.0, 20.0]))
    np.testing.assert_allclose(err["mean_all"], 0.2, atol=1e-12)
    assert err.attrs["frames_without_truth"].tolist() == [10.0, 30.0]
    assert err.attrs["frames_without_estimate"].tolist() == []


def test_truth_frames_before_the_tracked_reference_are_not_counted() -> None:
    # at rest until 10 ms, tracked from 10 ms: the frame at 0 ms precedes the tracked
    # sequence, it is not a frame the tracker missed
    truth = _field("displacement_true", TIMES, [0.0, 0.0, 1.0, 2.0])
    tracked = _field("displacement_grid", [10.0, 20.0, 30.0], [0.0, 1.0, 2.05])
    err = tracking_error(tracked, truth)  # no warning
    assert err.attrs["frames_without_estimate"].tolist() == []


def test_a_where_that_selects_nothing_in_a_frame_is_not_a_failed_frame() -> None:
    # 'where' empty at 10 ms (e.g. |u_true| above a threshold reached later): no body
    # voxel to score there, but the tracked result did not fail
    where = xr.DataArray([True, False, True, True], dims="time", coords={"time": TIMES})
    err = tracking_error(TRACKED, TRUTH, where=where)  # no warning
    np.testing.assert_allclose(err["mean_all"], 0.4, atol=1e-12)  # (0.2 + 0.6) / 2
    assert err.attrs["frames_without_estimate"].tolist() == []
