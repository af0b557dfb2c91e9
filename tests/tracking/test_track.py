"""FE tracking with the phase constraint on ideal phase images of a lagged rotation."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.errors import HarpxWarning, SchemaError
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import cylinder
from harpx.scenes._motion import RotationalImpact
from harpx.schema import standard_attrs, validate
from harpx.tracking.results import tracking_error
from harpx.tracking.settings import SolverTuning, TrackingSettings
from harpx.tracking.track import track
from tests._ideal import ideal_phase

RADIUS, HEIGHT = 30.0, 12.0


def _inside(X: np.ndarray) -> np.ndarray:
    return ((np.hypot(X[:, 0], X[:, 1]) <= RADIUS) & (np.abs(X[:, 2]) <= HEIGHT / 2)).astype(float)


@pytest.fixture(scope="module")
def scene():
    # the edge turns 12 mm (1.5 tag periods) over the frames; coarse grid so the test is fast
    motion = RotationalImpact(radius=RADIUS, base=-HEIGHT / 2, height=HEIGHT, angle=12.0 / RADIUS)
    ds = ideal_phase(
        motion, shape=(7, 48, 48), spacing=(3.0, 1.5, 1.5), times=np.arange(5) * 18.0, body=_inside
    )
    mesh = cylinder(
        RADIUS, HEIGHT, n_radial=2, n_circumferential=16, n_axial=3, center=(0, 0, -HEIGHT / 2)
    )
    return ds, mesh


@pytest.fixture(scope="module")
def tracked(scene):
    ds, mesh = scene
    return track(ds, Body(mesh, NeoHookean(c1=1.0, kappa=120.0)), epsilon=0.05)


def test_tracked_dataset_follows_the_schema(tracked):
    validate(tracked, "tracked")
    assert tracked.displacement.dims == ("time", "node", "axis")
    assert tracked.green_strain.shape[1:] == (tracked.sizes["cell"], 3, 3)
    # the reference frame is not moved
    np.testing.assert_array_equal(tracked.displacement.isel(time=0).values, 0.0)


STAGES = ("time_phase", "time_setup", "time_first_pass", "time_blur", "time_correction_pass",
          "time_output")  # fmt: skip


def test_time_split_accounts_for_the_whole_run(tracked):
    times = {k: v for k, v in tracked.attrs.items() if k.startswith("time_")}
    parts = {k: v for k, v in times.items()
             if k not in ("time_first_pass", "time_correction_pass", "time_total")}  # fmt: skip
    assert set(parts) >= {"time_sampling", "time_assembly", "time_solve", "time_prefilter"}
    # the per-frame wall times cover set-up and frames; phase validation and output lie
    # outside them. What the parts leave out (Python between the timers) measured 0.7-1.1 %
    # of the run on an idle machine and 2.3 % on an oversubscribed one (Python 3.11 and
    # 3.13 alike): 3 % + 10 ms of slack
    total = float(tracked.wall_time.sum()) + parts["time_phase"] + parts["time_output"]
    assert abs(sum(parts.values()) - total) <= 0.03 * total + 0.01, (parts, total)
    # the stages add up to the whole call (the same slack)
    staged = sum(times[k] for k in STAGES)
    assert abs(times["time_total"] - staged) <= 0.02 * staged + 0.01, times
    assert times["time_correction_pass"] == 0.0  # a user-given epsilon: no correction pass


def test_penalty_reaches_epsilon_every_frame(tracked):
    eps = tracked.epsilon.values[1:]
    assert tracked.target_reached.all(), f"epsilon per frame {eps}"
    assert np.all(eps <= 0.05), f"epsilon per frame {eps}"


def test_error_against_truth_is_sub_voxel(tracked, scene):
    ds, _ = scene
    err = tracking_error(tracked, ds)
    # ideal phase: the error is the coarse 144-cell model's misfit of a lagged rotation with
    # 12 mm edge displacement (the requirement: 0.3 mm mean, 0.2 voxel; 1 mm p95); measured
    # 0.217 mm mean and 0.613 mm p95, bounded 20 % above so that a lost gain shows
    assert float(err.mean_all) < 0.26, err.mean.values
    assert float(err.p95_all) < 0.74, err.p95.values
    # no tag jumps: a jump would leave errors near a tag period (8 mm)
    assert float(err.max_all) < 2.0, err.max.values
    assert float(err.coverage) > 0.95


def test_augmented_lagrangian_reaches_epsilon(scene, tracked):
    ds, mesh = scene
    al = track(
        ds, Body(mesh, NeoHookean(c1=1.0, kappa=120.0)), method="augmented-lagrangian", epsilon=0.05
    )
    assert np.all(al.epsilon.values[1:] <= 0.05), al.epsilon.values
    err_al = float(tracking_error(al, ds).mean_all)
    err_pen = float(tracking_error(tracked, ds).mean_all)
    # both enforce the same ε on the same data: their errors agree to within 0.1 mm
    assert abs(err_al - err_pen) < 0.1, (err_al, err_pen)


def test_body_outside_the_images_is_a_clear_error(scene):
    ds, mesh = scene
    far = cylinder(5.0, 5.0, n_radial=1, n_circumferential=8, n_axial=1, center=(500.0, 0.0, 0.0))
    with pytest.raises(SchemaError, match="outside the image field of view"):
        track(ds, Body(far, NeoHookean(c1=1.0, kappa=120.0)))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"method": "newton"}, "method='newton'", id="method"),
        pytest.param({"epsilon": -1.0}, "epsilon=-1.0", id="epsilon"),
        pytest.param({"penalty": 0.0}, "penalty=0.0", id="penalty"),
        pytest.param({"ramp": 0}, "ramp=0", id="ramp"),
    ],
)
def test_bad_settings_are_named(scene, kwargs, match):
    ds, mesh = scene
    with pytest.raises(ValueError, match=match):
        track(ds, Body(mesh, NeoHookean(c1=1.0, kappa=120.0)), **kwargs)


def test_a_tag_masked_over_part_of_the_body_still_pulls_with_the_others(scene):
    ds, mesh = scene
    body = Body(mesh, NeoHookean(c1=1.0, kappa=120.0))
    # tag "y" acquired only for x < 0 (like a long-axis slab that misses part of the organ):
    # points at x >= 0 keep tags "x" and "z" instead of dropping out of the constraint
    mask = np.ones((ds.sizes["tag"], ds.sizes["z"], ds.sizes["y"], ds.sizes["x"]), bool)
    mask[list(ds.tag.values).index("y"), :, :, ds.x.values >= 0] = False
    partial = ds.assign(mask=(("tag", "z", "y", "x"), mask, standard_attrs("mask")))
    from harpx.tracking.constraint import PhaseConstraint

    valid = PhaseConstraint(body, partial).reference_valid
    share = valid.mean(axis=0)
    # x, z: all points inside the images; y: about half (measured in the assertion's terms)
    assert share[0] > 0.95 and share[2] > 0.95 and 0.3 < share[1] < 0.7, share
    out = track(partial, body, epsilon=0.05)
    assert out.target_reached.all()
    kept = float(tracking_error(out, ds).mean_all)
    # dropping those points altogether (every tag masked at x >= 0, the all-tags rule)
    mask[:, :, :, ds.x.values >= 0] = False
    dropped_ds = ds.assign(mask=(("tag", "z", "y", "x"), mask, standard_attrs("mask")))
    with pytest.warns(HarpxWarning, match=r"50 % of the body .* outside every tag's mask"):
        dropped_track = track(dropped_ds, body, epsilon=0.05)  # and the tracker says so
    dropped = float(tracking_error(dropped_track, ds).mean_all)
    # measured 0.40 mm kept vs 0.66 mm dropped (0.22 mm with every tag everywhere): the
    # x and z tags on the unmasked half are worth keeping; 0.5 mm is a third of a voxel
    assert kept < 0.5 and kept < 0.75 * dropped, (kept, dropped)


def test_phase_only_epsilon_matches_the_full_state(scene, rng):
    from harpx.tracking.constraint import PhaseConstraint

    ds, mesh = scene
    body = Body(mesh, NeoHookean(c1=1.0, kappa=120.0))
    constraint = PhaseConstraint(body, ds)
    constraint.set_frame(2)
    u = rng.normal(0.0, 0.5, body.ndof)
    # the predictor ranks its candidates with the cheaper phase-only ε: it must be the same
    # number as the full state's (same samples, same weights; rounding only)
    assert constraint.epsilon_at(u) == pytest.approx(constraint.state(u).epsilon(), rel=1e-12)


def test_a_misspelt_setting_is_named_with_the_settings_listed(scene):
    ds, mesh = scene
    with pytest.raises(TypeError, match="'epsilom' is not a tracking setting.*epsilon_factor"):
        track(ds, Body(mesh, NeoHookean(c1=1.0, kappa=120.0)), epsilom=0.1)


def test_keywords_apply_on_top_of_a_settings_object(scene):
    # the one carrier: settings= and keyword overrides meet in TrackingSettings.build, and
    # the result records what was used
    ds, mesh = scene
    base = TrackingSettings(epsilon=0.2, max_iterations=7)
    out = ds.harp.track(Body(mesh, NeoHookean(c1=1.0, kappa=120.0)), settings=base, ramp=1)
    assert out.attrs["setting_epsilon"] == 0.2
    assert out.attrs["setting_max_iterations"] == 7
    assert out.attrs["setting_ramp"] == 1


def test_sampling_on_a_worker_thread_gives_the_same_track(scene, tracked, monkeypatch):
    """The worker that samples the images while the solve assembles (large bodies) changes
    when the work is done, not what is computed."""
    import harpx.tracking.track as track_module

    ds, mesh = scene
    monkeypatch.setattr(track_module, "_OVERLAP_POINTS", 0)  # this small body too
    again = track(ds, Body(mesh, NeoHookean(c1=1.0, kappa=120.0)), epsilon=0.05)
    np.testing.assert_array_equal(again.iterations.values, tracked.iterations.values)
    # the same operations in the same order: equal up to rounding, far below 1e-9 mm
    np.testing.assert_allclose(again.displacement.values, tracked.displacement.values, atol=1e-9)


def test_single_precision_factors_give_the_track_of_double_precision_ones(scene, tracked):
    """Each Gauss–Newton step is solved to 1 % with either precision of the factors
    (``SolverTuning.factor_precision``), so the tracks agree far below the tolerance."""
    ds, mesh = scene
    tuning = SolverTuning(factor_precision="double")
    double = track(ds, Body(mesh, NeoHookean(c1=1.0, kappa=120.0)), epsilon=0.05, tuning=tuning)
    assert tracked.attrs["setting_tuning_factor_precision"] == "single"
    np.testing.assert_array_equal(double.iterations.values, tracked.iterations.values)
    difference = np.abs(double.displacement.values - tracked.displacement.values).max()
    # a 1 % error of a last step below the tolerance (0.01 mm) could move it 1e-4 mm;
    # measured 1.3e-7 mm, as each step is solved well within its 1 %
    assert difference <= 1e-6
