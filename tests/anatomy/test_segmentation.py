"""Meshes from labelled segmentations: boundary following, names, quality, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.anatomy.segmentation import body_from_segmentation, mesh_from_labels
from harpx.io.labels import read_labels
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.quality import scaled_jacobian

R = 12.0  # ball radius, mm
COORD = np.arange(-20.0, 20.5, 1.0)  # 1 mm voxels, coarse grid so the tests are fast


def _grid(values: np.ndarray) -> xr.DataArray:
    return xr.DataArray(values, dims=("z", "y", "x"), coords={"z": COORD, "y": COORD, "x": COORD})


def _radius() -> np.ndarray:
    Z, Y, X = np.meshgrid(COORD, COORD, COORD, indexing="ij")
    return np.sqrt(X**2 + Y**2 + Z**2)


def _boundary_radius(spec) -> np.ndarray:
    mesh = spec.mesh
    verts = np.unique(mesh.facets[:, mesh.boundary_facets()])
    return np.linalg.norm(mesh.p[:, verts].T, axis=1)


def test_smoothed_ball_follows_the_sphere_better_than_the_voxel_mesh():
    ball = _grid((_radius() < R).astype(np.int64))
    smooth = mesh_from_labels(ball, element_size=2.0)
    voxel = mesh_from_labels(ball, element_size=2.0, smoothing=0)
    err_smooth = np.abs(_boundary_radius(smooth.spec) - R).mean()
    err_voxel = np.abs(_boundary_radius(voxel.spec) - R).mean()
    # measured 0.360 mm against 0.743 mm for the staircase (half-voxel iso-surface of a
    # binary mask at 1 mm voxels, 2 mm cubes): half the error (ratio 0.485)
    assert err_smooth < 0.58 * err_voxel, (err_smooth, err_voxel)
    assert err_smooth < 0.43
    q = smooth.quality
    assert q.inverted == 0 and q.dropped_cells == 0
    assert q.min_scaled_jacobian >= 0.2  # the default min_quality
    assert voxel.quality.min_scaled_jacobian == pytest.approx(1.0, abs=1e-12)  # cubes
    # the mesh volume matches the ball within 3 % (measured -2.4 %)
    volume = Body(smooth.spec, NeoHookean(c1=1.0, kappa=10.0)).cell_volume.sum()
    assert volume == pytest.approx(4.0 / 3.0 * np.pi * R**3, rel=0.03)


def test_regions_and_facets_are_named_after_the_labels():
    r = _radius()
    labels = np.where(r < 7.0, 2, np.where(r < 13.0, 1, 0))  # cavity 2 inside a shell 1
    result = mesh_from_labels(
        _grid(labels), element_size=2.0, names={1: "wall", 2: "cavity"}, mesh_labels=[1]
    )
    spec = result.spec
    assert sorted(spec.regions) == ["wall"]
    assert sorted(spec.boundaries) == ["cavity", "exterior"]
    mesh = spec.mesh
    inner = np.linalg.norm(mesh.p[:, mesh.facets[:, spec.boundaries["cavity"]]].T, axis=-1)
    outer = np.linalg.norm(mesh.p[:, mesh.facets[:, spec.boundaries["exterior"]]].T, axis=-1)
    # facets facing the cavity lie on the inner sphere, the others on the outer one
    # (measured at most 0.71 and 0.85 mm off, within half an element of 2 mm)
    assert np.abs(inner - 7.0).max() < 0.85 and np.abs(outer - 13.0).max() < 1.0
    assert result.quality.inverted == 0


def test_fraction_input_predicates_fibres_and_body():
    fraction = _grid(np.clip(R + 0.5 - _radius(), 0.0, 1.0))  # partial-volume ball
    body = body_from_segmentation(
        xr.Dataset({"body": fraction}),
        NeoHookean(c1=1.0, kappa=10.0),
        element_size=3.0,
        boundaries={"top": lambda centres, normals: normals[:, 2] > 0.7},
        fibers=lambda p: np.tile([1.0, 0.0, 0.0], (len(p), 1)),
    )
    assert sorted(body.regions) == ["body"]
    assert {"exterior", "top"} <= set(body.boundaries)
    top = body.mesh.p[:, body.mesh.facets[:, body.boundaries["top"]]]
    assert top[2].min() > 0.0  # upward-facing facets are on the upper half
    assert body.fibers is not None and np.allclose(body.fibers, [1.0, 0.0, 0.0])
    assert body.mesh_quality.inverted == 0
    assert scaled_jacobian(body.nodes, body.cells).min() == pytest.approx(
        body.mesh_quality.min_scaled_jacobian, rel=1e-12
    )


def test_read_labels_from_netcdf(tmp_path):
    labels = _grid((_radius() < R).astype(np.int8))
    path = tmp_path / "labels.nc"
    xr.Dataset({"seg": labels}).to_netcdf(path)
    read = read_labels(path, variable="seg")
    xr.testing.assert_equal(read, labels)  # exact: integer round trip


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"element_size": 0.1}, "at least half a voxel", id="small-element"),
        pytest.param({"element_size": 2.0, "mesh_labels": [5]}, r"labels \[5\]", id="label"),
        pytest.param({"element_size": 2.0, "min_quality": 1.5}, "min_quality", id="quality"),
    ],
)
def test_bad_options_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        mesh_from_labels(_grid((_radius() < R).astype(int)), **kwargs)


def test_bad_grids_are_named():
    uneven = _grid((_radius() < R).astype(int)).assign_coords(x=COORD**3)
    with pytest.raises(ValueError, match="'x' is not increasing and evenly spaced"):
        mesh_from_labels(uneven, element_size=2.0)
    with pytest.raises(ValueError, match="NaN"):
        mesh_from_labels(_grid(np.full(_radius().shape, np.nan)), element_size=2.0)
    with pytest.raises(ValueError, match="expected \\('z', 'y', 'x'\\)"):
        read_labels(xr.DataArray(np.zeros((2, 2)), dims=("y", "x")))


def test_nifti_affine_becomes_lps_coordinates(monkeypatch, tmp_path):
    # nibabel is optional: a stand-in module with the two attributes read_labels uses
    import sys
    import types

    data = np.zeros((4, 3, 2))  # (i, j, k) = (x, y, z) voxel axes
    data[1, 2, 0] = 7
    affine = np.diag([2.0, 3.0, 4.0, 1.0])
    affine[:3, 3] = [10.0, -5.0, 1.0]
    fake = types.SimpleNamespace(
        load=lambda path: types.SimpleNamespace(dataobj=data, affine=affine)
    )
    monkeypatch.setitem(sys.modules, "nibabel", fake)
    labels = read_labels(tmp_path / "mask.nii.gz")
    # RAS (10 + 2i, -5 + 3j, 1 + 4k) -> LPS (-R, -A, S), sorted increasing
    assert labels.x.values.tolist() == [-16.0, -14.0, -12.0, -10.0]
    assert labels.y.values.tolist() == [-1.0, 2.0, 5.0]
    assert labels.z.values.tolist() == [1.0, 5.0]
    hit = labels.where(labels == 7, drop=True)
    assert (hit.x.item(), hit.y.item(), hit.z.item()) == (-12.0, -1.0, 1.0)
    oblique = affine.copy()
    oblique[0, 1] = 0.5
    fake.load = lambda path: types.SimpleNamespace(dataobj=data, affine=oblique)
    with pytest.raises(ValueError, match="oblique affine"):
        read_labels(tmp_path / "mask.nii")


@pytest.mark.parametrize(("element_size", "measured"), [(2.0, 0.789), (4.0, 1.548)])
def test_max_boundary_offset_is_the_distance_to_the_smoothed_surface(element_size, measured):
    # independent truth: along each boundary vertex's ray from the centre, bisect the
    # trilinear interpolant of the smoothed ball for its 0.5 crossing (the surface is a
    # sphere to within the voxel staircase, so the ray meets it nearly normally)
    import scipy.ndimage as ndi

    ball = (_radius() < R).astype(np.int64)
    result = mesh_from_labels(_grid(ball), element_size=element_size)
    phi = ndi.gaussian_filter(ball.astype(np.float64), 1.0, mode="constant")
    mesh = result.spec.mesh
    p = mesh.p[:, np.unique(mesh.facets[:, mesh.boundary_facets()])].T
    radius = np.linalg.norm(p, axis=1)
    lo, hi = np.full(len(p), R - 4.0), np.full(len(p), R + 3.0)
    for _ in range(50):  # bisection to 1e-14 mm
        mid = 0.5 * (lo + hi)
        q = (p / radius[:, None]) * mid[:, None]
        inside = ndi.map_coordinates(phi, (q[:, ::-1] - COORD[0]).T, order=1) > 0.5
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    truth = float(np.abs(radius - 0.5 * (lo + hi)).max())
    # both 0.789 and 1.548 mm; the Newton path stops within 1e-4 of phi = 1/2 (about 1e-3
    # mm); it was |phi - 1/2| / |grad phi|, 25 % and 45 % too large here
    assert result.quality.max_boundary_offset == pytest.approx(truth, abs=0.01)
    assert truth == pytest.approx(measured, abs=0.01)


def test_slab_of_slices_is_meshed_to_its_faces():
    # 3 slices 6 mm apart of a disc: each voxel fills its 6 mm thickness, so the body spans
    # z = -9 .. 9 mm, not only the slice centres -6 .. 6 mm
    z = np.array([-6.0, 0.0, 6.0])
    Z, Y, X = np.meshgrid(z, COORD, COORD, indexing="ij")
    disc = xr.DataArray(
        (X**2 + Y**2 < 100.0).astype(np.int64), dims=("z", "y", "x"),
        coords={"z": z, "y": COORD, "x": COORD},
    )  # fmt: skip
    result = mesh_from_labels(disc, element_size=2.0)
    zs = result.spec.mesh.p[2]
    # measured -8.96 .. 8.96 (before: -7 .. 7, the voxel mesh's last cubes, with the level
    # set cut off at the slice centres)
    assert zs.min() == pytest.approx(-9.0, abs=0.045)
    assert zs.max() == pytest.approx(9.0, abs=0.045)
    # a distance (measured 1.29 mm at the rim, where the 6 mm slices are smoothed by one
    # slice); it was 5e11 mm, a division by the zero gradient beyond the grid
    assert 1.07 < result.quality.max_boundary_offset < 1.55
