"""Pictures from ds.harp.plot draw what they say on small datasets."""

from __future__ import annotations

import importlib

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

import harpx.plotting
from harpx.errors import SchemaError
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import cylinder
from harpx.scenes._motion import RotationalImpact
from harpx.tracking.track import track
from tests._ideal import ideal_phase
from tests.cardiac._lv import TEMPLATE, fe_dataset


@pytest.fixture(scope="module")
def tracked():
    motion = RotationalImpact(radius=12.0, base=-3.0, height=6.0, angle=0.1)
    ds = ideal_phase(motion, shape=(5, 24, 24), spacing=(1.5, 1.5, 1.5), times=[0.0, 36.0])
    mesh = cylinder(12.0, 6.0, n_radial=1, n_circumferential=8, n_axial=2, center=(0, 0, -3.0))
    fibers = np.tile([1.0, 0.0, 0.0], (mesh.mesh.nelements, 1))
    body = Body(mesh, NeoHookean(1.0, 120.0), fibers=fibers)
    return ds, track(ds, body)


@pytest.fixture(scope="module")
def cardiac():
    """A cardiac strain result (10 % in-plane contraction of the LV template)."""
    from harpx.cardiac.strain import cardiac_strain

    ds = fe_dataset(lambda p: -0.1 * (p - TEMPLATE.centre) * [1.0, 1.0, 0.0])
    return cardiac_strain(ds, TEMPLATE, anterior=0.0)


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


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


def test_plotting_leaves_the_matplotlib_backend_alone(tracked, cardiac):
    """Importing harpx.plotting and drawing keep the backend the user chose."""
    ds, result = tracked
    before = matplotlib.get_backend()
    plt.switch_backend("svg")
    try:
        importlib.reload(harpx.plotting)  # module-level code runs again, as on first import
        ds.harp.plot.phase()
        result.harp.plot.displacement()
        harpx.plotting.error_vs_runtime([{"method": "a", "seconds": 1, "mean": 1, "p95": 2}])
        cardiac.harp.plot.bullseye()
        cardiac.harp.plot.segment_curves()
        assert matplotlib.get_backend() == "svg"
    finally:
        plt.switch_backend(before)


def _outside(fig) -> list[str]:
    """Sides on which drawn text or artists stick out of the figure (1/144 in tolerance)."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    box = fig.get_tightbbox(canvas.get_renderer())  # inches, every drawn artist
    tol = 0.5 / 72
    width, height = fig.get_size_inches()
    sides = {"left": box.x0 < -tol, "bottom": box.y0 < -tol}
    sides.update(right=box.x1 > width + tol, top=box.y1 > height + tol)
    return [side for side, out in sides.items() if out]


def test_every_plot_keeps_its_titles_and_labels_inside_the_figure(tracked, cardiac):
    ds, result = tracked
    tagged = ds.copy()
    tagged["image"] = ds["magnitude"]
    tagged.attrs["harpx_schema"] = "tagged/1"
    axes = {
        "tag_image": tagged.harp.plot.tag_image(),
        "phase": ds.harp.plot.phase(tag="y"),
        "displacement": result.harp.plot.displacement(component="x"),
        "strain": result.harp.plot.strain(i=0, j=1),
        "fiber_stretch": result.harp.plot.fiber_stretch(),
    }
    figures = {name: ax.figure for name, ax in axes.items()}
    figures["displacement_maps"] = harpx.plotting.displacement_maps(
        {"FE hex8": result, "FE hex8 again": result}, ds, time=36.0
    )
    rows = [
        {"method": "conventional HARP, upsample 2", "seconds": 34.2, "mean": 0.42, "p95": 0.47},
        {"method": "FE penalty, hex8 4320 cells", "seconds": 103.3, "mean": 0.13, "p95": 0.34},
    ]
    figures["error_vs_runtime"] = harpx.plotting.error_vs_runtime(rows)
    figures["bullseye"] = harpx.plotting.bullseye(cardiac)
    figures["segment_curves"] = harpx.plotting.segment_curves(cardiac)
    # each single-axes plot has a title naming its frame
    assert axes["phase"].get_title() == "tag y, t = 36 ms, z = 0.0 mm"
    assert {name: _outside(fig) for name, fig in figures.items()} == dict.fromkeys(figures, [])


def test_plots_of_the_wrong_dataset_kind_name_both_kinds(tracked):
    ds, result = tracked
    with pytest.raises(SchemaError, match=r"'phase/1' dataset; got a 'tracked/1'"):
        result.harp.plot.phase()
    with pytest.raises(SchemaError, match=r"'tracked/1' dataset; got a 'phase/1'.*harp\.track"):
        ds.harp.plot.displacement()
    with pytest.raises(SchemaError, match=r"'tagged/1' dataset; got a 'phase/1'"):
        ds.harp.plot.tag_image()
    with pytest.raises(SchemaError, match=r"'tracked/1' dataset; got a 'phase/1'"):
        ds.harp.plot.strain()
    # a dataset without a kind attribute is named by what it lacks
    bare = result.drop_vars("displacement_grid")
    bare.attrs.pop("harpx_schema")
    with pytest.raises(SchemaError, match=r"needs 'displacement_grid' of a 'tracked/1'"):
        bare.harp.plot.displacement()


NOTEBOOK = """
# %%
import matplotlib
import harpx
from harpx.imaging.synth import synthesize_tagged

tagged = synthesize_tagged(
    lambda X, t: 0 * X, shape=(2, 16, 16), spacing=(2.0, 1.5, 1.5), times=[0.0],
    tags=("x",), snr=None, oversample=1,
)
print(harpx.__file__)

# %%
tagged.harp.plot.tag_image();

# %%
print(matplotlib.get_backend())
"""


@pytest.mark.slow
def test_a_plot_in_a_notebook_shows_inline():
    """Run in a real Jupyter kernel, a harpx plot appears under its cell as a PNG."""
    jupytext = pytest.importorskip("jupytext")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    nb = jupytext.reads(NOTEBOOK.strip(), fmt="py:percent")
    client = nbclient.NotebookClient(
        nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(root)}}
    )
    client.execute()
    first, plot, backend = (cell.outputs for cell in nb.cells)
    assert first[0]["text"].strip() == str(root / "harpx" / "__init__.py")  # this checkout
    assert [k for out in plot for k in out.get("data", {}) if k.startswith("image/")] == [
        "image/png"
    ]
    assert "inline" in backend[0]["text"]
