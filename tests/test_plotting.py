"""Pictures from ds.harp.plot draw what they say on small datasets: the values, slices,
masks and order they show, not their pixels."""

from __future__ import annotations

import importlib
import warnings

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

import harpx.plotting
from harpx.errors import HarpxWarning, SchemaError
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


def _collection(ax, gid):
    return next(c for c in ax.collections if c.get_gid() == gid)


def test_nearest_slice_is_named_and_far_ones_warn(tracked):
    """z = -3, -1.5, 0, 1.5, 3 mm: 0.5 mm shows z = 0 and says so; 10 mm (outside the
    stack, 7 mm from the last slice) also warns; an existing slice is named alone."""
    ds, result = tracked
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ax = ds.harp.plot.phase(tag="y", z=0.5)
        assert ax.get_title() == "tag y, t = 36 ms, z = 0 mm\n(nearest slice to z = 0.5 mm)"
        assert ds.harp.plot.phase(z=1.5, time=0.0).get_title() == "tag x, t = 0 ms, z = 1.5 mm"
    with pytest.warns(HarpxWarning, match=r"no z = 10 mm; showing the nearest, z = 3 mm"):
        ax = result.harp.plot.displacement(z=10.0)
    assert ax.get_title() == "t = 36 ms, z = 3 mm\n(nearest slice to z = 10 mm)"
    with pytest.warns(HarpxWarning, match=r"no time = 500 ms"):
        ds.harp.plot.phase(time=500.0)
    with pytest.raises(ValueError, match="z must be a finite number"):
        ds.harp.plot.phase(z=float("nan"))


def _disc_phase(noise: str | None):
    """Phase of a 10 mm disc (magnitude 1 inside, 0 outside) on a 1.5 mm grid."""
    motion = RotationalImpact(radius=10.0, base=-3.0, height=6.0, angle=0.05)
    ds = ideal_phase(
        motion, shape=(3, 20, 20), spacing=(1.5, 1.5, 1.5), times=[0.0],
        body=lambda p: (np.hypot(p[:, 0], p[:, 1]) < 10.0).astype(float),
    )  # fmt: skip
    if noise:
        ds["harmonic_noise"] = ("tag", [0.01, 0.01, 0.01] if noise == "estimated" else [np.nan] * 3)
    return ds


# "nan": the estimate extract_phase records for images too small to measure the noise; the
# map falls back on the magnitude alone rather than hiding every pixel
@pytest.mark.parametrize("noise", ["estimated", None, "nan"])
def test_phase_is_blank_outside_the_tissue(noise):
    ds = _disc_phase(noise)
    shown = _slice_values(ds.harp.plot.phase(tag="x", z=0.0))
    tissue = ds["magnitude"].sel(tag="x", z=0.0).isel(time=0).values > 0.5
    assert 50 < tissue.sum() < tissue.size - 50  # both inside and outside pixels
    assert np.array_equal(np.isfinite(shown), tissue)
    # the phase itself is untouched inside
    phase = ds["phase"].sel(tag="x", z=0.0).isel(time=0).values
    assert np.array_equal(shown[tissue], phase[tissue])
    # mask=None shows every pixel, a given mask those it holds
    assert np.isfinite(_slice_values(ds.harp.plot.phase(tag="x", z=0.0, mask=None))).all()
    square = (np.abs(ds.x) < 5.0) & (np.abs(ds.y) < 5.0)
    given = _slice_values(ds.harp.plot.phase(tag="x", z=0.0, mask=square))
    assert np.array_equal(np.isfinite(given), square.transpose("y", "x").values)
    with pytest.raises(ValueError, match="mask must be 'tissue'"):
        ds.harp.plot.phase(mask="body")


def _slice_values(ax) -> np.ndarray:
    """The (y, x) values of the map drawn in ``ax`` (NaN where blank)."""
    mesh = ax.collections[0]
    values = np.ma.filled(np.ma.masked_invalid(mesh.get_array()).astype(float), np.nan)
    ny, nx = (n - 1 for n in mesh.get_coordinates().shape[:2])
    return values.reshape(ny, nx)


ALPHA = 0.08  # uniform expansion u = ALPHA (X - c): E = (ALPHA + ALPHA^2 / 2) I


@pytest.fixture(scope="module")
def expanded():
    """Cardiac strain of the LV template expanded uniformly (every normal strain exact),
    its z tags missing (the longitudinal direction is then inferred) and in-plane only."""
    from harpx.cardiac.strain import cardiac_strain

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HarpxWarning)  # unseen directions, as intended
        uniform = fe_dataset(lambda p: ALPHA * (p - TEMPLATE.centre), seen=(1.0, 1.0, 0.0))
        in_plane = fe_dataset(lambda p: ALPHA * (p - TEMPLATE.centre) * [1.0, 1.0, 0.0])
        return (
            cardiac_strain(uniform, TEMPLATE, anterior=0.0),
            cardiac_strain(in_plane, TEMPLATE, anterior=0.0),
        )


def test_strain_map_of_a_uniform_expansion_is_its_closed_form(expanded):
    uniform, in_plane = expanded
    exact = 100.0 * (ALPHA + ALPHA**2 / 2.0)  # in %
    for component in ("radial", "circumferential", "longitudinal", "Ecc", "xx", "zz"):
        ax = uniform.harp.plot.strain(component=component, z=-20.0)
        cells = _collection(ax, "strain-cells")
        values = np.asarray(cells.get_array())
        assert len(values) >= 16  # one ring of cells at least
        assert np.allclose(values, exact, rtol=1e-9), component
        assert cells.norm.vmin == -cells.norm.vmax  # centred at 0
        assert "z = -20 mm" in ax.get_title()
        assert ax.figure.axes[-1].get_ylabel().endswith("(%)")
        plt.close("all")
    # in-plane expansion: e_c lies in the short-axis plane, so Ecc is exact everywhere,
    # and xx as well; zz is zero
    assert np.allclose(_collection(in_plane.harp.plot.strain(component="Ecc", z=-20.0),
                                   "strain-cells").get_array(), exact)  # fmt: skip
    assert np.allclose(_collection(in_plane.harp.plot.strain(component="zz", z=-20.0),
                                   "strain-cells").get_array(), 0.0, atol=1e-9)  # fmt: skip


def test_strain_map_cuts_the_mesh_where_asked(expanded):
    """The cells drawn are those the plane cuts, and their cross-sections fill the wall's
    section: the template's annulus at that height, as the 16-sided mesh approximates it."""
    from harpx.plotting.strain import strain_on_slice

    uniform, _ = expanded
    z = -20.0
    cut = strain_on_slice(uniform, "radial", z=z)
    corners = uniform["points"].values[uniform["cells"].values[:, :8], 2]
    assert np.array_equal(
        cut["cells"], np.flatnonzero((corners.min(1) <= z) & (corners.max(1) > z))
    )
    x, y = zip(*[(p[:, 0], p[:, 1]) for p in cut["polygons"]], strict=True)
    area = sum(
        0.5 * abs(a @ np.roll(b, -1) - b @ np.roll(a, -1)) for a, b in zip(x, y, strict=True)
    )
    g, h = TEMPLATE.geometry, z - TEMPLATE.centre[2]
    radius = [a * np.sqrt(1.0 - (h / c) ** 2) for a, c in (g.outer, g.inner)]
    polygon = 16 * np.sin(2 * np.pi / 16) / (2 * np.pi)  # 16-gon / circle, same radius
    # measured 0.17 % over (-0.2 % at z = 0): the cut's straight edges between node layers
    assert area == pytest.approx(polygon * np.pi * (radius[0] ** 2 - radius[1] ** 2), rel=0.01)
    with pytest.raises(ValueError, match=r"z = 200 mm does not cut the mesh, which spans"):
        uniform.harp.plot.strain(component="radial", z=200.0)


def test_strain_map_marks_what_the_model_inferred(expanded):
    """Without z tags the longitudinal strain is inferred (hatched, named in the title);
    the circumferential one lies in the tagged plane and is observed."""
    uniform, _ = expanded
    ax = uniform.harp.plot.strain(component="longitudinal", z=-20.0)
    assert "inferred by the model" in ax.get_title()
    hatched = _collection(ax, "strain-inferred")
    assert len(hatched.get_paths()) == len(_collection(ax, "strain-cells").get_paths())
    ax = uniform.harp.plot.strain(component="circumferential", z=-20.0)
    assert "inferred" not in ax.get_title()
    assert [c.get_gid() for c in ax.collections] == ["strain-cells"]


def test_strain_map_components_by_name(tracked, expanded):
    _, result = tracked
    ax = result.harp.plot.strain(i=1, j=0)  # the tutorial's spelling: E_xy
    same = result.harp.plot.strain(component="E_xy")
    assert np.array_equal(_collection(ax, "strain-cells").get_array(),
                          _collection(same, "strain-cells").get_array())  # fmt: skip
    assert "$E_{xy}$" in ax.get_title()
    with pytest.raises(SchemaError, match=r"cardiac_strain\(template\)"):
        result.harp.plot.strain(component="radial")
    with pytest.raises(ValueError, match="unknown component 'Erc'"):
        expanded[0].harp.plot.strain(component="Erc")
    with pytest.raises(ValueError, match="not both"):
        result.harp.plot.strain(component="xx", i=0, j=0)


def _with_regions(result, names, labels):
    out = result.copy()
    out["region"] = ("cell", np.asarray(labels))
    out["region"].attrs.update(flag_values=np.arange(len(names)), flag_meanings=" ".join(names))
    return out


def test_fiber_stretch_regions_in_order_without_empty_rows(tracked):
    """Labels in natural order top to bottom (aha_2 before aha_10), the empty region left
    out, each box drawn from its own cells; a compact figure."""
    _, result = tracked
    ncell = result.sizes["cell"]
    labels = np.arange(ncell) % 3 + 1  # myocardium (0) has no cell
    ds = _with_regions(result, ["myocardium", "aha_10", "aha_2", "aha_1"], labels)
    ax = ds.harp.plot.fiber_stretch()
    rows = sorted(ax.get_yticklabels(), key=lambda t: -t.get_position()[1])  # top first
    counts = [int((labels == k).sum()) for k in (3, 2, 1)]
    assert [t.get_text() for t in rows] == [
        f"aha_1 ({counts[0]})",
        f"aha_2 ({counts[1]})",
        f"aha_10 ({counts[2]})",
    ]
    width, height = ax.figure.get_size_inches()
    assert width <= 5.5 and height <= 2.5  # three rows (the old figure: 8 x 4 in)
    # the median line of the top box is the median of aha_1's cells
    stretch = ds["fiber_stretch"].isel(time=-1).values
    medians = [line for line in ax.lines if len(line.get_xdata()) == 2
               and line.get_xdata()[0] == line.get_xdata()[1]
               and abs(line.get_ydata()[1] - line.get_ydata()[0] - 0.6) < 1e-9]  # fmt: skip
    top = max(medians, key=lambda line: line.get_ydata()[0])
    assert top.get_xdata()[0] == pytest.approx(np.median(stretch[labels == 3]))
    # the order given; a region asked for without cells is named, an unknown one refused
    ax = ds.harp.plot.fiber_stretch(regions=["aha_10", "myocardium"])
    assert [t.get_text() for t in ax.get_yticklabels()] == [f"aha_10 ({counts[2]})"]
    assert "no cells: myocardium" in ax.get_title()
    with pytest.raises(ValueError, match=r"\['septum'\] are not in the dataset"):
        ds.harp.plot.fiber_stretch(regions=["septum"])


def test_fiber_stretch_of_seventeen_segments_stays_readable(tracked):
    """18 named regions (the LV mesh's myocardium and aha_01..aha_17): one row each, a
    figure no wider than a column (the old one was 23.6 in wide)."""
    _, result = tracked
    names = ["myocardium", *(f"aha_{k:02d}" for k in (1, 7, 2, 8, 3, 9, 4, 10, 5, 11, 6, 12))]
    names += [f"aha_{k:02d}" for k in range(13, 18)]
    labels = np.arange(result.sizes["cell"]) % 17 + 1
    ax = _with_regions(result, names, labels).harp.plot.fiber_stretch()
    rows = sorted(ax.get_yticklabels(), key=lambda t: -t.get_position()[1])  # top first
    texts = [t.get_text().split()[0] for t in rows]
    assert texts == [f"aha_{k:02d}" for k in range(1, 18)]
    width, height = ax.figure.get_size_inches()
    assert width <= 5.5 and height <= 7.5


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
        "strain_lv": cardiac.harp.plot.strain(component="radial"),
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
    assert axes["phase"].get_title() == "tag y, t = 36 ms, z = 0 mm"
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
