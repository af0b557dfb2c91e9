"""Tests of synthetic tagged-image formation (harpx.imaging.synth)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.errors import ConvergenceError
from harpx.imaging.motion import gridded_displacement, invert_motion
from harpx.imaging.synth import synthesize_tagged
from harpx.schema import validate
from tests._helpers import shear, still

PERIOD = 7.0


def swirl(X, t):
    """Rotation about z by up to 80 degrees: |grad u| > 1, the plain fixed point diverges."""
    angle = np.deg2rad(80.0) * t / 100.0 * np.exp(-(X[:, 0] ** 2 + X[:, 1] ** 2) / 2000.0)
    c, s = np.cos(angle), np.sin(angle)
    u = np.zeros_like(X)
    u[:, 0] = (c - 1) * X[:, 0] - s * X[:, 1]
    u[:, 1] = s * X[:, 0] + (c - 1) * X[:, 1]
    return u


def disk(X):
    return (np.hypot(X[:, 0], X[:, 1]) <= 14.0).astype(float)


def voxel_centres(ds):
    z, y, x = np.meshgrid(ds.z.values, ds.y.values, ds.x.values, indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


def test_dataset_follows_the_tagged_schema():
    ds = synthesize_tagged(
        shear,
        shape=(4, 16, 16),
        spacing=(2.0, 2.0, 2.0),
        times=[0.0, 50.0],
        body=disk,
        oversample=1,
        rng=0,
    )
    validate(ds, "tagged")
    assert ds.image.dims == ("tag", "time", "z", "y", "x")
    assert list(ds.slice_axis.values) == ["z", "z", "y"]
    np.testing.assert_array_equal(ds.tag_direction.values, np.eye(3))
    # default origin centres the grid on 0
    np.testing.assert_allclose(ds.x.values, (np.arange(16) - 7.5) * 2.0)
    assert ds.mask.dtype == bool and ds.mask.dims == ("tag", "z", "y", "x")


def test_displacement_true_is_u_at_voxel_centres():
    ds = synthesize_tagged(
        shear,
        shape=(4, 16, 16),
        spacing=(2.0, 2.0, 2.0),
        times=[0.0, 60.0],
        body=disk,
        oversample=1,
        snr=None,
    )
    pts = voxel_centres(ds)
    inside = ds.body.values.ravel() >= 0.5
    for n, t in enumerate(ds.time.values):
        truth = ds.displacement_true.isel(time=n).values.reshape(3, -1).T
        # same formula evaluated at the same points: exact
        np.testing.assert_array_equal(truth[inside], shear(pts[inside], t))
        assert np.isnan(truth[~inside]).all()


@pytest.mark.parametrize("motion", [shear, swirl], ids=["shear", "swirl-80deg"])
def test_numerical_inverse_satisfies_the_motion(motion, rng):
    x = rng.uniform(-25.0, 25.0, size=(5000, 3))
    X = invert_motion(motion, x, 100.0)
    # requirement 1e-6 mm; the iteration stops at 1e-9 mm
    np.testing.assert_allclose(X + motion(X, 100.0), x, rtol=0, atol=1e-6)


def test_inversion_failure_is_reported():
    def no_preimage(X, t):  # x = X + X² + 10 has no real solution X for x < 9.75
        u = np.zeros_like(X)
        u[:, 0] = X[:, 0] ** 2 + 10.0
        return u

    with pytest.raises(ConvergenceError, match="inverse=") as info:
        invert_motion(no_preimage, np.zeros((4, 3)), 1.0, max_iter=20)
    assert len(info.value.history) == 20


def test_noise_free_cspamm_signal_and_t1_fading():
    ds = synthesize_tagged(
        still,
        shape=(2, 8, 12),
        spacing=(2.0, 1.5, 1.5),
        times=[0.0, 300.0],
        tags=("x",),
        snr=None,
        oversample=1,
        flip_angle=60.0,
    )
    x = ds.x.values[None, None, :]
    beta = np.deg2rad(60.0)
    expected = 2 * np.sin(beta) ** 2 * np.cos(2 * np.pi * x / 8.0)  # default period 8 mm
    for n, t in enumerate([0.0, 300.0]):
        # closed form at voxel centres (oversample 1): rounding only
        np.testing.assert_allclose(
            ds.image.isel(tag=0, time=n).values,
            np.broadcast_to(expected * np.exp(-t / 850.0), (2, 8, 12)),
            rtol=0,
            atol=1e-12,
        )


def test_spamm_magnitude_has_dc_and_relaxation():
    ds = synthesize_tagged(
        still,
        shape=(2, 8, 12),
        spacing=(2.0, 1.5, 1.5),
        times=[0.0, 400.0],
        tags=("x",),
        sequence="SPAMM",
        snr=None,
        oversample=1,
    )
    theta = 2 * np.pi * ds.x.values / 8.0
    fade = np.exp(-400.0 / 850.0)
    # 1-1 SPAMM with beta = 45°: (1 + cos)/2 at t = 0, relaxing towards 1 (rounding only)
    np.testing.assert_allclose(ds.image.values[0, 0, 0, 0], (1 + np.cos(theta)) / 2, atol=1e-12)
    np.testing.assert_allclose(
        ds.image.values[0, 1, 0, 0], (1 + np.cos(theta)) / 2 * fade + 1 - fade, atol=1e-12
    )


def test_partial_volume_averages_subsamples():
    n = 4
    ds = synthesize_tagged(
        still,
        shape=(2, 4, 16),
        spacing=(2.0, 2.0, 1.5),
        times=[0.0],
        tags=("x",),
        tag_period=6.0,
        snr=None,
        oversample=n,
    )
    k = 2 * np.pi / 6.0
    offsets = 1.5 * ((np.arange(n) + 0.5) / n - 0.5)
    # mean of cos(k(x + o)) over symmetric offsets = cos(kx) * mean(cos(k o)): exact identity
    expected = 2 * np.cos(k * ds.x.values) * np.mean(np.cos(k * offsets))
    np.testing.assert_allclose(ds.image.values[0, 0, 1, 2], expected, atol=1e-12)


def test_slice_profile_integrates_over_the_thickness():
    def half_space(X):
        return (X[:, 2] <= 0.0).astype(float)

    common = dict(
        shape=(4, 8, 8),
        spacing=(2.0, 1.5, 1.5),
        times=[0.0],
        tags=("x",),
        snr=None,
        oversample=2,
        body=half_space,
    )
    thin = synthesize_tagged(still, **common)
    thick = synthesize_tagged(still, slice_thickness=4.0, **common)
    ratio = thick.image.values[0, 0] / thin.image.values[0, 0, 1]  # slice 1 is fully inside
    # slices centred at z = -1 and z = +1 mm: a 4 mm boxcar holds 3/4 and 1/4 tissue
    np.testing.assert_allclose(ratio[1], 0.75, atol=1e-12)
    np.testing.assert_allclose(ratio[2], 0.25, atol=1e-12)
    np.testing.assert_allclose(thin.image.values[0, 0, 2], 0.0, atol=1e-12)


def test_kspace_truncation_removes_high_frequencies(rng):
    ds = synthesize_tagged(
        still,
        shape=(2, 32, 32),
        spacing=(1.5, 1.5, 1.5),
        times=[0.0],
        tags=("x",),
        snr=None,
        oversample=1,
        kspace_fraction=0.5,
        body=disk,
    )
    spec = np.abs(np.fft.fft2(ds.image.values[0, 0]))
    q = np.abs(np.fft.fftfreq(32))
    outside = (q[:, None] > 0.25) | (q[None, :] > 0.25)
    # energy beyond the kept quarter of the spectrum is rounding noise only
    assert spec[:, outside].max() < 1e-10 * spec.max()
    assert spec[:, ~outside].max() > 0.1 * spec.max()


def test_cspamm_noise_matches_snr():
    common = dict(
        shape=(8, 32, 32),
        spacing=(1.5, 1.5, 1.5),
        times=[0.0, 100.0],
        snr=20.0,
        oversample=1,
        body=disk,
    )
    clean = synthesize_tagged(still, **{**common, "snr": None})
    noisy = synthesize_tagged(still, rng=3, **common)
    sigma = 2.0 / 20.0  # peak 2 sin²(90°) over SNR
    measured = float(np.std(noisy.image.values - clean.image.values))
    # 49k samples: the std estimate has a relative standard error of 0.3%; 5% allowed
    assert abs(measured / sigma - 1) < 0.05, f"measured sigma {measured:.4f}, expected {sigma}"
    assert noisy.attrs["noise_sigma"] == pytest.approx(sigma)


def test_spamm_noise_is_rician_and_non_negative():
    ds = synthesize_tagged(
        still,
        shape=(8, 32, 32),
        spacing=(1.5, 1.5, 1.5),
        times=[0.0, 100.0],
        snr=20.0,
        sequence="SPAMM",
        oversample=1,
        body=disk,
        rng=4,
    )
    image = ds.image.values
    assert image.min() >= 0.0
    background = image[:, :, ~(ds.body.values > 0)]
    sigma = 1.0 / 20.0
    # background is |complex Gaussian|: E[M²] = 2σ²; 60k samples, relative error < 1%
    measured = float(np.sqrt(np.mean(background**2) / 2))
    assert abs(measured / sigma - 1) < 0.05, f"measured sigma {measured:.4f}, expected {sigma}"
    # and Rayleigh-shaped: mean = σ sqrt(π/2) within 5%
    assert abs(background.mean() / (sigma * np.sqrt(np.pi / 2)) - 1) < 0.05


def test_gridded_displacement_matches_the_callable_on_its_grid():
    ds = synthesize_tagged(
        shear,
        shape=(4, 16, 16),
        spacing=(2.0, 2.0, 2.0),
        times=[0.0, 50.0, 100.0],
        oversample=1,
        snr=None,
    )
    field = ds.displacement_true  # no body: finite everywhere
    u = gridded_displacement(field)
    pts = voxel_centres(ds)
    # trilinear interpolation at grid nodes and at frame times reproduces the nodes exactly
    np.testing.assert_allclose(u(pts, 100.0), shear(pts, 100.0), atol=1e-12)
    np.testing.assert_allclose(
        u(pts, 75.0), 0.5 * (shear(pts, 50.0) + shear(pts, 100.0)), atol=1e-12
    )
    again = synthesize_tagged(
        field,
        shape=(4, 16, 16),
        spacing=(2.0, 2.0, 2.0),
        times=[0.0, 50.0, 100.0],
        oversample=1,
        snr=None,
    )
    xr.testing.assert_allclose(again.displacement_true, ds.displacement_true, atol=1e-12)


def test_explicit_directions_and_slice_axes():
    ds = synthesize_tagged(
        still,
        shape=(4, 8, 8),
        spacing=(2.0, 2.0, 2.0),
        times=[0.0],
        tags=([1.0, 1.0, 0.0], "z"),
        tag_period=[6.0, 8.0],
        snr=None,
        oversample=1,
    )
    assert list(ds.tag.values) == ["tag0", "z"]
    assert list(ds.slice_axis.values) == ["z", "y"]
    np.testing.assert_allclose(ds.tag_direction.values[0], [2**-0.5, 2**-0.5, 0.0])
    np.testing.assert_allclose(ds.tag_frequency.values, [1 / 6.0, 1 / 8.0])
    validate(ds, "tagged")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"tags": ("x",), "slice_axis": "x"}, "slice_axis", id="tag-along-slice"),
        pytest.param({"times": [10.0, 5.0]}, "'times'", id="times-decreasing"),
        pytest.param({"oversample": 0}, "'oversample'", id="oversample"),
        pytest.param({"kspace_fraction": 1.5}, "'kspace_fraction'", id="kspace"),
        pytest.param({"sequence": "DENSE"}, "'sequence'", id="sequence"),
        pytest.param({"tags": ("w",)}, "tag 'w'", id="tag-name"),
        pytest.param({"shape": (4, 8)}, "'shape'", id="shape"),
    ],
)
def test_bad_arguments(kwargs, match):
    args = dict(shape=(4, 8, 8), spacing=(2.0, 2.0, 2.0), times=[0.0], snr=None, oversample=1)
    with pytest.raises(ValueError, match=match):
        synthesize_tagged(still, **{**args, **kwargs})


def test_motion_must_start_at_the_reference():
    def moved(X, t):
        return np.ones_like(X)

    with pytest.raises(ValueError, match="reference frame"):
        synthesize_tagged(moved, shape=(2, 4, 4), spacing=(2, 2, 2), times=[0.0], oversample=1)
