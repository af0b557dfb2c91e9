"""Brain-phantom scene (paper §4.1): FE tracking against conventional HARP, small size.

The small phantom has 6 mm tags and a container that turns 0.3 rad in 36 ms, so the edge
steps 3.6 and 4.6 mm between frames: more than half a tag period, where wrapped phase
alone is ambiguous.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import track_harp
from harpx.scenes import phantom
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track


@pytest.fixture(scope="module")
def scene():
    return phantom("small")


@pytest.fixture(scope="module")
def phase(scene):
    return extract_phase(scene.tagged, upsample=2)


@pytest.fixture(scope="module")
def fe(scene, phase):
    return track(phase, scene.body("hex8"), epsilon=0.05)


@pytest.fixture(scope="module")
def harp(scene, phase):
    out = track_harp(phase, points=scene.tagged)
    # the phantom moves within the acquired field of view: HARP loses no point (its edge
    # points follow the blurred phase out of the tissue, and are counted in the errors)
    assert out.attrs["points_lost"] == 0
    return out


def _edge_band(tagged: xr.Dataset, width: float) -> xr.DataArray:
    """Body voxels within ``width`` mm of the cylinder's side or faces."""
    g = tagged.attrs
    radius = float(np.sqrt(tagged.x**2 + tagged.y**2).where(tagged.body > 0.5).max())
    r = np.sqrt(tagged.x**2 + tagged.y**2)
    ztop = float(tagged.z.where(tagged.body.max(("y", "x")) > 0.5).max())
    del g
    return (r > radius - width) | (np.abs(tagged.z) > ztop - width)


def test_fe_error_is_sub_voxel_without_tag_jumps(fe, scene):
    err = tracking_error(fe, scene.tagged)
    assert fe.target_reached.all(), fe.epsilon.values
    # issue 4 asks for 0.3 mm mean and 1 mm p95 (1.5 mm voxels); measured 0.197 mm mean and
    # 0.569 mm p95, bounded 20 % above so that a lost gain shows
    assert float(err.mean_all) < 0.24, err["mean"].values
    assert float(err.p95_all) < 0.68, err.p95.values
    # worst voxel measured 1.48 mm (bound 1.2 x); a tag jump would leave errors of about a
    # tag period (6 mm) somewhere
    assert float(err.max_all) < 1.2 * 1.48, err["max"].values


def test_harp_is_worse_at_the_edges_and_beyond_half_a_period(fe, harp, scene):
    tagged = scene.tagged
    edge = _edge_band(tagged, width=3.0)
    period = 1.0 / float(tagged.tag_frequency.max())
    steps = np.sqrt((tagged.displacement_true.diff("time") ** 2).sum("axis", skipna=False))
    fast = (steps > period / 2).reindex(time=tagged.time, fill_value=False)
    for name, where in [("edge band", edge), ("step > half a period", fast)]:
        e_fe = float(tracking_error(fe, tagged, where=where).mean_all)
        e_harp = float(tracking_error(harp, tagged, where=where).mean_all)
        # measured at least 5x; asserting 3x leaves room for the noise realisation
        assert e_harp > 3 * e_fe, (name, e_harp, e_fe)
        assert e_fe < 0.5, (name, e_fe)


def test_augmented_lagrangian_reaches_the_same_epsilon(phase, scene, fe):
    al = track(phase, scene.body("hex8"), method="augmented-lagrangian", epsilon=0.05)
    assert np.all(al.epsilon.values[1:] <= 0.05), al.epsilon.values
    e_al = float(tracking_error(al, scene.tagged).mean_all)
    e_pen = float(tracking_error(fe, scene.tagged).mean_all)
    # both enforce the same ε on the same data: within 0.1 mm mean of each other
    assert abs(e_al - e_pen) < 0.1, (e_al, e_pen)


@pytest.mark.parametrize("scale", [10.0, 0.1], ids=["C1x10", "C1x0.1"])
def test_penalty_adapts_to_material_stiffness(phase, scene, fe, scale):
    from harpx.mechanics.materials import NeoHookean

    stiff = scene.body("hex8", material=NeoHookean(c1=1.0 * scale, kappa=120.0))
    other = track(phase, stiff, epsilon=0.05)
    assert np.all(other.epsilon.values[1:] <= 0.05), other.epsilon.values
    e_other = float(tracking_error(other, scene.tagged).mean_all)
    e_ref = float(tracking_error(fe, scene.tagged).mean_all)
    # only C1 changes (κ stays 120 kPa, so κ/C1 becomes 12 or 1200: a different material,
    # not a rescaled one); the automatic λ reaches the same ε and the error changes by
    # less than 10 % (issue 4)
    assert abs(e_other - e_ref) < 0.1 * e_ref, (e_other, e_ref)


def test_hex8_and_hex20_agree(phase, scene, fe):
    hex20 = track(phase, scene.body("hex20"), epsilon=0.05)
    diff = np.sqrt(
        ((fe.displacement_grid - hex20.displacement_grid) ** 2).sum("axis", skipna=False)
    )
    # the two element orders track the same images to the same ε: issue 4 asks for agreement
    # within 0.1 mm; measured 0.051 mm mean difference, bounded 20 % above
    assert float(diff.isel(time=slice(1, None)).mean()) < 0.062
    e8 = float(tracking_error(fe, scene.tagged).mean_all)
    e20 = float(tracking_error(hex20, scene.tagged).mean_all)
    assert abs(e8 - e20) < 0.1, (e8, e20)
