"""Short-axis scene: in-plane tags only, a tube that contracts, twists and shortens (small)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.imaging.harp import extract_phase
from harpx.imaging.sample import wrap
from harpx.scenes import short_axis
from harpx.scenes.short_axis import GEOMETRIES
from harpx.schema import validate


@pytest.fixture(scope="module")
def scene():
    return short_axis("small")


def test_images_are_two_in_plane_tags_with_slab_masks(scene):
    ds = scene.tagged
    validate(ds, "tagged")
    g = GEOMETRIES["small"]
    assert list(ds.tag.values) == ["x", "y"] and list(ds.slice_axis.values) == ["z", "z"]
    np.testing.assert_allclose(ds.tag_frequency.values, 1.0 / g.tag_period, rtol=1e-15)
    # the mask is the stack's slab: the whole in-plane field of view, between the slab faces
    z = ds.z.values
    half = 0.5 * g.slices * g.slice_thickness  # slices centred on z = 0
    slab = (z >= -half - 1e-6) & (z <= half + 1e-6)
    expected = np.broadcast_to(slab[None, :, None, None], ds.mask.shape)
    np.testing.assert_array_equal(ds.mask.values, expected)
    # the grid spans the slab to within a voxel of each face
    assert z[0] - (z[1] - z[0]) < -half and z[-1] + (z[1] - z[0]) > half
    assert np.all(ds.image.values[:, :, ~slab] == 0.0)
    # the body is the tube, inside the slab, and a tissue voxel is not tissue-only masked
    body = ds.body.values
    assert body.max() == 1.0 and np.all(body[~slab] == 0.0)
    assert (body >= 0.5).sum() < 0.5 * slab.sum() * ds.sizes["y"] * ds.sizes["x"]


def test_tag_phase_at_frame_0_matches_the_tag_frequency():
    tagged = short_axis("small", snr=None).tagged
    phase = extract_phase(tagged.isel(time=[0]), upsample=1)
    body = phase.body.values >= 1.0  # voxels wholly inside the wall
    grid = {d: phase[d].values for d in ("x", "y")}
    Z, Y, X = np.meshgrid(phase.z.values, grid["y"], grid["x"], indexing="ij")
    for j, (tag, coord) in enumerate((("x", X), ("y", Y))):
        f = float(phase.tag_frequency.sel(tag=tag))
        residual = wrap(phase.phase.values[j, 0] - 2.0 * np.pi * f * coord)[body]
        # the phase ramp of the images has the tag frequency: a relative error df/f would
        # tilt the residual by 2π df per mm (measured 0.092 % on either tag)
        slope = np.polyfit(coord[body], residual, 1)[0]
        assert abs(slope / (2.0 * np.pi * f)) < 1.1e-3, (tag, slope)
        # CSPAMM cosine tags have no phase offset (measured 2e-9 and 6e-9 rad, the images'
        # float32 round-off: symmetric ring; round-off differs between machines, so 1e-6)
        offset = np.angle(np.mean(np.exp(1j * residual)))
        assert abs(offset) < 1e-6, (tag, offset)
        # noise-free: what is left is the band-pass filter's blur at the edges of a 7 mm
        # wall (measured median 0.052, p95 0.162 rad; one tag period is 2π rad = 7 mm)
        spread = np.abs(residual)
        assert np.median(spread) < 0.063, (tag, np.median(spread))
        assert np.percentile(spread, 95) < 0.195, (tag, np.percentile(spread, 95))


def test_truth_contracts_twists_and_shortens_towards_the_held_bottom(scene):
    g = GEOMETRIES["small"]
    truth = scene.tagged.displacement_true
    np.testing.assert_array_equal(np.isnan(truth.values[:, 0]), np.isnan(truth.values[:, 2]))
    assert np.nanmax(np.abs(truth.values[0])) < 1e-12  # reference frame (rounding of cos, sin)
    assert np.isnan(truth.values[:, :, scene.tagged.body.values < 0.5]).all()
    m = scene.motion
    bottom, top = m.bottom, m.bottom + m.length
    t_end = float(scene.tagged.time[-1])
    # exact closed form (rounding only): the inner wall moves in by `contraction`, the top
    # moves down by `shortening * length`, the bottom stays, the top twists by `twist`
    pts = np.array([[g.inner_radius, 0.0, bottom], [0.0, g.inner_radius, top]])
    x = pts + m(pts, t_end)
    r = np.hypot(x[:, 0], x[:, 1])
    np.testing.assert_allclose(r, g.inner_radius - g.contraction, rtol=1e-12)
    np.testing.assert_allclose(x[:, 2], [bottom, top - g.shortening * m.length], atol=1e-12)
    np.testing.assert_allclose(
        np.arctan2(x[:, 1], x[:, 0]), [0.0, 0.5 * np.pi + g.twist], atol=1e-12
    )
    # the through-plane motion is in the truth on the grid: up to 2.8 mm at the top voxels
    # (within a voxel, 1.17 mm x 10 %, of the top face), never upwards
    uz = truth.sel(axis="z").values
    assert np.nanmin(uz) < -g.shortening * (m.length - 1.17), np.nanmin(uz)
    assert np.nanmax(uz) < 1e-12


def test_motion_is_volume_preserving_and_its_inverse_is_exact(scene, rng):
    m = scene.motion
    g = GEOMETRIES["small"]
    n = 200
    R = rng.uniform(g.inner_radius, g.outer_radius, n)
    th = rng.uniform(0.0, 2 * np.pi, n)
    X = np.column_stack([R * np.cos(th), R * np.sin(th), rng.uniform(-14.0, 14.0, n)])
    t = 0.6 * float(scene.tagged.time[-1])
    x = X + m(X, t)
    np.testing.assert_allclose(m.inverse(x, t), X, atol=1e-12)  # closed form, rounding only
    h = 1e-5
    F = np.empty((n, 3, 3))
    for k in range(3):
        dX = np.zeros(3)
        dX[k] = h
        F[:, :, k] = ((X + dX + m(X + dX, t)) - (X - dX + m(X - dX, t))) / (2 * h)
    # central differences: error ~ h² |u'''| ~ 1e-10; det F = 1 analytically
    np.testing.assert_allclose(np.linalg.det(F), 1.0, atol=1e-7)


def test_error_split_separates_in_plane_from_through_plane(scene):
    truth = scene.tagged.displacement_true
    shifted = truth.copy()
    shifted.loc[{"axis": "z"}] = truth.sel(axis="z") + 1.0  # a rigid 1 mm drift along z
    tracked = xr.Dataset({"displacement_grid": shifted})
    split = scene.error_split(tracked)
    # exact: the in-plane part is the truth itself, the z part is off by exactly 1 mm
    np.testing.assert_allclose(split.in_plane_max.values[1:], 0.0, atol=1e-12)
    np.testing.assert_allclose(split.through_plane_mean.values[1:], 1.0, rtol=1e-12)
    np.testing.assert_allclose(split.drift.values, 1.0, rtol=1e-12)
    assert float(split.in_plane_mean_all) == 0.0 and float(split.through_plane_p95_all) == 1.0


def test_scene_states_its_boundary_condition_only(scene):
    (held,) = scene.dirichlet
    assert held.facet == "bottom" and held.components == (2,)
    body = scene.body()
    assert body.ncell == 2 * 16 * 3  # coarse mesh so the test is fast
    nodes = body.nodes
    bottom = nodes[np.abs(nodes[:, 2] - scene.motion.bottom) < 1e-9]
    # the truth does not move the held plane along z
    np.testing.assert_allclose(scene.motion(bottom, float(scene.tagged.time[-1]))[:, 2], 0.0)


def test_in_plane_tags_only_track_no_worse_than_harp_and_say_what_they_cannot_see(scene):
    from harpx.errors import HarpxWarning
    from harpx.imaging.harptrack import track_harp
    from harpx.tracking.track import track

    phase = extract_phase(scene.tagged)
    with pytest.warns(HarpxWarning, match="no tag sees motion along z"):
        fe = track(phase, scene.body(), dirichlet=list(scene.dirichlet))
    with pytest.warns(HarpxWarning, match="no tag sees motion along z"):
        plain = track(phase, scene.body(), dirichlet=list(scene.dirichlet), blur_passes=0)
    assert (fe.observed_directions.values == 2).all()
    # every frame reaches the default target itself, not only the plateau allowance
    assert (fe.epsilon.values[1:] <= fe.epsilon_target.values[1:]).all(), fe.epsilon.values
    assert not fe.plateau.values.any() and fe.target_reached.all()
    # the blur-correction pass starts every frame from the first pass's result at the top of
    # the penalty ramp: measured 34 then 13 Gauss–Newton iterations (the same on every run)
    first, second = fe.attrs["iterations_per_pass"]
    assert second <= 0.46 * first, (first, second)
    assert second == int(fe.iterations.sum())
    harp = track_harp(phase, points=scene.tagged)
    ours, theirs = scene.error_split(fe), scene.error_split(harp)
    without = scene.error_split(plain)
    # in-plane, on the same images with the tracker's defaults: measured FE 0.154 / 0.397 mm
    # (mean / p95) against 0.196 / 0.530 without the blur correction and HARP 0.198 / 0.542.
    # FE without the correction is level with HARP, so the correction is what wins: it must
    # keep ≥ 15 % of its 21 % gain, and the error stay within 15 % of the measured value
    assert float(ours.in_plane_mean_all) < 0.85 * float(without.in_plane_mean_all)
    assert float(ours.in_plane_p95_all) < 0.85 * float(without.in_plane_p95_all)
    assert float(ours.in_plane_mean_all) < 1.15 * 0.154
    assert float(ours.in_plane_p95_all) < 1.15 * 0.397
    assert float(ours.in_plane_mean_all) < float(theirs.in_plane_mean_all)
    # through-plane the motion is the model's, inferred from the wall's thickening: HARP
    # reports none, so its drift is the truth's mean shortening (up to 1.47 mm); measured FE
    # at most 0.92 mm, and 1.73 without the blur correction (which under-reports thickening)
    drift, none = np.abs(ours.drift.values).max(), np.abs(theirs.drift.values).max()
    assert drift < 1.12 * 0.92, (ours.drift.values, theirs.drift.values)
    assert drift < 0.65 * np.abs(without.drift.values).max()
    assert drift < 0.7 * none
