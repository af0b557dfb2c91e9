"""The figures say what they show: frames and slices matched and named, colour scales that
span the data (signed ones centred at 0), units that follow the data, blank cells counted.

Every input is constructed, so the expected numbers follow from it in closed form."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest
import xarray as xr

from harpx.errors import HarpxWarning
from harpx.plotting import bullseye, displacement_map, displacement_maps, strain_map

pytestmark = pytest.mark.filterwarnings("error::harpx.errors.HarpxWarning")

TIMES = np.array([0.0, 60.0, 120.0, 180.0, 240.0])
Z = np.array([-4.0, -2.0, 0.0, 2.0, 4.0])
XY = np.linspace(-10.0, 10.0, 11)


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _field(scale: float = 1.0) -> np.ndarray:
    """u = scale * (t / 240 ms) * (x / 10 mm, -y / 20 mm, z / 4 mm - 0.5) on the grid."""
    t = TIMES[:, None, None, None] / 240.0
    z, y, x = np.meshgrid(Z, XY, XY, indexing="ij")
    u = np.stack([x / 10.0, -y / 20.0, z / 4.0 - 0.5])  # (axis, z, y, x)
    return scale * t[:, None] * u[None]


def _truth() -> xr.Dataset:
    dims = ("time", "axis", "z", "y", "x")
    coords = {"time": TIMES, "axis": ["x", "y", "z"], "z": Z, "y": XY, "x": XY}
    return xr.Dataset({"displacement_true": (dims, _field())}, coords=coords)


def _tracked(scale: float = 1.0, frames: slice = slice(None)) -> xr.Dataset:
    truth = _truth().isel(time=frames)
    grid = truth["displacement_true"] * scale
    return xr.Dataset({"displacement_grid": grid.rename(None)}, attrs={"harpx_schema": "tracked/1"})


def test_displacement_maps_refuses_a_result_without_the_frame_shown():
    """A result of frames 0..120 ms has no 240 ms frame: comparing its 120 ms frame with
    the truth's 240 ms one (as before) would show an error of half the motion."""
    with pytest.raises(ValueError, match=r"results\['first 3'\] has no frame at time = 240 ms"):
        displacement_maps({"first 3": _tracked(frames=slice(0, 3))}, _truth(), time=240.0)
    # a shared frame draws: the result's 120 ms frame equals the truth's, error 0
    fig = displacement_maps({"first 3": _tracked(frames=slice(0, 3))}, _truth(), time=120.0)
    err = np.asarray(fig.axes[3].images[0].get_array())
    assert np.nanmax(err) == pytest.approx(0.0, abs=1e-12)
    assert fig.get_suptitle() == "t = 120 ms, z = 0 mm"


def test_displacement_maps_title_the_slice_drawn_and_warn_when_far():
    """z = 500 mm lies 496 mm beyond the last slice (4 mm): the title names z = 4 mm."""
    with pytest.warns(HarpxWarning, match=r"no z = 500 mm; showing the nearest, z = 4 mm"):
        fig = displacement_maps({"FE": _tracked()}, _truth(), time=240.0, z=500.0)
    assert fig.get_suptitle() == "t = 240 ms, z = 4 mm\n(nearest slice to z = 500 mm)"
    # the truth drawn is that slice: |u| at x = y = 10 mm, z = 4 mm, t = 240 ms
    truth = np.asarray(fig.axes[0].images[0].get_array())
    assert truth[-1, -1] == pytest.approx(np.sqrt(1.0 + 0.25 + 0.25), rel=1e-12)


def test_displacement_maps_error_scale_spans_the_errors():
    """A result 3 × the truth errs by 2 |u_true|, up to 2 * sqrt(1.5) = 2.449 mm at the
    corners of z = 0 (|u_true| = sqrt(1 + 0.25 + 0.25) at t = 240 ms), beyond the old fixed
    2 mm; its |u| (up to 3.674 mm) also exceeds the truth's: each row spans its largest."""
    scale = 3.0
    fig = displacement_maps({"bad": _tracked(scale)}, _truth(), time=240.0, z=0.0)
    top = np.sqrt(1.0 + 0.25 + 0.25)  # |u_true| at the corners of z = 0, t = 240 ms
    err_image = fig.axes[3].images[0]
    assert err_image.get_clim() == pytest.approx((0.0, (scale - 1.0) * top), rel=1e-12)
    assert fig.axes[1].images[0].get_clim() == pytest.approx((0.0, scale * top), rel=1e-12)
    labels = [a.get_ylabel() for a in fig.axes[4:]]
    assert labels == ["|u| (mm)", "|u − u_true| (mm)"]
    assert "max 2.45" in fig.axes[3].get_title()


def test_a_signed_displacement_component_is_centred_at_zero():
    """u_z = z / 4 - 0.5 at t = 240 ms spans -1.5 .. 0.5 mm: limits ±1.5 mm."""
    ax = displacement_map(_tracked(), component="z", z=-4.0)  # the slice z = -4: u_z = -1.5
    assert ax.collections[0].get_clim() == pytest.approx((-1.5, 1.5), rel=1e-12)
    ax = displacement_map(_tracked(), component="x", z=0.0)  # u_x = x / 10: -1 .. 1 mm
    assert ax.collections[0].get_clim() == pytest.approx((-1.0, 1.0), rel=1e-12)


def _strain_result() -> xr.Dataset:
    """A cardiac_strain-like result: peak strain -0.01 k (segment k), peak at 240 ms."""
    segment = np.arange(1, 18)
    component = ["radial", "circumferential", "longitudinal"]
    peak = -0.01 * segment[:, None] * np.array([-1.0, 1.0, 0.5])
    curve = TIMES[:, None, None] / 240.0 * peak[None]
    return xr.Dataset(
        {
            "peak_strain": (("segment", "component"), peak, {"units": "1",
                            "long_name": "peak segment Green-Lagrange strain"}),
            "peak_time": (("segment", "component"), np.full((17, 3), 240.0), {"units": "ms",
                          "long_name": "time of peak strain"}),
            "segment_strain": (("time", "segment", "component"), curve, {"units": "1",
                               "long_name": "segment mean Green-Lagrange strain"}),
        },
        coords={"segment": segment, "component": component, "time": TIMES},
        attrs={"radial_strain_caution": "likely under-reported"},
    )  # fmt: skip


def test_bullseye_units_follow_the_data():
    result = _strain_result()
    fig = bullseye(result, variable="peak_time")  # 240 ms, not 24000 %
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert texts[:2] == ["1", "240"]
    assert fig.axes[1].get_ylabel() == "time of peak circumferential strain (ms)"
    # plain numbers state no units: times are still taken as strains, but it warns and says so
    with pytest.warns(HarpxWarning, match=r"no units and reach 240.*pass units="):
        fig = bullseye(np.full(17, 240.0))
    assert "no units given: drawn as strain (%)" in fig.axes[0].texts[-1].get_text()
    fig = bullseye(np.full(17, 240.0), units="ms", title="peak time")
    assert [t.get_text() for t in fig.axes[0].texts][:2] == ["1", "240"]
    assert fig.axes[1].get_ylabel() == "value (ms)"


def test_bullseye_of_a_derived_array_does_not_claim_the_strain():
    """tracked - truth keeps the name and attributes of peak_strain (xarray keeps attrs)."""
    result = _strain_result()
    diff = result.peak_strain - 0.5 * result.peak_strain  # segment k: -0.005 k
    assert diff.attrs["long_name"] == "peak segment Green-Lagrange strain"
    fig = bullseye(diff)
    assert fig.axes[0].get_title() == "circumferential value"
    assert fig.axes[1].get_ylabel() == "circumferential value (%)"
    assert [t.get_text() for t in fig.axes[0].texts][:2] == ["1", "\u22120.5"]


def test_bullseye_time_beyond_the_frames_warns_and_component_is_honoured():
    result = _strain_result()
    with pytest.warns(HarpxWarning, match=r"no time = 10000 ms; showing the nearest, time = 240"):
        fig = bullseye(result, variable="segment_strain", time=10000.0)
    assert fig.axes[0].get_title() == (
        "circumferential strain (Green-Lagrange)\nt = 240 ms\n(nearest frame to time = 10000 ms)"
    )
    radial = result.peak_strain.sel(component="radial")  # segment k: +0.01 k
    with pytest.raises(ValueError, match=r"component='circumferential'.*holds 'radial'"):
        bullseye(radial, component="circumferential")
    fig = bullseye(radial, component="radial")
    assert [t.get_text() for t in fig.axes[0].texts][:2] == ["1", "1.0"]
    with pytest.raises(ValueError, match=r"time=100.0 cannot be selected"):
        bullseye(result, time=100.0)
    # the radial caution of a dataset follows the component shown
    fig = bullseye(result, component="radial")
    assert "under-reported" in fig.axes[0].texts[-1].get_text()


def _slab(values: list[float]) -> xr.Dataset:
    """Three hex8 cells in a row along x (2 mm cubes, z 0..2 mm); E_xx of each given."""
    x = np.arange(4) * 2.0
    grid = np.array([[xi, yi, zi] for zi in (0.0, 2.0) for yi in (0.0, 2.0) for xi in x])
    node = {tuple(p): n for n, p in enumerate(grid)}
    cells = []
    for c in range(3):
        x0, x1 = x[c], x[c + 1]
        corners = [(x0, 0, 0), (x1, 0, 0), (x1, 2, 0), (x0, 2, 0),
                   (x0, 0, 2), (x1, 0, 2), (x1, 2, 2), (x0, 2, 2)]  # fmt: skip
        cells.append([node[tuple(map(float, p))] for p in corners])
    strain = np.zeros((1, 3, 3, 3))
    strain[0, :, 0, 0] = values
    return xr.Dataset(
        {
            "points": (("point", "coord"), grid),
            "cells": (("cell", "corner"), np.array(cells), {"element": "hex8"}),
            "green_strain": (("time", "cell", "i", "j"), strain),
        },
        coords={"time": [100.0]},
        attrs={"harpx_schema": "tracked/1"},
    )


def test_strain_map_counts_blank_cells_and_refuses_a_non_positive_vmax():
    ds = _slab([0.02, np.nan, -0.05])
    ax = strain_map(ds, component="xx")
    assert "1 of 3 cells without a value (blank)" in ax.get_title().split("\n")
    cells = next(c for c in ax.collections if c.get_gid() == "strain-cells")
    assert cells.get_clim() == pytest.approx((-5.0, 5.0), rel=1e-12)
    for bad in (0.0, -10.0, float("nan")):
        with pytest.raises(ValueError, match=rf"vmax must be a positive number.*vmax={bad!r}"):
            strain_map(ds, component="xx", vmax=bad)
    ax = strain_map(_slab([0.02, 0.01, -0.05]), component="xx", vmax=10.0)
    assert "without a value" not in ax.get_title()
    cells = next(c for c in ax.collections if c.get_gid() == "strain-cells")
    assert cells.get_clim() == (-10.0, 10.0)
