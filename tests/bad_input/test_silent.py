"""Silent wrong results: input that used to give a plausible but wrong number."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.tracking.results import tracking_error


def _grid_pair(times_tracked: list[float], times_truth: list[float]) -> tuple[xr.Dataset, ...]:
    """Uniform x displacement 0.1 mm/ms on a 2 x 3 x 4 grid; tracked is exact."""
    coords = {"z": [0.0, 2.0], "y": [0.0, 2.0, 4.0], "x": [0.0, 2.0, 4.0, 6.0]}

    def field(times: list[float], name: str) -> xr.Dataset:
        u = np.zeros((len(times), 3, 2, 3, 4))
        u[:, 0] = 0.1 * np.asarray(times)[:, None, None, None]
        dims = ("time", "axis", "z", "y", "x")
        return xr.Dataset(
            {name: (dims, u)}, coords={"time": times, "axis": ["x", "y", "z"], **coords}
        )

    return field(times_tracked, "displacement_grid"), field(times_truth, "displacement_true")


def test_tracking_error_compares_frames_by_time_not_index() -> None:
    # tracked frames 0, 20 ms against a truth with frames 0, 10, 20 ms: by index, frame 20
    # would be compared with the truth at 10 ms (error 1 mm); by time it is exact
    tracked, truth = _grid_pair([0.0, 20.0], [0.0, 10.0, 20.0])
    err = tracking_error(tracked, truth)
    assert err.time.values.tolist() == [0.0, 20.0]
    np.testing.assert_allclose(err["max_all"], 0.0, atol=1e-12)  # exact tracking


def test_tracking_error_without_common_frames_is_named() -> None:
    tracked, truth = _grid_pair([0.0, 15.0], [5.0, 10.0])
    with pytest.raises(ValueError, match=r"share no frame time: tracked has time \[0.0, 15.0\]"):
        tracking_error(tracked, truth)
