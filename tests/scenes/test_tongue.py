"""Tongue scene end to end: images, tracking, activation estimate per muscle (paper §4.3)."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from harpx.inverse import (
    ACTIVATION_TRACKING,
    calibrate_activation,
    correct_activation,
    estimate_activation,
    resimulate,
)
from harpx.scenes.tongue import ACTIVATIONS, tongue
from harpx.schema import validate
from harpx.tracking.results import tracking_error


@pytest.fixture(scope="module")
def scene():
    return tongue("small")  # reduced ground-truth mesh so the test is fast


@pytest.fixture(scope="module")
def body(scene):
    return scene.body()


@pytest.fixture(scope="module")
def tracked(scene, body):
    # the activation chain's settings: the defaults with the target at twice the floor
    return scene.track(body, settings=ACTIVATION_TRACKING)


@pytest.fixture(scope="module")
def estimates(scene, body, tracked):
    bcs = list(scene.dirichlet)
    direct = estimate_activation(tracked, body)
    corrected = correct_activation(direct, tracked, body, dirichlet=bcs)
    calibrated = calibrate_activation(
        corrected,
        tracked,
        body,
        measure=partial(scene.measure, settings=ACTIVATION_TRACKING),
        dirichlet=bcs,
    )
    return direct, corrected, calibrated


def test_images_follow_the_schema_and_the_tongue_moves_a_few_mm(scene):
    ds = scene.tagged
    validate(ds, "tagged")
    assert ds.attrs["sequence"] == "CSPAMM"
    assert ds.attrs["coronal_slices"] == 10 and ds.attrs["sagittal_slices"] == 8
    assert list(ds.slice_axis.values) == ["y", "x", "x"]  # x tag sagittal; y, z coronal
    np.testing.assert_allclose(np.diff(ds.x.values), 1.9, rtol=1e-9)
    u = ds.displacement_true.isel(time=-1)
    magnitude = np.sqrt((u**2).sum("axis", skipna=False))
    inside = ds.body.values >= 0.5
    # NaN only in boundary voxels whose centre lies just outside the fine polyhedron
    assert np.isfinite(magnitude.values[inside]).mean() > 0.95
    assert np.all(np.isnan(magnitude.values[ds.body.values == 0]))
    # a retraction of a few mm (the tip moves most)
    assert 4.0 < float(magnitude.max()) < 12.0, float(magnitude.max())
    rest = ds.displacement_true.isel(time=0).values[:, inside]
    np.testing.assert_array_equal(rest[np.isfinite(rest)], 0.0)  # frame 0 is the reference


def test_tracking_reaches_epsilon_with_sub_voxel_error(scene, tracked):
    # the activation chain's target: twice the images' phase-noise floor (never below
    # 0.03 rad); measured floors 0.020-0.022 rad (SNR 20 CSPAMM), ε 0.036-0.039 rad, every
    # frame below its target itself (no plateau allowance used)
    assert tracked.target_reached.all(), tracked.epsilon.values
    eps, target = tracked.epsilon.values[1:], tracked.epsilon_target.values[1:]
    floor = tracked.epsilon_floor.values[1:]
    np.testing.assert_allclose(target, np.maximum(2.0 * floor, 0.03))
    assert np.all(floor > 0.017) and np.all(floor < 0.026), floor
    assert np.all(eps <= target) and not tracked.plateau.values.any(), eps
    # the tracked grid is the acquired grid, up to round-off in its coordinates: use the
    # tagged coordinates so that xarray aligns every voxel
    grid = {d: scene.tagged[d] for d in ("z", "y", "x")}
    assert all(np.allclose(tracked[d], grid[d], atol=1e-9) for d in grid)
    err = tracking_error(tracked.assign_coords(grid), scene.tagged)
    # SNR 20, 1.9 mm pixels, 7 mm between slices: measured 0.109 / 0.274 mm (mean / p95 over
    # frames; 0.085-0.129 mm mean per frame); bounds at measured × 1.2
    assert float(err.mean_all) < 1.2 * 0.109, err["mean"].values
    assert float(err.p95_all) < 1.2 * 0.274, err.p95.values
    assert float(err.coverage) > 0.99


def test_activation_estimate_per_muscle_is_within_15_percent(scene, estimates):
    direct, corrected, calibrated = estimates
    truth = np.array([scene.t_max[m] for m in calibrated.region.values])
    rel = calibrated.t_max.values / truth - 1.0
    # issue 5 must-show: every muscle within 15 %; measured -3 % (SL) to +11 % (V), bounded
    # at 1.2 × the largest
    assert np.all(np.abs(rel) <= 0.133), dict(
        zip(calibrated.region.values, rel.round(3), strict=True)
    )
    # the steps are what the docs say: the paper's local estimate is biased low (measured
    # 0.23-0.50 of the truth), the equilibrium correction removes part of it (0.63-0.78),
    # the calibration the rest (chain transfer measured 0.57-0.80)
    assert np.all(direct.t_max.values < 0.6 * truth), direct.t_max.values
    assert np.all(corrected.t_max.values > direct.t_max.values)
    assert np.all(
        (calibrated.chain_transfer.values > 0.47) & (calibrated.chain_transfer.values < 0.96)
    )


def test_resimulation_agrees_with_the_true_fibre_stretch(scene, body, tracked, estimates):
    _, _, calibrated = estimates
    sim = resimulate(body, calibrated.t_max, dirichlet=list(scene.dirichlet), tracked=tracked)
    truth = scene.true_stretch_by_muscle(body)
    diff = sim.stretch_simulated.values - np.array([truth[m] for m in sim.region.values])
    # mean fibre stretch per muscle: measured |diff| <= 0.0057 (V)
    assert np.all(np.abs(diff) < 0.0069), diff
    # element by element the re-simulation follows the tracked pattern (measured r = 0.885)
    assert float(sim.correlation_all) > 0.74
    # tracking smooths the shortening: the tracked stretch is closer to 1 than the truth
    assert np.all(sim.stretch_tracked.values > np.array([truth[m] for m in sim.region.values]))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"size": "huge"}, "size='huge'", id="size"),
        pytest.param({"activations": {"XX": 1.0}}, "'XX'", id="muscle"),
        pytest.param({"activations": {"GG": -1.0}}, "'GG'=-1.0", id="negative"),
    ],
)
def test_bad_arguments_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        tongue(**kwargs)


def test_default_activations_cover_every_muscle():
    assert sorted(ACTIVATIONS) == ["GG", "IL", "SL", "T", "V"]
