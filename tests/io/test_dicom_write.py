"""write_tagged → read_tagged reproduces a tagged/1 dataset (grid, masks, images, times)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

pytest.importorskip("pydicom")

from harpx.io.dicom import read_tagged  # noqa: E402
from harpx.io.dicom_write import write_tagged  # noqa: E402
from harpx.schema import fill_standard_attrs  # noqa: E402


def _tagged(rng) -> xr.Dataset:
    # a small grid so the test is fast: 2 frames of 6 x 8 x 7 voxels of 2 mm
    z, y, x = np.arange(6) * 2.0 - 5.0, np.arange(8) * 2.0 - 7.0, np.arange(7) * 2.0 - 6.0
    image = rng.normal(size=(3, 2, z.size, y.size, x.size))
    mask = np.ones((3, z.size, y.size, x.size), dtype=bool)
    mask[:2, :1] = False  # the short-axis slab leaves out the lowest plane
    mask[2, :, :2] = False  # the long-axis slab leaves out two y planes
    image = np.where(mask[:, None], image, 0.0)
    ds = xr.Dataset(
        {"image": (("tag", "time", "z", "y", "x"), image),
         "mask": (("tag", "z", "y", "x"), mask)},
        coords={
            "tag": ["x", "y", "z"], "axis": ["x", "y", "z"],
            "tag_direction": (("tag", "axis"), np.eye(3)),
            "tag_frequency": ("tag", [0.125] * 3),
            "slice_axis": ("tag", ["z", "z", "y"]),
            "time": ("time", [0.0, 30.0]), "z": z, "y": y, "x": x,
        },
        attrs={"harpx_schema": "tagged/1", "sequence": "CSPAMM"},
    )  # fmt: skip
    return fill_standard_attrs(ds)


def test_written_series_read_back_on_the_same_grid(tmp_path, rng):
    ds = _tagged(rng)
    described = write_tagged(ds, tmp_path)
    assert described == {"x": "tagged x", "y": "tagged y", "z": "tagged z"}
    directions = {described[t]: [(t, tuple(np.eye(3)[i]))] for i, t in enumerate("xyz")}
    back = read_tagged(tmp_path, tag_period=8.0, tag_directions=directions)
    for d in ("z", "y", "x", "time"):
        np.testing.assert_allclose(back[d], ds[d], atol=1e-9)  # decimal strings, 10 digits
    assert back.attrs["sequence"] == "CSPAMM"
    np.testing.assert_array_equal(back["mask"].values, ds["mask"].values)
    # uint16 with one slope per series: at most half a slope = range / 131070 off
    bound = 0.5 * float(ds.image.max() - ds.image.min()) / 65535 + 1e-9
    assert float(np.abs(back.image - ds.image).max()) <= bound
