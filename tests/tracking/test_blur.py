"""The band-pass blur of the harmonic phase, predicted from a motion (harpx.tracking.blur)."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.imaging.harp import extract_phase
from harpx.imaging.sample import wrap
from harpx.scenes import short_axis
from harpx.tracking.blur import blur_correction, deblurred, splat
from harpx.tracking.results import grid_points


def test_splat_conserves_the_sum_and_puts_it_at_the_centre_of_mass(rng):
    values = rng.normal(size=200) + 1j * rng.normal(size=200)
    positions = rng.uniform(1.0, 6.0, (200, 3))
    grid = splat(values, positions, np.zeros(3), np.full(3, 0.5), (16, 16, 16))
    # trilinear weights sum to one: the total is kept exactly (round-off)
    assert grid.sum() == pytest.approx(values.sum(), abs=1e-12)
    # and a single real value lands at its position's centre of mass
    one = splat(np.array([1.0 + 0j]), np.array([[2.3, 1.1, 4.9]]), np.zeros(3), np.ones(3),
                (8, 8, 8))  # fmt: skip
    idx = np.indices((8, 8, 8)).reshape(3, -1)
    centre = (idx * one.real.ravel()).sum(axis=1)
    np.testing.assert_allclose(centre, [2.3, 1.1, 4.9], atol=1e-12)


def test_splat_drops_the_corners_beyond_the_grid_and_spreads_columns_at_once():
    from harpx.tracking.blur import splat_operator

    # a point half a voxel outside the first z plane keeps only its in-grid half
    edge = splat(np.array([2.0 + 0j]), np.array([[-0.5, 1.0, 1.0]]), np.zeros(3), np.ones(3),
                 (3, 3, 3))  # fmt: skip
    assert edge.sum() == pytest.approx(1.0, abs=1e-15)
    assert edge[0, 1, 1] == pytest.approx(1.0, abs=1e-15)
    positions = np.array([[0.2, 1.7, 0.4], [1.5, 0.5, 2.5], [-2.0, 0.0, 0.0]])
    values = np.array([[1.0, 2j], [3.0, -1.0], [5.0, 5.0]])
    P = splat_operator(positions, np.zeros(3), np.ones(3), (3, 3, 3))
    both = (P @ values).reshape(3, 3, 3, 2)
    for column in range(2):
        one = splat(values[:, column], positions, np.zeros(3), np.ones(3), (3, 3, 3))
        np.testing.assert_allclose(both[..., column], one, atol=1e-15)
    assert P[:, 2].sum() == 0.0  # wholly outside: nothing lands


def test_predicted_blur_explains_the_phase_bias_of_a_thickening_wall():
    # noise-free short-axis images of the known motion: the measured phase minus the ideal
    # k·X(x) is the band-pass's bias; the correction predicted from the true motion removes
    # two thirds of it once the wall thickens (measured 0.096-0.153 → 0.039-0.046 rad in
    # frames 2-4; what is left is mostly the 8 mm slice profile, which the model omits)
    scene = short_axis("small", snr=None)
    phase = extract_phase(scene.tagged)
    body = scene.body()
    times = phase["time"].values
    U = np.stack([scene.motion(body.dof_points, float(t)).ravel() for t in times])
    correction = blur_correction(phase, body, U)
    assert correction.shape == (2, len(times), *phase["phase"].shape[2:])
    assert np.all(correction[:, 0] == 0.0)
    points = grid_points(phase)
    directions = phase.tag_direction.transpose("tag", "axis").sel(axis=["x", "y", "z"]).values
    k = 2 * np.pi * phase.tag_frequency.values[:, None] * directions
    g = scene.info["geometry"]
    grid_phase = phase.phase.transpose("time", "z", "y", "x", "tag").values.reshape(
        len(times), -1, 2
    )
    offset = np.angle(np.exp(1j * (grid_phase[0] - points @ k.T)).mean(axis=0))
    fixed = deblurred(phase, correction).phase.transpose("time", "z", "y", "x", "tag")
    fixed = fixed.values.reshape(len(times), -1, 2)
    for n in range(2, len(times)):
        X = scene.motion.inverse(points, float(times[n]))
        R = np.hypot(X[:, 0], X[:, 1])
        wall = (R > g.inner_radius + 0.5) & (R < g.outer_radius - 0.5)
        wall &= np.abs(X[:, 2]) < 0.5 * g.length - 4.0
        ideal = X @ k.T + offset
        before = np.abs(wrap(grid_phase[n] - ideal))[wall].mean()
        after = np.abs(wrap(fixed[n] - ideal))[wall].mean()
        assert after < 0.45 * before, (n, before, after)


def test_corrected_images_replace_later_frames_only():
    from harpx.tracking.constraint import PhaseConstraint

    scene = short_axis("small")
    phase = extract_phase(scene.tagged)
    constraint = PhaseConstraint(scene.body(), phase)
    shifted = phase.copy()
    shifted["phase"] = phase["phase"].copy()
    shifted["phase"][:, 1:] = wrap(phase["phase"].values[:, 1:] + 0.1)
    constraint.replace_images(shifted)  # frame 0 kept: accepted
    assert constraint.phase is shifted
    moved = shifted.copy()
    moved["phase"] = shifted["phase"].copy()
    moved["phase"][:, 0] = wrap(phase["phase"].values[:, 0] + 0.1)
    with pytest.raises(ValueError, match="frame 0 unchanged"):
        constraint.replace_images(moved)


def test_phase_carries_the_scenes_slice_geometry_or_none():
    from harpx.errors import SchemaError
    from harpx.schema import validate
    from harpx.tracking.blur import blur_models

    scene = short_axis("small")
    phase = extract_phase(scene.tagged)
    # the scene's 4 contiguous 8 mm SA slices, matched to the x and y tags by their slab
    np.testing.assert_allclose(phase.slice_thickness.values, [8.0, 8.0])
    np.testing.assert_allclose(phase.slice_position.values, [[-12.0, -4.0, 4.0, 12.0]] * 2)
    assert blur_models(phase) == ["slice-profile"] * 2
    assert blur_models(phase, "in-plane") == ["in-plane"] * 2
    # an archive without slice geometry keeps the in-plane model
    bare = phase.drop_vars(["slice_thickness", "slice_position"])
    validate(bare, "phase")
    assert blur_models(bare) == ["in-plane"] * 2
    broken = phase.copy()
    broken["slice_position"] = phase.slice_position[:, ::-1].copy()
    with pytest.raises(SchemaError, match="slice_position"):
        validate(broken, "phase")


@pytest.mark.slow
def test_slice_profile_explains_more_of_the_phase_bias_of_a_thick_slice_wall():
    # noise-free LV images (10 mm SA slices, 11.7 mm LA slices, oblique wall towards the
    # apex) and the truth's own mesh and motion: median |phase − k·X(x)| over the tissue at
    # end systole, measured 0.074 (x, y tags) and 0.042 rad (z tag) as imaged; the in-plane
    # prediction leaves 0.069 / 0.034, the slice-profile one 0.038 / 0.019
    from harpx.scenes.lv import lv

    scene = lv(size="small", snr=None)
    phase = extract_phase(scene.tagged, upsample=1, radius=0.8)
    motion, n = scene.truth, phase.sizes["time"] - 1
    points = grid_points(phase)
    directions = phase.tag_direction.transpose("tag", "axis").sel(axis=["x", "y", "z"]).values
    k = 2 * np.pi * phase.tag_frequency.values[:, None] * directions
    measured = phase.phase.transpose("time", "z", "y", "x", "tag").values.reshape(n + 1, -1, 3)
    tissue0 = phase.body.values.reshape(-1) > 0.99
    offset = np.angle(np.exp(1j * (measured[0] - points @ k.T))[tissue0].mean(axis=0))
    X = motion.inverse(points, float(phase.time[n]))
    tissue = motion.density(X) > 0.99
    held = phase["mask"].transpose("z", "y", "x", "tag").values.reshape(-1, 3) & tissue[:, None]
    ideal = X @ k.T + offset

    def median_error(values):
        error = np.abs(wrap(values - ideal))
        return np.array([np.median(error[held[:, t], t]) for t in range(3)])

    before = median_error(measured[n])
    after = {}
    for model in ("in-plane", "slice-profile"):
        correction = blur_correction(phase, motion.body, motion.U, model)
        fixed = deblurred(phase, correction).phase.transpose("time", "z", "y", "x", "tag")
        after[model] = median_error(fixed.values.reshape(n + 1, -1, 3)[n])
    np.testing.assert_allclose(before, [0.074, 0.074, 0.042], atol=0.005)
    np.testing.assert_allclose(after["in-plane"], [0.069, 0.069, 0.034], atol=0.005)
    np.testing.assert_allclose(after["slice-profile"], [0.038, 0.038, 0.019], atol=0.005)
    assert np.all(after["slice-profile"] < 0.6 * after["in-plane"])
