"""Pictures from ds.harp.plot draw what they say on small datasets."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import cylinder
from harpx.scenes._motion import RotationalImpact
from harpx.tracking.track import track
from tests._ideal import ideal_phase


@pytest.fixture(scope="module")
def tracked():
    motion = RotationalImpact(radius=12.0, base=-3.0, height=6.0, angle=0.1)
    ds = ideal_phase(motion, shape=(5, 24, 24), spacing=(1.5, 1.5, 1.5), times=[0.0, 36.0])
    mesh = cylinder(12.0, 6.0, n_radial=1, n_circumferential=8, n_axial=2, center=(0, 0, -3.0))
    fibers = np.tile([1.0, 0.0, 0.0], (mesh.mesh.nelements, 1))
    body = Body(mesh, NeoHookean(1.0, 120.0), fibers=fibers)
    return ds, track(ds, body)


def test_phase_and_displacement_maps(tracked):
    ds, result = tracked
    ax = ds.harp.plot.phase(tag="x")
    # the colour scale spans the wrapped range
    assert ax.collections[0].get_clim() == (-np.pi, np.pi)
    ax = result.harp.plot.displacement(component="y")
    assert "u_y (mm)" in ax.figure.axes[-1].get_ylabel()
    plt.close("all")


def test_strain_and_fiber_stretch(tracked):
    _, result = tracked
    ax = result.harp.plot.strain(i=0, j=1)
    assert len(ax.collections[0].get_offsets()) > 0
    ax = result.harp.plot.fiber_stretch()
    assert ax.get_ylabel() == "fibre stretch"
    plt.close("all")


def test_tag_image_of_a_tagged_dataset():
    from harpx.imaging.synth import synthesize_tagged

    tagged = synthesize_tagged(
        lambda X, t: 0 * X,
        shape=(2, 16, 16),
        spacing=(2.0, 1.5, 1.5),
        times=[0.0],
        tags=("x",),
        snr=None,
        oversample=1,
    )
    ax = tagged.harp.plot.tag_image()
    assert ax.images or ax.collections
    plt.close("all")


def test_fiber_stretch_without_fibers_is_a_clear_error(tracked):
    ds, result = tracked
    with pytest.raises(ValueError, match="no 'fiber_stretch'"):
        result.drop_vars("fiber_stretch").harp.plot.fiber_stretch()
