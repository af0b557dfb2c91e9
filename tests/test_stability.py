"""Fast subset of the stability report (benchmarks/stability.py, issue 7).

Stiff materials, large per-frame motion, extreme penalties, near-inversion and degenerate
data each end in a finite result or a clear, named error — never NaN and never a hang.
Scenes are small (coarse meshes, 1.5 mm voxels, 1–5 frames) so the file runs in well under a
minute; the full sweeps with their timings live in the benchmark.
"""

from __future__ import annotations

import contextlib
import signal
import warnings
from collections.abc import Iterator

import numpy as np
import pytest

from harpx.errors import (
    ConvergenceError,
    ElementInversionError,
    HarpxWarning,
    SchemaError,
)
from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import track_harp
from harpx.mechanics.body import Body
from harpx.mechanics.linsolve import LinearSolver
from harpx.mechanics.loads import Fixed, Pressure
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box
from harpx.mechanics.newton import solve
from harpx.scenes._motion import RotationalImpact
from harpx.scenes.phantom import GEOMETRIES, phantom
from harpx.tracking.constraint import PhaseConstraint
from harpx.tracking.equilibrium import equilibrate
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track
from tests._rigid import RigidRotation, Translation, cylinder_scene, frame_profile

PERIOD = 8.0  # tag period, mm
FRAME = 18.0  # ms


@contextlib.contextmanager
def deadline(seconds: float) -> Iterator[None]:
    """Fail (instead of hanging the suite) if the block runs longer than ``seconds``."""

    def expire(signum: int, frame: object) -> None:
        raise TimeoutError(f"still running after {seconds} s: the solver hangs")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def translation(step: float, frames: int = 5, ramp: int = 0, margin: float = 0.5 * PERIOD):
    """12 mm cylinder translating along the x tag, ``step`` tag periods per frame.

    ``margin`` mm of field of view beyond the final position (the benchmark has none).
    """
    times = np.arange(frames) * FRAME
    offsets = frame_profile(step * PERIOD, frames, ramp=ramp)
    motion = Translation(times=tuple(times), offsets=tuple(offsets))
    # half a tag period of field of view beyond the final position: the band-pass filter
    # treats each slice as periodic, so the phase within ~2 voxels of the field of view's
    # edge is contaminated by the opposite edge. (With the body 1 voxel from the edge the
    # FE error was once 6.0 mm: not the contamination but the predictor's choice between
    # two starts of equal ε, which the edge tipped; see the test of the ramped translation)
    return cylinder_scene(motion, times=times, travel=float(offsets[-1]) + margin)


def rotation(step: float, frames: int = 2, snr: float | None = None):
    """24 mm cylinder turning rigidly; its edge moves ``step`` tag periods per frame."""
    times = np.arange(frames) * FRAME
    angles = frame_profile(step * PERIOD / 24.0, frames)
    motion = RigidRotation(times=tuple(times), angles=tuple(angles))
    return cylinder_scene(
        motion, times=times, radius=24.0, n_radial=3, n_circumferential=24, snr=snr
    )


def mean_error(tracked, tagged) -> float:
    err = tracking_error(tracked, tagged)
    values = err["mean"].values[1:]
    assert np.all(np.isfinite(values)), f"NaN in the per-frame error {values}"
    return float(err.mean_all)


# ----------------------------------------------------------------------------- stiffness
@pytest.fixture(scope="module")
def small_phantom():
    scene = phantom("small")
    return scene, extract_phase(scene.tagged)


def test_nearly_incompressible_model_tracks_like_a_moderate_one(small_phantom):
    scene, phase = small_phantom
    errors = {}
    for ratio in (1e2, 1e5):
        body = scene.body("hex8", material=NeoHookean(c1=1.0, kappa=ratio))
        out = track(phase, body)
        assert np.isfinite(out.epsilon.values).all() and out.target_reached.all(), (
            ratio,
            out.epsilon.values,
        )
        errors[ratio] = mean_error(out, scene.tagged)
    # the criterion: κ/C1 = 1e5 within 10 % of κ/C1 = 1e2. Measured 0.1544 vs
    # 0.1542 mm, 0.15 % apart (the same to the last digit over repeated runs, with 1 or 2
    # MKL threads); bounded at 1.2 × each. With the consistent pressure stiffness in the
    # Gauss–Newton tangent it was 3.0 mm: the tangent turned indefinite after the first
    # step and the model diverged
    assert errors[1e2] < 0.185, errors
    assert abs(errors[1e5] - errors[1e2]) <= 0.0018 * errors[1e2], errors


# ----------------------------------------------------------------------------- large motion
@pytest.mark.parametrize(
    ("make", "carrier"),
    [
        # one frame of a rigid rotation: no history, so no predictor; the slower centre
        # and the mechanics that couple it to the edge carry the edge past the wrap
        pytest.param(lambda: rotation(0.75), "mechanics + slower centre", id="rotation"),
        # a uniform translation reaching 0.75 period per frame after a two-frame ramp:
        # nothing moves less, the motion predictor carries it
        pytest.param(lambda: translation(0.75, ramp=2), "predictor", id="translation"),
    ],
)
def test_fe_holds_three_quarter_period_steps_where_harp_jumps(make, carrier):
    scene = make()
    phase = extract_phase(scene.tagged)
    fe = mean_error(track(phase, scene.body()), scene.tagged)
    with warnings.catch_warnings():
        # HARP's jumping edge points may leave the field of view (it says how many, a
        # HarpxWarning): this test is about the error of the points it keeps
        warnings.simplefilter("ignore", HarpxWarning)
        harp_out = track_harp(phase, points=scene.tagged)
    harp = float(tracking_error(harp_out, scene.tagged).mean_all)
    # noise-free images: the issue asks for 0.5 mm (a third of a voxel); FE measured 0.071 mm
    # (rotation) and 0.0019 mm (translation), bounded 20-30 % above so that a regression
    # shows; HARP starts each point from its last position and lands a tag (8 mm) away
    # wherever the step exceeds half a period (measured 3.48 and 8.14 mm mean), bounded
    # below at measured / 1.2 (the issue asks for more than 2 mm)
    assert fe < {"mechanics + slower centre": 0.085, "predictor": 0.0025}[carrier], (carrier, fe)
    assert harp > {"mechanics + slower centre": 2.9, "predictor": 6.8}[carrier], (carrier, harp)


def test_uniform_translation_needs_the_predictor():
    scene = translation(0.75, ramp=2)
    phase = extract_phase(scene.tagged)
    # the jumped frame cannot match the images any more, and the tracker says so
    with pytest.warns(HarpxWarning, match="missed the tracking target"):
        unpredicted = track(phase, scene.body(), predictor="none")
    without = mean_error(unpredicted, scene.tagged)
    # wrapped phase cannot tell +0.75 from −0.25 period and a rigid translation costs the
    # mechanics nothing either way: without the predictor the model jumps a tag like HARP
    # (measured 5.98 mm; bounded at measured / 1.2), so the predictor, not the mechanics,
    # carries the uniform case
    assert without > 5.0, without


def test_ramped_translation_keeps_its_steady_motion_through_a_phase_tie():
    # the benchmark's scene (no field of view beyond the final position): after a two-frame
    # ramp the step grows 2 → 4 → 6 mm on 8 mm tags, so in frame 3 the starts α = 0 and
    # α = 1 lie a quarter period short of and beyond the truth, with ε equal to 4 digits.
    # Picked by the smallest ε, α = 0 won and the body stayed a tag behind (6.03 mm, the
    # last frame flagged); the predictor now keeps α = 1 unless another start is clearly
    # (5 %) better
    scene = translation(0.75, ramp=2, margin=0.0)
    phase = extract_phase(scene.tagged)
    with deadline(60.0):  # measured 0.2-0.6 s
        out = track(phase, scene.body())
    assert out.target_reached.all(), out.epsilon.values
    # noise-free images: measured 0.0020 mm mean against the truth, where a jump costs 8 mm
    assert mean_error(out, scene.tagged) < 0.0025


def test_a_whole_period_per_frame_ends_flagged():
    # steps of 2.7, 5.3 and then 8 mm on 8 mm tags: in frame 3 the start α = 0 (the body
    # held where it was) is exactly one period short and fits as well as the truth (ε 0.02
    # against 0.70 for α = 1, which is a third of a period off), so the predictor takes it
    # and the body falls a tag behind (measured 6.0 mm mean). Wrapped phase cannot tell a
    # whole period per frame from none; the tracker must say it missed
    scene = translation(1.0, ramp=2, margin=0.0)
    phase = extract_phase(scene.tagged)
    with deadline(60.0), pytest.warns(HarpxWarning, match="missed the tracking target"):
        out = track(phase, scene.body())
    assert not out.target_reached.values.all(), out.epsilon.values


def test_impact_beyond_a_tag_period_per_frame_ends_flagged():
    # the small phantom turning 0.5 rad instead of 0.3: its edge steps 6.2 and 7.7 mm per
    # frame on 6 mm tags. Raising the penalty in frame 2 dragged the edge across a wrap
    # (0.57 period in one doubling) and the blur-correction pass, predicted from that fit,
    # then confirmed it: every frame "reached" with a 9.8 mm error at the edge. A doubling
    # that moves a point half a period now stops the raise, and a frame the first pass
    # missed stays a miss; either alone left the run looking converged (measured)
    g = GEOMETRIES["small"]
    motion = RotationalImpact(
        radius=g.radius, base=-g.height / 2, height=g.height, angle=0.5, rise_time=g.rise_time
    )
    scene = phantom("small", motion=motion)
    phase = extract_phase(scene.tagged)
    with deadline(60.0), pytest.warns(HarpxWarning) as caught:
        out = track(phase, scene.body())  # measured 9–17 s on two shared cores
    said = [str(w.message) for w in caught]
    assert any("missed the tracking target: frame 2" in m for m in said), said
    assert out.target_reached.values.tolist() == [True, True, False, True, True]
    # frames the result flags as stopped at the iteration limit are the ones a warning names
    stopped = [n for n, ok in enumerate(out.converged.values) if not ok]
    named = [m for m in said if "iteration limit" in m]
    assert named == [] if not stopped else any(f"frame(s) {stopped}" in m for m in named), said
    # the frames after it meet ε from where frame 2 left the body: measured 0.60 mm mean
    # error (max 6.2 mm, a tag period at a few edge voxels)
    assert np.isfinite(out.displacement.values).all()


# ----------------------------------------------------------------------------- penalty
def test_epsilon_does_not_rise_with_a_pinned_penalty():
    scene = rotation(0.25, snr=10.0)
    phase = extract_phase(scene.tagged)
    eps = []
    for lam in (0.1, 1.0, 10.0, 100.0, 1e4):
        # penalty = penalty_limit pins λ; an unreachable target makes every frame end there
        with pytest.warns(HarpxWarning, match="missed the tracking target"):
            out = track(phase, scene.body(), penalty=lam, penalty_limit=lam, epsilon=1e-6)
        assert not out.target_reached.values[1:].any()
        assert np.isfinite(out.displacement.values).all(), lam
        eps.append(float(out.epsilon.values[1]))
    # a stiffer data term can only lower the misfit it penalises (measured 0.041, 0.033,
    # 0.020, 0.013, 0.011 rad); 1e-3 rad of slack allows for the Gauss–Newton stopping
    # tolerance (0.01 mm × |k| ≈ 0.008 rad at a point, averaged over thousands of points)
    # where ε saturates at the noise floor. On the small phantom, whose edge steps exceed
    # half a period, ε rises beyond 10³ × the default λ (the data overpower the mechanics
    # across the wrap): that limit is reported by the benchmark, not hidden here
    assert np.all(np.diff(eps) <= 1e-3), eps


# ----------------------------------------------------------------------------- bounded runs
@pytest.mark.parametrize(
    ("make", "kwargs"),
    [
        pytest.param(
            lambda: translation(0.25, frames=3),
            {"penalty": 1e-3, "penalty_limit": 1e-3},
            id="penalty-1e-3",
        ),
        pytest.param(
            lambda: translation(0.25, frames=3),
            {"penalty": 1e6, "penalty_limit": 1e6},
            id="penalty-1e6",
        ),
        pytest.param(lambda: translation(1.0, frames=3), {}, id="full-period-steps"),
        pytest.param(lambda: rotation(0.5, snr=3.0), {}, id="snr-3"),
    ],
)
def test_extreme_cases_end_in_a_finite_result(make, kwargs):
    # measured: every case tracks to a result (max ε 0.005, 0.0001, 0.020, 0.089 rad) without
    # a warning; harpx warnings are errors in the tests, so a missed target fails here too
    scene = make()
    phase = extract_phase(scene.tagged)
    with deadline(60.0):  # measured < 1 s; a hang fails here instead of stalling the suite
        out = track(phase, scene.body(), **kwargs)
    # no NaN anywhere in what the user reads
    for name in ("displacement", "epsilon", "penalty", "green_strain"):
        assert np.isfinite(out[name].values).all(), name


# ----------------------------------------------------------------------------- near-inversion
def test_pressed_cube_near_a_limit_point_fails_clearly_and_promptly():
    body = Body(box((10.0, 10.0, 10.0), (3, 3, 3)), NeoHookean(c1=1.0, kappa=100.0))
    # 100 C1 of follower pressure has a limit point near s = 0.05; the cut-back loop once
    # crept towards it forever (tiny converged steps reset the cut-back count)
    with deadline(60.0), pytest.raises(ConvergenceError, match=r"at load factor s="):
        solve(body, [Fixed("bottom"), Pressure("top", 100.0)], steps=4)
    with deadline(60.0), pytest.raises(ElementInversionError, match=r"cells \[") as info:
        solve(body, [Fixed("bottom"), Pressure("top", 1000.0)], steps=4)
    assert info.value.cells, "the inverted cells are named"


def test_tracking_step_that_inverts_names_the_frame_and_cells():
    scene = translation(0.0, frames=2)  # static images
    phase = extract_phase(scene.tagged)
    body = scene.body()
    constraint = PhaseConstraint(body, phase)
    constraint.set_frame(1)
    constraint.penalty = constraint.penalty_scale()
    squeeze = [Pressure("top", 100.0), Pressure("bottom", 100.0)]
    # without halvings the crushing step must raise, naming the frame and the cells
    with pytest.raises(ElementInversionError, match=r"of frame 1 inverts cells \[") as info:
        equilibrate(
            body,
            constraint,
            np.zeros(body.ndof),
            terms=squeeze,
            solver=LinearSolver(),
            max_halvings=0,
            max_iterations=20,
        )
    assert info.value.cells
    # with the default halvings the same load is survived: J stays positive
    res = equilibrate(
        body,
        constraint,
        np.zeros(body.ndof),
        terms=squeeze,
        solver=LinearSolver(),
        max_iterations=20,
    )
    assert np.isfinite(res.u).all() and body.jacobian(res.u).min() > 0.0


# ----------------------------------------------------------------------------- degenerate data
@pytest.fixture(scope="module")
def moving():
    return translation(0.25, frames=4)


def _empty_mask(ds):
    ds["mask"][:] = False


def _one_tag_masked(ds):
    ds["mask"][2] = False


def _zero_frame(ds):
    ds["image"][:, 2] = 0.0


def _nan_slice(ds):
    ds["image"][0, :, 2] = np.nan


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        pytest.param(_empty_mask, "no constraint point of the body lies inside", id="empty-mask"),
        pytest.param(
            _one_tag_masked, r"tag \['z'\] has no data at any constraint point", id="one-tag-masked"
        ),
        pytest.param(_zero_frame, r"frame 2 \(time=36.0 ms\) has no valid phase", id="zero-frame"),
        pytest.param(_nan_slice, "'image' has .* non-finite values", id="nan-slice"),
    ],
)
def test_degenerate_data_raise_named_errors(moving, edit, match):
    ds = moving.tagged.copy(deep=True)
    edit(ds)
    # a blank frame is named by the phase extraction first (a warning), then refused
    blank = edit is _zero_frame
    warns = (
        pytest.warns(HarpxWarning, match="constant images") if blank else contextlib.nullcontext()
    )
    with warns, pytest.raises(SchemaError, match=match):
        track(ds, moving.body())


def test_tiny_mask_tracks_what_it_sees_and_reports_the_rest():
    scene = rotation(0.25)
    ds = scene.tagged.copy(deep=True)
    ds["mask"][:] = False
    cz, cy, cx = (ds.sizes[d] // 2 for d in ("z", "y", "x"))
    ds["mask"][:, cz - 1 : cz + 1, cy - 1 : cy + 1, cx - 1 : cx + 1] = True  # 8 voxels at the axis
    with pytest.warns(HarpxWarning, match=r"100 % of the body .* outside every tag's mask"):
        out = track(ds, scene.body())
    assert np.isfinite(out.displacement.values).all()
    no_data = np.isnan(out.epsilon_cell.values[1]).sum()
    # the 8 voxels lie within 2.1 mm of the axis, which move 0.18 mm in the frame, so they
    # keep their points; every other cell has no data and is reported as such (NaN ε_cell,
    # measured 208 of 216 cells), not silently fitted
    assert no_data > 0.9 * out.sizes["cell"], no_data
    assert np.isfinite(out.epsilon.values).all()


def test_mesh_partly_outside_the_field_of_view_is_reported(moving):
    cropped = moving.tagged.sel(x=slice(None, 4.0))  # a third of the body is cut off
    with pytest.warns(HarpxWarning, match=r"32 % of the body .* outside the field of view"):
        out = track(cropped, moving.body())
    assert np.isfinite(out.displacement.values).all()
    outside = np.isnan(out.epsilon_cell.values[1:]).all(axis=0)
    # cells beyond the field of view carry no constraint: NaN ε_cell (measured 32 of 96)
    # and a finite displacement from the mechanics; the others still meet the ε target
    assert outside.any() and not outside.all(), outside.sum()
    assert out.target_reached.values[1:].all(), out.epsilon.values
