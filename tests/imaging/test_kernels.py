"""Tests of the numpy kernels of the harmonic-phase pipeline (_kernels and bandpass)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from harpx.imaging._kernels import (
    linear_weights,
    refine_linear,
    refine_positions,
    upsample_slices,
    wrap,
)
from harpx.imaging.bandpass import bandpass_mask, harmonic_images, harmonic_phase

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(a=finite, k=st.integers(min_value=-1000, max_value=1000))
def test_wrap_range_and_periodicity(a, k):
    w = float(wrap(a))
    assert -np.pi <= w < np.pi
    shifted = float(wrap(a + 2 * np.pi * k))
    # a + 2πk is rounded to the float grid: equality holds up to a few ulps of |a + 2πk|
    tol = 8 * np.finfo(float).eps * (abs(a) + abs(2 * np.pi * k) + 1.0)
    circular = abs(float(wrap(shifted - w)))
    assert circular <= tol


def test_wrap_maps_pi_to_minus_pi_and_is_identity_inside():
    np.testing.assert_array_equal(wrap([np.pi, -np.pi, 0.0]), [-np.pi, -np.pi, 0.0])
    inside = np.linspace(-np.pi, np.pi, 101)[:-1]
    np.testing.assert_allclose(wrap(inside), inside, rtol=0, atol=1e-15)  # exact up to rounding


def test_refined_grid_is_voxel_aligned():
    p = refine_positions(4, 3)
    # refined centres subdivide each native voxel [i - 1/2, i + 1/2] into 3 equal parts
    np.testing.assert_allclose(p[:3], [-1 / 3, 0.0, 1 / 3], atol=1e-15)
    np.testing.assert_allclose(p[-1], 3 + 1 / 3, atol=1e-15)
    np.testing.assert_allclose(np.diff(p), 1 / 3, atol=1e-15)
    i0, i1, w = linear_weights(4, 2)
    np.testing.assert_array_equal(i0, [0, 0, 0, 1, 1, 2, 2, 3])
    np.testing.assert_array_equal(i1, [0, 1, 1, 2, 2, 3, 3, 3])  # i1 == i0 where w == 0
    np.testing.assert_allclose(w, [0, 0.25, 0.75, 0.25, 0.75, 0.25, 0.75, 0])


@pytest.mark.parametrize("mode", ["reflect", "mirror", "grid-wrap"])
@pytest.mark.parametrize("factor", [2, 3, (2, 3)])
def test_upsample_matches_scipy_zoom(mode, factor, rng):
    slices = rng.standard_normal((3, 9, 11))
    ours = upsample_slices(slices, factor, mode=mode)
    zoom = factor if isinstance(factor, tuple) else (factor, factor)
    expected = np.stack([ndimage.zoom(s, zoom, order=3, grid_mode=True, mode=mode) for s in slices])
    # same spline, different evaluation order: agreement to rounding (1e-12 on O(1) values)
    np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("mode", ["mirror", "grid-wrap"])
def test_upsample_interpolates_native_samples(mode, rng):
    slices = rng.standard_normal((2, 7, 8))
    fine = upsample_slices(slices, 3, mode=mode)
    # with an odd factor every third refined centre is a native centre: the spline
    # interpolates, so those samples reproduce the input to rounding. (scipy's "reflect"
    # prefilter truncates its boundary initialisation at ~1e-8, so it is not used here.)
    np.testing.assert_allclose(fine[:, 1::3, 1::3], slices, rtol=0, atol=1e-12)


def test_upsample_converges_at_fourth_order():
    errors = []
    for n in (16, 32, 64):
        x = (np.arange(n) + 0.5) / n
        f = lambda s: np.sin(2 * np.pi * s) + 0.3 * np.cos(4 * np.pi * s)  # noqa: E731
        img = f(x)[:, None] * np.ones((1, 4))
        fine = upsample_slices(img, (2, 1), mode="grid-wrap")
        xf = (np.arange(2 * n) + 0.5) / (2 * n)
        errors.append(np.max(np.abs(fine[:, 0] - f(xf))))
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    # cubic splines interpolate smooth periodic data with O(h^4) error: rate 4 ± 0.3
    assert np.all(np.abs(rates - 4.0) < 0.3), f"observed rates {rates}"


def test_bandpass_mask_is_a_disk_at_the_tag_frequency():
    mask = bandpass_mask((32, 32), (1.0, 1.0), (0.0, 0.25), 0.1)
    q = np.fft.fftfreq(32)
    rows, cols = np.nonzero(mask)
    assert np.allclose(q[rows].mean(), 0.0) and np.allclose(q[cols].mean(), 0.25)
    assert mask.sum() == 37  # radius 3.2 bins on a 1/32 grid: 37 lattice points i²+j² <= 10.24
    assert not mask[0, 0]  # the DC peak is outside


@pytest.mark.parametrize(
    "freq", [(0.1, 0.15), (-0.1, 0.15), (0.1, -0.15), (0.0, 0.2)], ids=["pp", "mp", "pm", "axis"]
)
@pytest.mark.parametrize("upsample", [1, 2, 3, (2, 3)])
def test_spectral_upsampling_equals_spatial_upsampling_then_filter(freq, upsample, rng):
    slices = rng.standard_normal((4, 24, 20))
    spacing = (1.5, 1.2)
    ours = harmonic_images(slices, spacing, freq, 0.5, upsample=upsample)
    factors = upsample if isinstance(upsample, tuple) else (upsample, upsample)
    fine = upsample_slices(slices, factors, mode="grid-wrap")
    fine_spacing = (spacing[0] / factors[0], spacing[1] / factors[1])
    mask = bandpass_mask(fine.shape[-2:], fine_spacing, freq, 0.5 * np.hypot(*freq))
    expected = np.fft.ifft2(np.fft.fft2(fine) * mask)
    # the transfer function of periodic cubic-spline upsampling is exact: equal to rounding
    np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def test_harmonic_image_of_a_plane_wave(rng):
    n, d = 40, 1.5
    k = (2 / (n * d), 5 / (n * d))  # on the frequency grid: exact DFT peak
    y, x = np.meshgrid(np.arange(n) * d, np.arange(n) * d, indexing="ij")
    img = 3.0 * np.cos(2 * np.pi * (k[0] * y + k[1] * x)) + 1.0  # DC of SPAMM-like images
    h = harmonic_images(img, (d, d), k, 0.5, upsample=1)
    # a single spectral line: amplitude A/2 and phase 2π k·x exactly (rounding only)
    np.testing.assert_allclose(np.abs(h), 1.5, rtol=1e-12)
    np.testing.assert_allclose(wrap(np.angle(h) - 2 * np.pi * (k[0] * y + k[1] * x)), 0, atol=1e-12)


@pytest.mark.parametrize("slice_axis", [0, 1, 2])
@pytest.mark.parametrize("upsample", [(2, 2, 2), (1, 2, 3), (3, 1, 2)])
def test_harmonic_phase_interpolates_the_complex_image_between_slices(slice_axis, upsample, rng):
    volume = rng.standard_normal((2, 6, 10, 12))
    spacing, freq = (1.5, 1.2, 1.0), (0.1, 0.12, 0.15)
    phase, magnitude = harmonic_phase(
        volume, spacing=spacing, freq=freq, slice_axis=slice_axis, upsample=upsample, threads=1
    )
    inplane = [k for k in range(3) if k != slice_axis]
    moved = np.moveaxis(volume, 1 + slice_axis, -3)
    h = harmonic_images(
        moved,
        [spacing[k] for k in inplane],
        [freq[k] for k in inplane],
        0.5,
        upsample=[upsample[k] for k in inplane],
    )
    i0, i1, w = linear_weights(volume.shape[1 + slice_axis], upsample[slice_axis])
    fine = h[:, i0] * (1 - w)[:, None, None] + h[:, i1] * w[:, None, None]
    expected = np.moveaxis(fine, -3, 1 + slice_axis)
    # same arithmetic in another order: rounding-level agreement
    np.testing.assert_allclose(magnitude, np.abs(expected), rtol=0, atol=1e-13)
    big = np.abs(expected) > 1e-3  # the angle of a near-zero number is ill-conditioned
    np.testing.assert_allclose(wrap(phase - np.angle(expected))[big], 0, atol=1e-10)
    assert phase.min() >= -np.pi and phase.max() < np.pi


def test_harmonic_phase_threads_give_identical_results(rng):
    volume = rng.standard_normal((5, 4, 16, 16))
    kwargs = dict(spacing=(1.0, 1.0, 1.0), freq=(0.0, 0.1, 0.2), slice_axis=0, upsample=(2, 2, 2))
    one = harmonic_phase(volume, threads=1, **kwargs)
    two = harmonic_phase(volume, threads=2, **kwargs)
    # same plans per frame, frames merely spread over workers: bitwise equal
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])


def test_kernel_bad_input():
    img = np.ones((8, 8))
    with pytest.raises(ValueError, match="'upsample'"):
        harmonic_images(img, (1, 1), (0.1, 0.1), 0.5, upsample=0)
    with pytest.raises(ValueError, match="'radius'"):
        harmonic_images(img, (1, 1), (0.1, 0.1), 1.5)
    with pytest.raises(ValueError, match="non-zero"):
        harmonic_images(img, (1, 1), (0.0, 0.0), 0.5)
    with pytest.raises(ValueError, match="holds no frequency sample"):
        harmonic_images(img, (1, 1), (0.11, 0.11), 0.01)
    with pytest.raises(ValueError, match="'slice_axis'"):
        harmonic_phase(np.ones((2, 4, 4)), spacing=(1, 1, 1), freq=(0, 0, 0.2), slice_axis=3)


@pytest.mark.parametrize("factors", [(2, 2, 2), (1, 3, 2), (3, 1, 1), (1, 1, 1)])
def test_refine_linear_matches_weighted_neighbours(factors, rng):
    volume = rng.standard_normal((2, 5, 6, 7))
    volume[0, 2, 3, 4] = np.nan  # e.g. a voxel outside the body
    ours = refine_linear(volume, factors, threads=2)
    expected = volume
    for axis, m in zip((1, 2, 3), factors, strict=True):
        i0, i1, w = linear_weights(expected.shape[axis], m)
        shape = [1, 1, 1, 1]
        shape[axis] = -1
        expected = np.take(expected, i0, axis=axis) * (1 - w).reshape(shape) + np.take(
            expected, i1, axis=axis
        ) * w.reshape(shape)
    # same weights, other operation order: rounding only; NaN exactly where a neighbour
    # with non-zero weight is NaN
    np.testing.assert_array_equal(np.isnan(ours), np.isnan(expected))
    np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-13)
