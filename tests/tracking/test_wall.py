"""Smoothing along the wall (harpx.tracking.wall): depth from the endo/epi boundaries, an
average that keeps the transmural profile and removes detail along the wall."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box
from harpx.tracking.settings import TrackingSettings
from harpx.tracking.wall import smooth_along_wall, transmural_depth, wall_smoother
from tests.cardiac._lv import TEMPLATE, body_of


@pytest.fixture(scope="module")
def wall_body() -> Body:
    return body_of(n=(48, 12, 4))


def test_depth_follows_the_template_layers(wall_body):
    # the template meshes its wall in 4 equal transmural steps: layers at 0, 1/4, ..., 1 of
    # the template's own transmural fraction (an independent, geometric definition)
    layers = TEMPLATE.transmural(wall_body.dof_points)
    depth = transmural_depth(wall_body)
    # measured: 0.0021 rms, 0.0063 at worst; bounds 1.2 × those
    assert np.sqrt(np.mean((depth - layers) ** 2)) < 1.2 * 0.0021
    assert np.max(np.abs(depth - layers)) < 1.2 * 0.0063
    assert depth.min() == 0.0 and depth.max() == 1.0


def test_the_average_keeps_the_transmural_profile_and_damps_detail_along_the_wall(wall_body):
    S = wall_smoother(wall_body, 5.0)
    np.testing.assert_allclose(np.asarray(S.sum(axis=1)).ravel(), 1.0, rtol=1e-12)
    layers = TEMPLATE.transmural(wall_body.dof_points)
    # a thickening profile: 2 mm inward at the endocardium to 0 at the epicardium (along x)
    profile = np.zeros((2, wall_body.ndof))
    profile[1, wall_body.node_dofs[:, 0]] = 2.0 * (1.0 - layers)
    # alternating ±0.5 mm between neighbouring nodes around the wall (48 around): a fit's
    # roughness; judged away from the apical cap, whose nodes are not on the 48-around grid
    off = wall_body.dof_points[:, :2] - np.array(TEMPLATE.centre[:2])
    ring = np.hypot(*off.T) >= 15.0
    rough = np.zeros((2, wall_body.ndof))
    rough[1, wall_body.node_dofs[:, 1]] = 0.5 * np.cos(24 * np.arctan2(off[:, 1], off[:, 0]))
    kept = smooth_along_wall(wall_body, profile, S)
    damped = smooth_along_wall(wall_body, rough, S)

    # measured: the profile moves by 0.046 % of its rms, the roughness keeps 2.5 % of its
    # rms on the ring; bounds 1.2 × those. Without the depth weight (an average over all
    # depths) the profile moves by 37 % of its rms and the first bound fails.
    def rms(a):
        return float(np.sqrt(np.mean(a**2)))

    assert rms(kept - profile) < 1.2 * 0.00046 * rms(profile)
    y = wall_body.node_dofs[ring, 1]
    assert rms(damped[1, y]) < 1.2 * 0.025 * rms(rough[1, y])
    np.testing.assert_array_equal(kept[0], 0.0)


def test_the_smoother_refuses_a_body_without_a_wall_and_a_length_not_positive():
    body = Body(box((10.0, 10.0, 10.0), (2, 2, 2)), NeoHookean(c1=1.0, kappa=10.0))
    with pytest.raises(ValueError, match="'endo' boundary"):
        wall_smoother(body, 4.0)
    with pytest.raises(ValueError, match="wall_smoothing=-1"):
        TrackingSettings(wall_smoothing=-1.0)
    with pytest.raises(ValueError, match="wall_smoothing=0"):
        wall_smoother(body_of(), 0.0)


def test_track_refuses_wall_smoothing_on_a_body_without_the_wall(lv_small):
    from harpx.imaging.harp import extract_phase
    from harpx.tracking.track import track

    body = lv_small.body()
    # the same mesh with its base named and its endocardium and epicardium not
    bare = Body(lv_small.mesh, lv_small.material, boundaries={"base": body.boundaries["base"]})
    phase = extract_phase(lv_small.tagged.isel(time=[0, 1]), upsample=1)
    with pytest.raises(ValueError, match="needs the body's 'endo' boundary"):
        track(phase, bare, dirichlet=lv_small.dirichlet(), wall_smoothing=3.0)


def test_a_wall_one_cell_thick_is_counted_warned_and_flagged(lv_small):
    from harpx.errors import HarpxWarning
    from harpx.imaging.harp import extract_phase
    from harpx.tracking.track import track
    from harpx.tracking.wall import cells_across_wall

    # the template's layers: one cell per transmural division (measured within 0.17 % of n:
    # the depth's nearest-node distances are not exactly the template's layers)
    for n in (1, 2, 4):
        assert cells_across_wall(body_of(n=(16, 6, n))) == pytest.approx(n, rel=2e-3)
    # one cell across: on the small infarct scene's 6 mm segmentation mesh (one across) the
    # radial error rose from 8.6-9.0 % to 10.1-11.0 % with wall_smoothing (the guide)
    thin = Body(lv_small.template().mesh(n_circumferential=16, n_longitudinal=4,
                                         n_transmural=1), lv_small.material)  # fmt: skip
    phase = extract_phase(lv_small.tagged.isel(time=[0, 1]), upsample=1)
    with pytest.warns(HarpxWarning, match=r"about 1\.0 cells thick"):
        result = track(phase, thin, dirichlet=lv_small.template().base_conditions(),
                       wall_smoothing=3.0, blur_passes=1)  # fmt: skip
    assert result.attrs["wall_cells_across"] == 1.0


def test_wall_smoothing_without_a_correction_pass_is_warned_about(lv_small):
    from harpx.errors import HarpxWarning
    from harpx.imaging.harp import extract_phase
    from harpx.tracking.track import track

    phase = extract_phase(lv_small.tagged.isel(time=[0, 1]), upsample=1)
    with pytest.warns(HarpxWarning, match="wall_smoothing has no effect"):
        result = track(phase, lv_small.body(), dirichlet=lv_small.dirichlet(),
                       wall_smoothing=3.0, blur_passes=0)  # fmt: skip
    assert "wall_cells_across" not in result.attrs
