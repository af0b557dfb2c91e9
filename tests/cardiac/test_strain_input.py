"""cardiac_strain on inputs it used to get wrong: a grid stored in descending coordinate
order, and ``anterior=`` in a form it does not take."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.anatomy.ventricle import VentricleGeometry
from harpx.anatomy.ventricle_fit import VentricleTemplate
from harpx.cardiac.strain import aha_segments, cardiac_strain

TEMPLATE = VentricleTemplate(VentricleGeometry((25.0, 70.0), (35.0, 78.0), 10.0), anterior=0.0)


def _grid_motion() -> xr.Dataset:
    """The wall on a 4 mm grid shrinking by 10 % in the short-axis plane, turning by 0.1
    degree per mm of height and shortening by 5 % along the axis (ascending coordinates)."""
    x = y = np.arange(-36.0, 37.0, 4.0)
    z = np.arange(-78.0, 11.0, 4.0)
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    a = np.deg2rad(0.1) * Z
    u = np.stack([0.9 * (np.cos(a) * X - np.sin(a) * Y) - X,
                  0.9 * (np.sin(a) * X + np.cos(a) * Y) - Y, -0.05 * Z])  # fmt: skip
    wall = TEMPLATE.transmural(np.stack([X, Y, Z], axis=-1).reshape(-1, 3)).reshape(X.shape)
    return xr.Dataset(
        {"displacement_true": (("time", "axis", "z", "y", "x"), np.stack([0.0 * u, u])),
         "body": (("z", "y", "x"), ((wall >= 0.0) & (wall <= 1.0) & (Z <= 10.0)) * 1.0)},
        coords={"time": [0.0, 100.0], "axis": ["x", "y", "z"], "z": z, "y": y, "x": x},
    )  # fmt: skip


@pytest.mark.parametrize("dims", [("z",), ("x",), ("x", "y", "z")])
def test_descending_grid_gives_the_same_segments(dims):
    ds = _grid_motion()
    ascending = cardiac_strain(ds, TEMPLATE)
    reversed_ = cardiac_strain(ds.isel({d: slice(None, None, -1) for d in dims}), TEMPLATE)
    # the same voxels in another order: same segment volumes (4**3 mm3 each, positive),
    # strains, peaks and twist to round-off
    volume = ascending.segment_volume.values
    assert np.all(volume > 0)
    np.testing.assert_allclose(reversed_.segment_volume.values, volume, rtol=1e-12)
    for name in ("peak_strain", "segment_coverage", "twist", "torsion"):
        np.testing.assert_allclose(reversed_[name].values, ascending[name].values, atol=1e-12)
    # and the closed form: circumferential Green strain (0.9**2 - 1) / 2 = -0.095 in every
    # segment, torsion 0.1 degree/mm (both 2e-16 off measured; the tolerance leaves room
    # for central differences of the turn on another grid)
    circ = reversed_.peak_strain.sel(component="circumferential").values
    np.testing.assert_allclose(circ, -0.095, atol=1e-3)
    assert float(reversed_.torsion.sel(time=100.0)) == pytest.approx(0.1, abs=1e-3)
    # the segment map follows the reversed voxels
    np.testing.assert_array_equal(
        reversed_.aha_segment_grid.transpose("z", "y", "x").sortby(["z", "y", "x"]).values,
        ascending.aha_segment_grid.values,
    )


def test_ascending_body_with_descending_displacement_is_aligned():
    # body= passed separately on the ascending grid: reversed to the displacement's order
    # (not read in the wrong voxel order), so the result is that of the consistent dataset
    ds = _grid_motion()
    body = ds["body"]
    flipped = ds.drop_vars("body").isel(z=slice(None, None, -1))
    out = cardiac_strain(flipped, TEMPLATE, body=body)
    want = cardiac_strain(ds, TEMPLATE)
    np.testing.assert_allclose(out.peak_strain.values, want.peak_strain.values, atol=1e-12)
    # a body on another grid is refused, naming the coordinate
    with pytest.raises(ValueError, match="body's z coordinate"):
        cardiac_strain(flipped, TEMPLATE, body=body.isel(z=slice(1, None)))


@pytest.mark.parametrize(
    ("anterior", "error", "match"),
    [
        ((0.0, 1.0, 0.0), TypeError, r"anterior=\(0\.0, 1\.0, 0\.0\) must be an angle in deg"),
        ([90.0], TypeError, r"anterior=\[90\.0\] must be an angle"),
        ("90", TypeError, "anterior='90' must be an angle"),
        (float("nan"), ValueError, "anterior=nan is not finite"),
    ],
)
def test_anterior_must_be_an_angle(anterior, error, match):
    with pytest.raises(error, match=match):
        cardiac_strain(_grid_motion(), TEMPLATE, anterior=anterior)
    with pytest.raises(error, match=match):
        aha_segments([[30.0, 0.0, 0.0]], TEMPLATE, anterior=anterior)
    # the form the message points at: the angle of a point on the anterior wall (here +y at
    # mid level, z = -30 between the thirds' borders -43.3 and -16.7 mm) labels it mid anterior
    point = [[0.0, 30.0, -30.0]]
    angle = float(TEMPLATE.angle(point)[0])
    assert angle == pytest.approx(90.0, abs=1e-9)
    assert aha_segments(point, TEMPLATE, anterior=angle).tolist() == [7]
