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
