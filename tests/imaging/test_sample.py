"""Tests of harpx.imaging.sample: wrap-safe phase and gradient interpolation."""

from __future__ import annotations

from collections.abc import Callable

import dask.array as da
import numpy as np
import pytest
import xarray as xr
from hypothesis import given
from hypothesis import strategies as st
from numpy.typing import NDArray
from scipy import ndimage

from harpx.errors import SchemaError
from harpx.imaging.sample import PhaseSampler, reference_phase, wrap
from harpx.schema import standard_attrs, validate

PERIOD = 8.0  # tag period, mm
FREQ = 1.0 / PERIOD  # cycles/mm
K = 2 * np.pi * FREQ  # |k|, rad/mm


def _perturbation(p: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A smooth phase perturbation (rad) and its gradient (rad/mm) at points (n, 3)."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    value = 0.5 * np.sin(2 * np.pi * x / 40) + 0.3 * np.cos(2 * np.pi * y / 30 + 0.2 * z)
    s = -0.3 * np.sin(2 * np.pi * y / 30 + 0.2 * z)
    grad = np.stack(
        [0.5 * 2 * np.pi / 40 * np.cos(2 * np.pi * x / 40), s * 2 * np.pi / 30, s * 0.2], -1
    )
    return value, grad


def phase_dataset(
    *,
    shape: tuple[int, int, int] = (10, 26, 28),
    spacing: tuple[float, float, float] = (1.5, 1.0, 1.0),
    ntag: int = 3,
    field: Callable[
        [NDArray[np.float64]], tuple[NDArray[np.float64], NDArray[np.float64]]
    ] = _perturbation,
) -> xr.Dataset:
    """phase/1 with phase W(k_t·x + p(x)) and magnitude 1 on a (z, y, x) grid."""
    z = 2.0 + spacing[0] * np.arange(shape[0])
    y = -3.0 + spacing[1] * np.arange(shape[1])
    x = 0.5 + spacing[2] * np.arange(shape[2])
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    points = np.stack([xx, yy, zz], -1).reshape(-1, 3)
    directions = np.eye(3)[:ntag]
    pert, _ = field(points)
    phase = wrap(points @ (K * directions).T + pert[:, None]).T.reshape(ntag, 1, *shape)
    dims = ("tag", "time", "z", "y", "x")
    ds = xr.Dataset(
        {
            "phase": (dims, phase, standard_attrs("phase")),
            "magnitude": (dims, np.ones_like(phase), standard_attrs("magnitude")),
        },
        coords={
            "tag": ("tag", ["x", "y", "z"][:ntag], standard_attrs("tag")),
            "axis": ("axis", ["x", "y", "z"], standard_attrs("axis")),
            "tag_direction": (("tag", "axis"), directions, standard_attrs("tag_direction")),
            "tag_frequency": ("tag", [FREQ] * ntag, standard_attrs("tag_frequency")),
            "slice_axis": ("tag", ["z", "z", "y"][:ntag], standard_attrs("slice_axis")),
            "time": ("time", [0.0], standard_attrs("time")),
            "z": ("z", z, standard_attrs("z")),
            "y": ("y", y, standard_attrs("y")),
            "x": ("x", x, standard_attrs("x")),
        },
        attrs={"harpx_schema": "phase/1", "sequence": "CSPAMM", "upsample": 1, "radius": 0.5},
    )
    validate(ds)
    return ds


def expected(ds: xr.Dataset, p: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    ntag = ds.sizes["tag"]
    k = K * np.eye(3)[:ntag]
    pert, grad = _perturbation(p)
    return wrap(p @ k.T + pert[:, None]), k[None] + grad[:, None, :]


def random_points(
    ds: xr.Dataset, rng: np.random.Generator, n: int, margin: int = 3
) -> NDArray[np.float64]:
    """Uniform points at least `margin` voxels inside the field of view."""
    lo = np.array([float(ds[a][margin]) if ds.sizes[a] > 1 else float(ds[a][0]) for a in "xyz"])
    hi = np.array(
        [float(ds[a][-1 - margin]) if ds.sizes[a] > 1 else float(ds[a][0]) for a in "xyz"]
    )
    return lo + (hi - lo) * rng.random((n, 3))


def test_analytic_phase_and_gradient_3d(rng: np.random.Generator) -> None:
    ds = phase_dataset()
    points = random_points(ds, rng, 2000)
    phi, grad, valid = PhaseSampler(ds, 0).sample(points)
    phi_true, grad_true = expected(ds, points)
    assert valid.all()
    # cubic spline of the smooth demodulated image: O(h^4) error (measured ~3e-5 rad)
    phase_error = np.abs(wrap(phi - phi_true)).max()
    assert phase_error < 1e-3, f"max phase error {phase_error:.2e} rad"
    # its exact derivative: O(h^3) error (measured ~1e-4 rad/mm)
    grad_error = np.abs(grad - grad_true).max()
    assert grad_error < 1e-3 * K, f"max gradient error {grad_error:.2e} rad/mm"
    assert phi.min() >= -np.pi and phi.max() < np.pi


def test_analytic_near_edges_is_still_close(rng: np.random.Generator) -> None:
    ds = phase_dataset()
    points = random_points(ds, rng, 2000, margin=0)
    phi, grad, valid = PhaseSampler(ds, 0).sample(points)
    phi_true, grad_true = expected(ds, points)
    assert valid.all()
    # odd-reflection extension keeps edge errors second order (measured 1.84e-3 rad and
    # 4.7e-3 rad/mm; bounded 25 % above)
    assert np.abs(wrap(phi - phi_true)).max() < 2.3e-3
    assert np.abs(grad - grad_true).max() < 5.9e-3


def test_analytic_single_slice_2d(rng: np.random.Generator) -> None:
    ds = phase_dataset(shape=(1, 30, 32), ntag=2)
    points = random_points(ds, rng, 2000)
    points[:, 2] = rng.uniform(-50, 50, len(points))  # a single slice: z is ignored
    phi, grad, valid = PhaseSampler(ds, 0).sample(points)
    on_slice = points.copy()
    on_slice[:, 2] = float(ds.z[0])
    phi_true, grad_true = expected(ds, on_slice)
    assert valid.all()
    assert np.abs(wrap(phi - phi_true)).max() < 1e-3  # as in 3D: O(h^4)
    assert np.abs(grad[..., :2] - grad_true[..., :2]).max() < 1e-3 * K  # O(h^3)
    assert np.all(grad[..., 2] == 0)  # invariant along the single-slice axis


def test_wrap_line_is_exact(rng: np.random.Generator) -> None:
    """Points straddling the π → -π jump: no 2π blow-up (naive interpolation has one)."""
    ds = phase_dataset(ntag=1)
    base = random_points(ds, rng, 400)
    # move each point along x onto the nearest wrap line (k x + p(x) = π mod 2π), then
    # offset it by up to half a voxel on either side
    for _ in range(20):  # Newton on the 1D phase along x
        phi, grad = expected(ds, base)
        base[:, 0] -= wrap(phi[:, 0] - np.pi) / grad[:, 0, 0]
    points = base + np.c_[rng.uniform(-0.5, 0.5, len(base)), np.zeros((len(base), 2))]
    phi, grad, valid = PhaseSampler(ds, 0).sample(points)
    phi_true, grad_true = expected(ds, points)
    assert valid.all()
    assert np.abs(wrap(phi - phi_true)).max() < 1e-3  # same bound as anywhere else
    assert np.abs(grad - grad_true).max() < 1e-3 * K
    # the points really straddle a wrap: interpolating wrapped phase directly fails there
    u = (points[:, ::-1] - [float(ds.z[0]), float(ds.y[0]), float(ds.x[0])]) / [1.5, 1.0, 1.0]
    naive = ndimage.map_coordinates(ds.phase.values[0, 0], u.T, order=3, mode="mirror")
    assert np.abs(wrap(naive - phi_true[:, 0])).max() > 1.0


def test_outside_fov_masked_and_faded_points_are_invalid() -> None:
    ds = phase_dataset(shape=(6, 12, 14), ntag=2)
    mask = np.ones((2, 6, 12, 14), bool)
    mask[1, :, :, :3] = False  # tag "y" has no data in the first 3 x columns
    magnitude = ds.magnitude.values.copy()
    magnitude[0, 0, :, 8:, :] = 0.0  # tag "x" has faded for y rows >= 8
    ds = ds.assign(
        mask=(("tag", "z", "y", "x"), mask, standard_attrs("mask")),
        magnitude=ds.magnitude.copy(data=magnitude),
    )
    x0, y0, z0 = float(ds.x[0]), float(ds.y[0]), float(ds.z[0])
    points = np.array(
        [
            [x0 + 6.2, y0 + 3.1, z0 + 2.0],  # inside everything
            [x0 - 0.5, y0 + 3.1, z0 + 2.0],  # left of the first voxel centre
            [x0 + 6.2, y0 + 3.1, z0 + 99.0],  # above the last slice
            [np.nan, y0 + 3.1, z0 + 2.0],  # not a number
            [x0 + 1.0, y0 + 3.1, z0 + 2.0],  # outside the mask of tag "y"
            [x0 + 6.2, y0 + 10.0, z0 + 2.0],  # below the magnitude floor of tag "x"
            [x0 + 13.0, y0 + 11.0, z0 + 7.5],  # the far corner voxel centre (inside)
        ]
    )
    phi, grad, valid = PhaseSampler(ds, 0).sample(points)
    assert valid.tolist() == [True, False, False, False, False, False, False]
    assert np.all(phi[~valid] == 0) and np.all(grad[~valid] == 0)
    corner = PhaseSampler(ds.drop_vars("mask").assign(magnitude=xr.ones_like(ds.magnitude)), 0)
    assert corner.sample(points[-1:])[2].tolist() == [True]
    # per tag: the point outside tag "y"'s mask keeps tag "x"; a faded tag still voids
    # every tag of its point (no tissue signal there), as does leaving the field of view
    phi_t, grad_t, valid_t = PhaseSampler(ds, 0).sample(points, per_tag=True)
    assert valid_t.tolist() == [[True, True], [False, False], [False, False], [False, False],
                                [True, False], [False, False], [False, False]]  # fmt: skip
    np.testing.assert_array_equal(phi_t[valid], phi[valid])
    assert phi_t[4, 1] == 0 and np.all(grad_t[4, 1] == 0) and np.any(grad_t[4, 0] != 0)
    # the acquisition alone (field of view and masks): faded tissue is still acquired
    assert PhaseSampler(ds, 0).acquired(points).tolist() == [
        [True, True], [False, False], [False, False], [False, False],
        [True, False], [True, True], [True, True]]  # fmt: skip


def test_linear_order_is_second_order(rng: np.random.Generator) -> None:
    ds = phase_dataset()
    points = random_points(ds, rng, 1000)
    phi, grad, _ = PhaseSampler(ds, 0, order=1).sample(points)
    phi_true, grad_true = expected(ds, points)
    # trilinear: h^2/8 |D''| ~ 1e-2 rad at h = 1.5 mm (measured 5.5e-3); slope O(h) ~ 1e-2
    # (measured 8.9e-3 rad/mm); bounded 25 % above
    assert np.abs(wrap(phi - phi_true)).max() < 6.9e-3
    assert np.abs(grad - grad_true).max() < 1.1e-2


@pytest.mark.parametrize("shape", [(10, 26, 28), (1, 30, 32)], ids=["3d", "single-slice"])
def test_linear_order_is_the_linear_interpolant_of_the_demodulated_harmonic(
    rng: np.random.Generator, shape: tuple[int, int, int]
) -> None:
    # independent truth: scipy's linear interpolation of D = exp(i (φ − k·x)) on the voxel
    # centres, remodulated; its gradient by central differences, exact inside a cell (the
    # interpolant is linear along each axis there) up to rounding
    ds = phase_dataset(shape=shape, ntag=2)
    points = random_points(ds, rng, 500)
    origin = np.array([float(ds[a][0]) for a in "zyx"])
    step = np.array([1.5, 1.0, 1.0])
    active = [a for a in range(3) if shape[a] > 1]
    h = 1e-4  # mm
    frac = ((points[:, ::-1] - origin) / step)[:, active] % 1.0
    points = points[np.all((frac > 2 * h) & (frac < 1 - 2 * h), axis=1)]  # off the faces
    if shape[0] == 1:
        points[:, 2] = float(ds.z[0])
    phi, grad, valid = PhaseSampler(ds, 0, order=1).sample(points)
    zz, yy, xx = np.meshgrid(*(ds[a].values for a in "zyx"), indexing="ij")
    voxels = np.stack([xx, yy, zz], -1)

    def interpolated(p: NDArray[np.float64]) -> NDArray[np.float64]:
        u = ((p[:, ::-1] - origin) / step)[:, active].T
        out = []
        for t in range(2):
            k = K * np.eye(3)[t]
            D = np.exp(1j * (ds.phase.values[t, 0] - voxels @ k)).reshape(
                [shape[a] for a in active]
            )
            lin = ndimage.map_coordinates(D.real, u, order=1) + 1j * ndimage.map_coordinates(
                D.imag, u, order=1
            )
            out.append(np.angle(lin) + p @ k)
        return np.stack(out, -1)

    truth = interpolated(points)
    slope = np.zeros_like(grad)
    for c in (0, 1, 2) if shape[0] > 1 else (0, 1):
        e = np.zeros(3)
        e[c] = h
        slope[..., c] = wrap(interpolated(points + e) - interpolated(points - e)) / (2 * h)
    assert valid.all() and len(points) > 400
    assert np.abs(wrap(phi - truth)).max() < 1e-9
    assert np.abs(grad - slope).max() < 1e-6 * K  # central differences: rounding ~1e-12 / h


def test_magnitude_and_reference_phase(rng: np.random.Generator) -> None:
    ds = phase_dataset(ntag=2)
    points = random_points(ds, rng, 100)
    sampler = PhaseSampler(ds, 0)
    magnitude, valid = sampler.magnitude(points)
    assert valid.all()
    np.testing.assert_allclose(magnitude, 1.0, atol=1e-3)  # |exp(i p)| interpolated, O(h^4)
    phi0, valid0 = reference_phase(ds, points)
    phi, _, _ = sampler.sample(points)
    # same spline, a differently shaped matmul (value only): floating-point identity
    np.testing.assert_allclose(phi0, phi, rtol=0, atol=1e-12)
    assert valid0.all()


def test_dask_backed_dataset_gives_the_same_answer(rng: np.random.Generator) -> None:
    ds = phase_dataset(ntag=2)
    lazy = ds.chunk({"z": 2})
    assert isinstance(lazy.phase.data, da.Array)
    points = random_points(ds, rng, 50)
    for eager, from_lazy in zip(
        PhaseSampler(ds, 0).sample(points), PhaseSampler(lazy, 0).sample(points), strict=True
    ):
        np.testing.assert_array_equal(eager, from_lazy)  # same numbers after compute: exact


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        pytest.param(
            lambda ds: PhaseSampler(ds, 3),
            IndexError,
            "time_index=3 is out of range for 1 frames",
            id="time-index",
        ),
        pytest.param(
            lambda ds: PhaseSampler(ds, 0, order=2),
            ValueError,
            "order=2 is not supported",
            id="order",
        ),
        pytest.param(
            lambda ds: PhaseSampler(ds.drop_vars("magnitude"), 0),
            SchemaError,
            "missing data variable 'magnitude'",
            id="no-magnitude",
        ),
        pytest.param(
            lambda ds: PhaseSampler(ds, 0).sample(np.zeros((4, 2))),
            ValueError,
            r"points must have shape \(n, 3\)",
            id="points-shape",
        ),
    ],
)
def test_bad_input(call: Callable[[xr.Dataset], object], error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        call(phase_dataset(shape=(3, 6, 6), ntag=1))


@given(a=st.floats(-1e6, 1e6), turns=st.integers(-1000, 1000))
def test_wrap_range_and_periodicity(a: float, turns: int) -> None:
    w = wrap(a)
    assert -np.pi <= w < np.pi
    # float rounding of a + 2πk grows with |a + 2πk| (~1e-9 here); W is 2π-periodic
    assert abs(wrap(wrap(a + 2 * np.pi * turns) - w)) < 1e-8


def test_float32_phase_samples_like_float64():
    # extract_phase returns float32 by default; the sampler must give the float64 answer to
    # float32 resolution: the demodulation argument φ − W(k·x) stays within a few π, so
    # its float32 rounding is ~1e-6 rad (k·x alone reaches ~60 rad on this grid)
    from harpx.imaging.harp import extract_phase
    from harpx.imaging.synth import synthesize_tagged

    def motion(X, t):
        return 0.5 * t / 100 * np.sin(X[:, [1, 2, 0]] / 5)

    tagged = synthesize_tagged(motion, shape=(8, 24, 20), spacing=(1.5,) * 3,
                               times=[0.0, 100.0], tag_period=6.0, snr=20.0, oversample=1,
                               rng=0)  # fmt: skip
    single = extract_phase(tagged)
    double = extract_phase(tagged, dtype="float64")
    assert single.phase.dtype == np.float32
    pts = np.random.default_rng(0).uniform([-14, -17, -5], [14, 17, 5], (500, 3))
    for order in (3, 1):
        # the spline coefficients keep the data's precision (half the memory traffic)
        fast, exact = PhaseSampler(single, 1, order=order), PhaseSampler(double, 1, order=order)
        assert fast._padded is not None and fast._padded.dtype == np.float32
        assert exact._padded is not None and exact._padded.dtype == np.float64
        a, b = fast.sample(pts), exact.sample(pts)
        assert a[2].mean() > 0.9 and np.array_equal(a[2], b[2])
        assert np.abs(wrap(a[0] - b[0])).max() < 2e-5
        assert np.abs(a[1] - b[1]).max() < 2e-4 * np.abs(b[1]).max()


@pytest.mark.parametrize(("order", "tol"), [(3, 1e-9), (1, 0.0)])
def test_region_samples_like_the_whole_grid(
    rng: np.random.Generator, order: int, tol: float
) -> None:
    # a 60 x 64 x 4 grid, a 10 x 10 mm box: inside the box the cropped spline
    # differs from the whole grid's by ~0.268**20 of the data (the prefilter's decay over
    # the 20-voxel margin); trilinear taps need no margin and agree exactly
    ds = phase_dataset(shape=(4, 64, 60), spacing=(1.5, 1.0, 1.0))
    box = np.array([[30.0, 30.0, 2.0], [40.0, 40.0, 6.5]])
    points = box[0] + (box[1] - box[0]) * rng.random((400, 3))
    whole = PhaseSampler(ds, 0, order=order)
    part = PhaseSampler(ds, 0, order=order, region=box)
    assert part._padded is not None and whole._padded is not None
    assert part._padded.size < 0.8 * whole._padded.size  # less is prepared
    for a, b in zip(whole.sample(points), part.sample(points), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=tol)
    # a point in the field of view but beyond the box's 20-voxel margin is not sampled
    far = np.array([[0.6, -2.9, 2.0]])
    assert whole.acquired(far).all() and not part.acquired(far).any()
    assert not part.sample(far)[2].any()
    with pytest.raises(ValueError, match="region must be a finite"):
        PhaseSampler(ds, 0, region=[[0.0, 0.0, np.nan], [1.0, 1.0, 1.0]])


def test_outside_window_counts_points_a_whole_grid_sampler_would_sample() -> None:
    ds = phase_dataset()  # x 0.5 .. 27.5, y -3 .. 22, z 2 .. 15.5 mm
    box = np.array([[5.0, 0.0, 5.0], [10.0, 8.0, 9.0]])
    points = np.array([[7.0, 4.0, 7.0], [20.0, 4.0, 7.0], [7.0, 4.0, 40.0], [-9.0, 4.0, 7.0]])
    # in the box; in the grid beyond the box; beyond the grid along z; beyond it along x
    windowed = PhaseSampler(ds, 0, order=1, region=box)
    assert windowed.outside_window(points) == 1
    assert windowed.phase(points)[1].tolist() == [True, False, False, False]
    assert PhaseSampler(ds, 0, order=1).outside_window(points) == 0


def test_float32_region_keeps_a_margin_to_float32_resolution(rng: np.random.Generator) -> None:
    # float32 coefficients: a 13-voxel margin (0.268**13 ~ 4e-8 of the data) is below their
    # resolution, so the cropped spline samples like the whole grid's to float32 rounding
    double = phase_dataset(shape=(4, 64, 60), spacing=(1.5, 1.0, 1.0))
    ds = double.assign(
        phase=double.phase.astype(np.float32), magnitude=double.magnitude.astype(np.float32)
    )
    box = np.array([[30.0, 30.0, 2.0], [40.0, 40.0, 6.5]])
    points = box[0] + (box[1] - box[0]) * rng.random((400, 3))
    whole, part = PhaseSampler(ds, 0), PhaseSampler(ds, 0, region=box)
    assert part._padded is not None and part._padded.dtype == np.float32
    (phi_w, grad_w, ok_w), (phi_p, grad_p, ok_p) = whole.sample(points), part.sample(points)
    assert ok_w.all() and np.array_equal(ok_w, ok_p)
    assert np.abs(wrap(phi_w - phi_p)).max() < 2e-6
    assert np.abs(grad_w - grad_p).max() < 2e-6 * np.abs(grad_w).max()
    # the window reaches 13 voxels beyond the box, not 20 as for float64 data
    assert part._lo[-1] == PhaseSampler(double, 0, region=box)._lo[-1] + 7


def test_reuse_gives_the_same_samples_and_retires_the_old_sampler(
    rng: np.random.Generator,
) -> None:
    ds = phase_dataset(ntag=2)
    points = random_points(ds, rng, 200)
    first = PhaseSampler(ds, 0)
    expected_samples = PhaseSampler(ds, 0).sample(points)
    second = PhaseSampler(ds, 0, reuse=first)
    assert second._padded is not None and second._padded.base is not None  # first's memory
    for a, b in zip(expected_samples, second.sample(points), strict=True):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(RuntimeError, match="handed its buffers"):
        first.sample(points)
