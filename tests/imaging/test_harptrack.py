"""Tests of harpx.imaging.harptrack: conventional HARP tracking, successes and failures."""

from __future__ import annotations

import sys
import types
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from numpy.typing import NDArray

from harpx.errors import HarpxWarning, SchemaError
from harpx.imaging.harptrack import track_harp
from harpx.imaging.sample import wrap
from harpx.io.netcdf import open_dataset, to_netcdf
from harpx.schema import standard_attrs, validate

PERIOD = 8.0  # tag period, mm
K = 2 * np.pi / PERIOD  # rad/mm
Motion = Callable[[NDArray[np.float64], int], NDArray[np.float64]]


def moving_phase(
    motion: Motion,
    *,
    ntime: int = 3,
    shape: tuple[int, int, int] = (1, 40, 40),
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0),
    ntag: int = 2,
) -> xr.Dataset:
    """phase/1 of a motion u(X, t): phase(x, t) = W(k_t · X(x, t)), magnitude 1.

    X(x, t) inverts x = X + u(X, t) by fixed-point iteration (|grad u| << 1 here).
    """
    z, y, x = (spacing[i] * np.arange(shape[i]) for i in range(3))
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    spatial = np.stack([xx, yy, zz], -1).reshape(-1, 3)
    k = K * np.eye(3)[:ntag]
    phase = np.empty((ntag, ntime, *shape))
    for t in range(ntime):
        material = spatial.copy()
        for _ in range(60):
            material = spatial - motion(material, t)
        phase[:, t] = wrap(material @ k.T).T.reshape(ntag, *shape)
    dims = ("tag", "time", "z", "y", "x")
    return xr.Dataset(
        {
            "phase": (dims, phase, standard_attrs("phase")),
            "magnitude": (dims, np.ones_like(phase), standard_attrs("magnitude")),
        },
        coords={
            "tag": ("tag", ["x", "y", "z"][:ntag], standard_attrs("tag")),
            "axis": ("axis", ["x", "y", "z"], standard_attrs("axis")),
            "tag_direction": (("tag", "axis"), np.eye(3)[:ntag], standard_attrs("tag_direction")),
            "tag_frequency": ("tag", [1 / PERIOD] * ntag, standard_attrs("tag_frequency")),
            "slice_axis": ("tag", ["z", "z", "y"][:ntag], standard_attrs("slice_axis")),
            "time": ("time", 18.0 * np.arange(ntime), standard_attrs("time")),
            "z": ("z", z, standard_attrs("z")),
            "y": ("y", y, standard_attrs("y")),
            "x": ("x", x, standard_attrs("x")),
        },
        attrs={"harpx_schema": "phase/1", "sequence": "CSPAMM", "upsample": 1, "radius": 0.5},
    )


def translation(step: tuple[float, float, float]) -> Motion:
    return lambda X, t: np.broadcast_to(t * np.asarray(step), X.shape)


def _errors(out: xr.Dataset, motion: Motion) -> NDArray[np.float64]:
    """|tracked - true| displacement (time, node) in mm; NaN where untracked."""
    X = out.points.values
    truth = np.stack([motion(X, t) for t in range(out.sizes["time"])])
    return np.linalg.norm(out.displacement.values - truth, axis=-1)


def test_rigid_translation_2d_on_the_voxel_grid() -> None:
    motion = translation((1.5, -0.5, 0.0))  # half-voxel multiples, 1.6 mm per frame < P/2
    ds = moving_phase(motion)
    with pytest.warns(HarpxWarning, match="lost 157 of 1600 points"):
        out = track_harp(ds)
    validate(out)
    assert out.attrs["method"] == "harp" and out.cells.attrs["element"] == "points"
    error = _errors(out, motion)
    tracked = np.isfinite(error)
    # only points carried out of the field of view are lost: 3 mm along x takes the last 3
    # columns out (120 points), -1 mm along y the first row (40), 3 of them counted twice
    assert out.attrs["points_lost"] == 157
    assert (~tracked[-1]).sum() == 157
    # analytic phase, cubic spline of a constant demodulated image: the fixed point is exact
    # up to the 1e-4 rad stopping tolerance (1e-4 / |k| ~ 1e-4 mm); the brief asks < 0.05 mm
    assert np.nanmax(error) < 0.05, np.nanmax(error)
    assert np.all(out.epsilon.values < 1e-4)  # stopped by the tolerance
    assert out.iterations.values[0] == 0 and np.all(out.iterations.values[1:] <= 10)
    assert np.all(out.displacement.values[..., 2][tracked] == 0)  # 2 tags: in-plane only
    grid = out.displacement_grid
    assert grid.dims == ("time", "axis", "z", "y", "x")
    # the grid holds the same numbers as the node list
    np.testing.assert_array_equal(
        grid.isel(time=1).sel(axis="x").values.ravel()[np.isfinite(error[1])],
        out.displacement.isel(time=1).sel(axis="x").values[np.isfinite(error[1])],
    )


def test_rigid_translation_3d_three_tags() -> None:
    motion = translation((1.0, -0.5, 0.75))
    ds = moving_phase(motion, shape=(12, 14, 14), spacing=(1.5, 1.0, 1.0), ntag=3)
    points = np.array([[5.0, 6.0, 6.0], [7.3, 4.1, 8.2], [3.5, 8.5, 4.5]])
    out = track_harp(ds, points=points)
    assert "displacement_grid" not in out
    error = _errors(out, motion)
    assert np.isfinite(error).all()
    assert error.max() < 0.05, error.max()  # as in 2D: exact up to the stopping tolerance


def _smooth(X: NDArray[np.float64], t: int) -> NDArray[np.float64]:
    """A smooth non-rigid motion: up to 1.2 mm per frame, strains up to ~20%."""
    x, y = X[:, 0], X[:, 1]
    u = np.zeros_like(X)
    u[:, 0] = t * (0.8 * np.sin(2 * np.pi * y / 32) + 0.4)
    u[:, 1] = t * 0.6 * np.cos(2 * np.pi * x / 40)
    return u


def test_smooth_deformation_2d() -> None:
    ds = moving_phase(_smooth)
    with pytest.warns(HarpxWarning, match="lost"):  # at the edge of the field of view
        out = track_harp(ds)
    error = _errors(out, _smooth)
    X = out.points.values
    interior = np.all((X[:, :2] >= 6) & (X[:, :2] <= 33), axis=1)  # away from the FOV edge
    assert np.isfinite(error[:, interior]).all()
    assert out.attrs["points_lost"] == int((~np.isfinite(error)).any(axis=0).sum()) > 0
    # exact phase, smooth demodulated image: spline error ~1e-4 rad ~ 1e-4 mm
    assert np.nanmax(error[:, interior]) < 0.05, np.nanmax(error[:, interior])


def test_tag_jump_beyond_half_a_period() -> None:
    """The textbook failure: a 0.75-period step per frame is tracked as -0.25 period."""
    step = 0.75 * PERIOD  # 6 mm along the x tag direction in one frame
    ds = moving_phase(translation((step, 0.0, 0.0)), ntime=2, shape=(1, 24, 48))
    points = np.array([[20.0, 10.0, 0.0], [24.5, 12.5, 0.0], [30.0, 6.0, 0.0]])
    out = track_harp(ds, points=points)
    ux = out.displacement.sel(axis="x").values[1]
    uy = out.displacement.sel(axis="y").values[1]
    # HARP lands on the nearest equal-phase line, one tag period behind: 0.75 P - P = -0.25 P
    np.testing.assert_allclose(ux, -0.25 * PERIOD, atol=0.05)  # same 0.05 mm as the successes
    np.testing.assert_allclose(uy, 0.0, atol=0.05)
    assert out.epsilon.values[1] < 1e-4  # and it is fully "converged": the error is silent


def test_points_outside_the_data_are_nan() -> None:
    ds = moving_phase(translation((0.5, 0.0, 0.0)), ntime=2, shape=(1, 12, 12))
    with pytest.warns(HarpxWarning, match=r"1 of 2 points have no valid phase in frame 0"):
        out = track_harp(ds, points=[[5.0, 5.0, 0.0], [50.0, 5.0, 0.0]])
    assert np.isfinite(out.displacement.values[:, 0]).all()
    assert out.attrs["points_lost"] == 0  # a point without data at frame 0 is not "lost"
    assert out.attrs["points_unseen"] == 1  # but it is counted
    assert np.isnan(out.displacement.values[:, 1]).all()


def test_result_archives_exactly(tmp_path: Path) -> None:
    with pytest.warns(HarpxWarning, match="lost 19 of 100"):  # the edge row and column
        out = track_harp(moving_phase(translation((0.5, 0.5, 0.0)), ntime=2, shape=(1, 10, 10)))
    xr.testing.assert_identical(open_dataset(to_netcdf(out, tmp_path / "h.nc")), out)  # exact


def test_tagged_input_is_phase_extracted_first(monkeypatch: pytest.MonkeyPatch) -> None:
    phase = moving_phase(translation((0.5, 0.0, 0.0)), ntime=2, shape=(1, 12, 12))
    calls = []

    def extract_phase(ds: xr.Dataset, **kwargs: object) -> xr.Dataset:
        calls.append(ds.attrs["harpx_schema"])
        return phase

    fake = types.ModuleType("harpx.imaging.harp")
    fake.extract_phase = extract_phase  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "harpx.imaging.harp", fake)
    tagged = xr.Dataset(attrs={"harpx_schema": "tagged/1"})
    out = track_harp(tagged, points=[[5.0, 5.0, 0.0]])
    assert calls == ["tagged/1"]
    assert abs(float(out.displacement.sel(axis="x")[1, 0]) - 0.5) < 0.05  # as above


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        pytest.param(
            {"iterations": 0}, ValueError, "iterations=0 must be a whole number", id="iterations"
        ),
        pytest.param(
            {"points": np.zeros((3, 2))},
            ValueError,
            r"points must have shape \(n, 3\)",
            id="points",
        ),
    ],
)
def test_bad_arguments(kwargs: dict[str, object], error: type, match: str) -> None:
    ds = moving_phase(translation((0.5, 0.0, 0.0)), ntime=2, shape=(1, 8, 8))
    with pytest.raises(error, match=match):
        track_harp(ds, **kwargs)  # type: ignore[arg-type]


def test_wrong_schema_is_rejected() -> None:
    with pytest.raises(SchemaError, match="needs a 'phase/1' or 'tagged/1' dataset"):
        track_harp(xr.Dataset(attrs={"harpx_schema": "tracked/1"}))


def test_a_contracting_ring_made_the_synth_way_loses_no_points() -> None:
    """The mask is the acquisition's field of view, so tissue moving within it stays valid."""
    from harpx.imaging.synth import synthesize_tagged
    from harpx.scenes.short_axis import ContractingTube

    ring = ContractingTube(
        inner_radius=12.0, bottom=-14.0, length=28.0, contraction=3.0, duration=160.0
    )

    def body(X: NDArray[np.float64]) -> NDArray[np.float64]:
        R = np.hypot(X[:, 0], X[:, 1])
        return ((R >= 12.0) & (R <= 19.0)).astype(float)

    # one short-axis slice of 8 mm, x and y tags of 7 mm, 1.17 mm pixels, SNR 20
    ds = synthesize_tagged(
        ring,
        shape=(1, 48, 48),
        spacing=(8.0, 1.17, 1.17),
        times=40.0 * np.arange(5),
        tag_period=7.0,
        tags=("x", "y"),
        slice_thickness=8.0,
        body=body,
        inverse=ring.inverse,
        oversample=2,
        rng=0,
    )
    assert ds["mask"].values.all()  # the whole grid was acquired; the tissue is `body`
    with warnings.catch_warnings():
        warnings.simplefilter("error", HarpxWarning)
        out = track_harp(ds, points=ds)
    assert out.attrs["points_lost"] == 0
    # the tissue voxels, less a few edge voxels where the (linearly) refined body is < 0.5
    # (measured 490 of 504)
    assert out.sizes["node"] > 0.95 * int((ds["body"].values >= 0.5).sum()), out.sizes["node"]
    assert np.isfinite(out["displacement"].values).all()
    # the old meaning (mask = the body at frame 0) dropped every point whose current position
    # left the reference body: the contracting inner wall, about a quarter of the points
    old = ds.assign(mask=(ds["mask"] & (ds["body"] >= 0.5)).assign_attrs(ds["mask"].attrs))
    with pytest.warns(HarpxWarning, match="lost"):
        lost = track_harp(old, points=old).attrs["points_lost"]
    assert lost > 0.2 * out.sizes["node"], lost
