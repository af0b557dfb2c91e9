"""The tracker's core, tested directly: the constraint's force and tangent against finite
differences, mask weighting, the penalty and augmented-Lagrangian strategies, settings."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box
from harpx.tracking.constraint import PhaseConstraint
from harpx.tracking.equilibrium import EquilibriumResult
from harpx.tracking.frame import FrameGoal, FrameProblem
from harpx.tracking.settings import SolverTuning, TrackingSettings
from tests._helpers import still
from tests._ideal import ideal_phase

still.inverse = lambda x, t: x  # type: ignore[attr-defined]


@pytest.fixture(scope="module")
def ideal():
    # a linear phase in every direction (no motion): the demodulated images are constant,
    # so trilinear interpolation is exact and the residual is exactly linear in u
    ds = ideal_phase(still, shape=(9, 16, 16), spacing=(2.0, 2.0, 2.0), times=[0.0, 10.0])
    body = Body(box((12.0, 12.0, 8.0), (3, 3, 2), origin=(-6.0, -6.0, -4.0)).mesh,
                NeoHookean(c1=1.0, kappa=50.0))  # fmt: skip
    constraint = PhaseConstraint(body, ds)
    constraint.set_frame(1)
    constraint.penalty = 3.0
    return body, constraint


def _energy(constraint: PhaseConstraint, u: np.ndarray) -> float:
    st = constraint.state(u)
    r = st.residual
    w = st.weight[:, None] * st.tag_valid
    return float((w * (0.5 * constraint.penalty * r**2 + constraint.multipliers * r)).sum())


def test_force_is_the_gradient_of_the_constraint_energy(ideal, rng):
    body, constraint = ideal
    constraint.multipliers = rng.normal(0.0, 0.5, constraint.multipliers.shape)
    try:
        u = rng.normal(0.0, 0.3, body.ndof)
        v = rng.normal(0.0, 1.0, body.ndof)
        h = 1e-4  # mm; the residual is linear here, so central differences are exact to round-off
        numeric = (_energy(constraint, u + h * v) - _energy(constraint, u - h * v)) / (2 * h)
        analytic = float(constraint.force(constraint.state(u)) @ v)
        assert numeric == pytest.approx(analytic, rel=1e-7)
    finally:
        constraint.multipliers[:] = 0.0


def test_tangent_is_the_derivative_of_the_force_on_a_linear_phase(ideal, rng):
    # on a linear phase the dropped phase Hessian is zero: Gauss-Newton is the exact tangent
    body, constraint = ideal
    u = rng.normal(0.0, 0.3, body.ndof)
    v = rng.normal(0.0, 1.0, body.ndof)
    h = 1e-3
    _, K = constraint.assemble(constraint.state(u))
    numeric = (
        constraint.force(constraint.state(u + h * v))
        - constraint.force(constraint.state(u - h * v))
    ) / (2 * h)
    np.testing.assert_allclose(K @ v, numeric, rtol=1e-7, atol=1e-9 * np.abs(numeric).max())


def _cauchy_energy(constraint: PhaseConstraint, u: np.ndarray) -> float:
    st = constraint.state(u)
    r0 = constraint.robust_scale
    w = st.weight[:, None] * st.tag_valid
    return float((w * 0.5 * constraint.penalty * r0**2 * np.log1p((st.residual / r0) ** 2)).sum())


@pytest.fixture(scope="module")
def robust(ideal):
    body, plain = ideal
    constraint = PhaseConstraint(body, plain.phase, robust_scale=0.2)
    constraint.set_frame(1)
    constraint.penalty = 3.0
    return body, constraint


def test_robust_force_is_the_gradient_of_the_cauchy_energy(robust, rng):
    # displacements of ~0.3 mm give residuals of ~0.3 rad, beyond r0 = 0.2 rad: the
    # weight varies, so this checks the weighted force, not the quadratic one
    body, constraint = robust
    u = rng.normal(0.0, 0.3, body.ndof)
    v = rng.normal(0.0, 1.0, body.ndof)
    st = constraint.state(u)
    assert st.robust_weight is not None and st.robust_weight[st.tag_valid].min() < 0.5
    h = 1e-5
    numeric = (_cauchy_energy(constraint, u + h * v) - _cauchy_energy(constraint, u - h * v)) / (
        2 * h
    )
    assert numeric == pytest.approx(float(constraint.force(st) @ v), rel=1e-6)


def test_robust_weight_bounds_the_pull_of_a_point_near_a_wrap(ideal, robust):
    # a uniform shift of 0.45 tag periods puts every point ~2.8 rad from its phase: the
    # quadratic pull grows with the residual, the Cauchy pull has fallen to r0 / r of it
    body, plain = ideal
    _, constraint = robust
    period = 1.0 / float(plain.phase["tag_frequency"].max())
    u = np.zeros(body.ndof)
    u[0::3] = 0.45 * period
    quadratic = np.abs(plain.force(plain.state(u))).sum()
    weighted = np.abs(constraint.force(constraint.state(u))).sum()
    r = 2 * np.pi * 0.45
    assert weighted / quadratic == pytest.approx(1.0 / (1.0 + (r / 0.2) ** 2), rel=0.05)


def test_points_outside_a_tags_mask_carry_none_of_its_force(rng):
    ds = ideal_phase(still, shape=(9, 16, 16), spacing=(2.0, 2.0, 2.0), times=[0.0, 10.0])
    mask = np.ones((3, 9, 16, 16), dtype=bool)
    mask[0, :, :, 8:] = False  # the x tag has no data at x > 0
    ds["mask"] = (("tag", "z", "y", "x"), mask)
    body = Body(box((12.0, 12.0, 8.0), (3, 3, 2), origin=(-6.0, -6.0, -4.0)).mesh,
                NeoHookean(c1=1.0, kappa=50.0))  # fmt: skip
    constraint = PhaseConstraint(body, ds)
    constraint.set_frame(1)
    st = constraint.state(np.zeros(body.ndof))
    right = constraint.points[:, 0] > 0.5
    left = constraint.points[:, 0] < -0.5
    assert not st.tag_valid[right, 0].any() and st.tag_valid[left, 0].all()
    assert st.tag_valid[:, 1:].all()  # the other tags keep every point
    constraint.penalty = 1.0
    u = np.zeros(body.ndof)
    u[0::3] = 0.5  # a pure x translation: only the x tag pulls back, and only where it has data
    force = constraint.force(constraint.state(u)).reshape(-1, 3)
    nodes = body.dof_points
    # nodes of cells wholly at x > 2 mm feel no x force; those of cells at x < −2 mm do (the
    # residual R = λ ∇φ r is positive: the restoring force −R points back along −x)
    assert np.abs(force[nodes[:, 0] > 2.5, 0]).max() == 0.0
    assert (force[nodes[:, 0] < -2.5, 0] > 0).all()
    np.testing.assert_allclose(force[:, 1:], 0.0, atol=1e-12)


class _Scripted(FrameProblem):
    """A frame problem whose solves return a scripted ε per call (strategy logic only).

    ``moves``: the x displacement (tag periods of the stub's one x tag) each solve ends at;
    default: where it started.
    """

    def __init__(self, epsilons, settings, moves=None):
        self.epsilons = list(epsilons)
        self.moves = None if moves is None else list(moves)
        self.settings = settings
        self.penalties = []
        self.constraint = _StubConstraint(self)

    def solve(self, u, max_iterations, start=None):
        self.penalties.append(self.constraint.penalty)
        if self.moves is not None:
            u = np.full_like(u, self.moves.pop(0) * _StubConstraint.PERIOD)
        return EquilibriumResult(u, _StubState(self.epsilons.pop(0)), 2, [0.0], True)


class _StubState:
    def __init__(self, eps):
        self.eps = eps
        self.residual = np.ones((1, 1))
        self.tag_valid = np.ones((1, 1), bool)

    def epsilon(self):
        return self.eps


class _StubConstraint:
    PERIOD = 8.0  # mm, of its one tag along x; its one point moves with u[0]

    def __init__(self, problem):
        self.penalty = 0.0
        self.multipliers = np.zeros((1, 1))
        self.problem = problem
        self.wavevectors = np.array([[2.0 * np.pi / self.PERIOD, 0.0, 0.0]])
        self.reference_valid = np.ones((1, 1), dtype=bool)

    def current_points(self, u):
        return np.asarray(u, dtype=float)[:3].reshape(1, 3)

    def penalty_scale(self):
        return 1.0

    def update_multipliers(self, st):
        self.multipliers = self.multipliers + self.penalty * st.residual
        return 1.0  # never converges on its own


def test_penalty_ramps_then_doubles_until_the_target():
    from harpx.tracking.penalty import track_frame_penalty

    problem = _Scripted([0.5, 0.3, 0.2, 0.09], TrackingSettings(ramp=2, penalty_limit=100.0))
    out = track_frame_penalty(problem, np.zeros(3), FrameGoal(target=0.1, penalty=4.0))
    # ramp 2 → 4, then doubled 8 → 16 while each doubling lowers ε by > 3 %
    assert problem.penalties == [2.0, 4.0, 8.0, 16.0]
    assert out.reached and out.penalty == 16.0 and out.stages == 4 and out.epsilon == 0.09


def test_a_warm_frame_starts_at_the_top_of_the_ramp():
    from harpx.tracking.penalty import track_frame_penalty

    # an earlier pass's result: no relaxed stage, straight to λ_max, then the usual doubling
    problem = _Scripted([0.3, 0.09], TrackingSettings(ramp=2, penalty_limit=100.0))
    out = track_frame_penalty(problem, np.zeros(3), FrameGoal(target=0.1, penalty=4.0, warm=True))
    assert problem.penalties == [4.0, 8.0]
    assert out.reached and out.stages == 2


def test_penalty_stops_raising_at_the_noise_floor():
    from harpx.tracking.penalty import track_frame_penalty

    stalled = 0.2 * (1.0 - SolverTuning().stall / 2)  # lowers ε by less than the stall margin
    problem = _Scripted([0.3, 0.2, stalled], TrackingSettings(ramp=1, penalty_limit=100.0))
    out = track_frame_penalty(problem, np.zeros(3), FrameGoal(target=0.1, penalty=1.0))
    assert problem.penalties == [1.0, 2.0, 4.0]
    assert not out.reached and out.stalled


def test_penalty_stops_at_its_limit():
    from harpx.tracking.penalty import track_frame_penalty

    problem = _Scripted([0.5, 0.4, 0.3], TrackingSettings(ramp=1, penalty=1.0, penalty_limit=4.0))
    out = track_frame_penalty(problem, np.zeros(3), FrameGoal(target=0.1, penalty=1.0))
    assert problem.penalties == [1.0, 2.0, 4.0]
    assert not out.reached and not out.stalled and out.penalty == 4.0


@pytest.mark.parametrize(
    ("moves", "relocated"),
    [
        # the doubling to λ = 4 moves the point 0.6 tag period (measured 0.7 on the small
        # phantom with 4 mm tags): it is stopped, the fit at λ = 2 kept, the frame a miss
        pytest.param([0.30, 0.32, 0.92, 0.93], True, id="across-a-wrap"),
        # 0.4 period (the small left ventricle's largest doubling moved 0.43): refinement
        pytest.param([0.30, 0.32, 0.72, 0.73], False, id="refinement"),
    ],
)
def test_a_doubling_that_drags_the_body_across_a_wrap_ends_the_frame_as_a_miss(moves, relocated):
    from harpx.tracking.penalty import track_frame_penalty

    settings = TrackingSettings(ramp=1, penalty_limit=100.0)
    problem = _Scripted([0.5, 0.3, 0.2, 0.09], settings, moves=moves)
    out = track_frame_penalty(problem, np.zeros(3), FrameGoal(target=0.1, penalty=1.0))
    if relocated:
        assert problem.penalties == [1.0, 2.0, 4.0]  # no doubling after the relocation
        assert not out.reached and not out.plateau and out.penalty == 2.0
        assert out.epsilon == 0.3 and out.u[0] == pytest.approx(0.32 * 8.0)  # the fit kept
        assert out.stages == 3 and out.iterations == 6  # the work done still counts
    else:
        assert problem.penalties == [1.0, 2.0, 4.0, 8.0]
        assert out.reached and out.epsilon == 0.09


def test_augmented_lagrangian_updates_multipliers_then_raises_the_penalty():
    from harpx.tracking.augmented import track_frame_augmented

    settings = TrackingSettings(method="augmented-lagrangian", max_updates=2, penalty_limit=10.0)
    problem = _Scripted([0.5, 0.4, 0.3, 0.05], settings)
    out = track_frame_augmented(problem, np.zeros(3), FrameGoal(target=0.1, penalty=2.0))
    # two updates at λ = 2 (Λ += 2 r each), then λ doubled
    assert problem.penalties == [2.0, 2.0, 4.0, 4.0]
    assert problem.constraint.multipliers[0, 0] == pytest.approx(2.0 + 2.0 + 4.0)
    assert out.reached and out.stages == 4


def test_a_frame_prepared_near_its_start_samples_like_the_whole_grid_wherever_points_go(rng):
    # the images of a frame are prepared in a box around its start (2 tag periods of 8 mm
    # beyond the body on a 80 mm grid); a point that leaves the box (a 25 mm shift here)
    # must see exactly what a constraint prepared on the whole grid sees
    ds = ideal_phase(still, shape=(9, 40, 40), spacing=(2.0, 2.0, 2.0), times=[0.0, 10.0])
    body = Body(box((12.0, 12.0, 8.0), (3, 3, 2), origin=(-6.0, -6.0, -4.0)).mesh,
                NeoHookean(c1=1.0, kappa=50.0))  # fmt: skip
    windowed, whole = PhaseConstraint(body, ds), PhaseConstraint(body, ds)
    windowed.set_frame(1, near=np.zeros(body.ndof))
    whole.set_frame(1)
    far = np.tile([25.0, 0.0, 0.0], body.ndof // 3)
    assert windowed._sampler.outside_window(windowed.current_points(far)) > 0
    assert whole._sampler.outside_window(whole.current_points(far)) == 0
    for shift in (np.zeros(body.ndof), far):  # inside the box, then beyond it
        u = shift + rng.normal(0.0, 0.3, body.ndof)
        a, b = windowed.state(u), whole.state(u)
        assert a.tag_valid.all()
        np.testing.assert_array_equal(a.residual, b.residual)
        np.testing.assert_array_equal(a.gradient, b.gradient)
        assert windowed.epsilon_at(u) == whole.epsilon_at(u)
    assert windowed._sampler.outside_window(windowed.current_points(far)) == 0  # regrown


def test_one_product_assembly_equals_the_cell_block_assembly(ideal, rng):
    # every cell of a one-element-type mesh has the same N at its points: the tangent is one
    # matrix product; the per-cell block path (kept for meshes without that) must agree
    body, constraint = ideal
    assert constraint._shared_products is not None
    u = rng.normal(scale=0.2, size=body.ndof)
    st = constraint.state(u)
    r_fast, K_fast = constraint.assemble(st, 0.7)
    shared, constraint._shared_products = constraint._shared_products, None
    try:
        r_block, K_block = constraint.assemble(st, 0.7)
    finally:
        constraint._shared_products = shared
    np.testing.assert_array_equal(r_fast, r_block)
    assert abs(K_fast - K_block).max() <= 1e-14 * abs(K_block).max()
    np.testing.assert_array_equal(K_fast.indices, K_block.indices)


def test_multiplier_update_is_lambda_times_the_residual(ideal, rng):
    body, constraint = ideal
    u = rng.normal(0.0, 0.3, body.ndof)
    st = constraint.state(u)
    constraint.multipliers[:] = 0.0
    change = constraint.update_multipliers(st)
    np.testing.assert_allclose(constraint.multipliers, constraint.penalty * st.residual)
    assert change == pytest.approx(1.0)  # from zero, the whole multiplier is new
    constraint.multipliers[:] = 0.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"ramp": float("nan")}, "ramp=nan", id="ramp-nan"),
        pytest.param({"penalty_limit": float("nan")}, "penalty_limit=nan", id="limit-nan"),
        pytest.param({"multiplier_tolerance": float("nan")}, "multiplier_tolerance=nan", id="tol"),
        pytest.param({"multiplier_tolerance": -1.0}, "multiplier_tolerance=-1.0", id="tol-neg"),
        pytest.param({"intorder": 0}, "intorder=0", id="intorder"),
        pytest.param({"max_updates": 0}, "max_updates=0", id="updates"),
        pytest.param({"epsilon_factor": 0.5}, "epsilon_factor=0.5", id="factor"),
        pytest.param({"regularization": "none"}, "regularization='none'", id="regularization"),
        pytest.param({"robust_scale": 0.0}, "robust_scale=0.0", id="robust"),
    ],
)
def test_settings_name_what_is_wrong(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TrackingSettings(**kwargs)


class _Candidates:
    """A constraint whose ε at u(n−1) + α·step is scripted per α (predictor logic only).

    The last step is a uniform x translation of ``cycles`` tag periods of 8 mm.
    """

    def __init__(self, body, eps_by_alpha, cycles):
        self.eps_by_alpha = eps_by_alpha
        self.last = np.zeros(body.ndof)
        self.before = np.zeros(body.ndof)
        self.before[0::3] = -cycles * 8.0
        self.sampled = []

    def epsilon_at(self, u):
        alpha = round(float(np.mean((u - self.last)[0::3])) / float(-self.before[0]), 6)
        self.sampled.append(alpha)
        return self.eps_by_alpha[alpha]


@pytest.mark.parametrize(
    ("eps", "tuning", "chosen"),
    [
        # a tie between a quarter period short of the motion and a quarter beyond it (ramped
        # translation, 1 % apart): no information, the steady motion (α = 1) starts the frame
        pytest.param({0.0: 0.704, 0.5: 1.047, 1.0: 0.711}, SolverTuning(), 1.0, id="tie"),
        # the motion stopped: α = 0 lowers ε far beyond the margin
        pytest.param({0.0: 0.076, 0.5: 0.225, 1.0: 0.386}, SolverTuning(), 0.0, id="stop"),
        # it slowed: α = ½ beats α = 1 by more than 5 %, α = 0 does not beat α = ½
        pytest.param({0.0: 0.50, 0.5: 0.40, 1.0: 0.45}, SolverTuning(), 0.5, id="slowed"),
        # without a margin the smallest ε wins, a tie's 1 % included
        pytest.param(
            {0.0: 0.704, 0.5: 1.047, 1.0: 0.711},
            SolverTuning(predictor_margin=0.0),
            0.0,
            id="no-margin",
        ),
    ],
)
def test_predictor_keeps_the_steady_motion_unless_another_start_is_clearly_better(
    ideal, eps, tuning, chosen
):
    from harpx.tracking.track import _predict

    body, _ = ideal
    constraint = _Candidates(body, eps, cycles=1 / 3)
    start = _predict(body, constraint, constraint.last, constraint.before, tuning)
    step = constraint.last - constraint.before
    np.testing.assert_allclose(start, constraint.last + chosen * step)
    assert constraint.sampled == [1.0, 0.5, 0.0]  # the steady motion is the reference


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"predictor_margin": 1.0}, r"predictor_margin=1.0 must lie in \[0, 1\)"),
        pytest.param({"predictor_margin": -0.1}, r"predictor_margin=-0.1 must lie"),
        pytest.param({"raise_move": -1.0}, "raise_move=-1.0 must be a positive"),
        pytest.param({"step_accuracy": 1.0}, r"step_accuracy=1.0 must lie in \(0, 1\)"),
        pytest.param({"step_accuracy": 0.0}, "step_accuracy=0.0 must be a positive"),
        pytest.param({"factor_precision": "half"}, "factor_precision='half' is not 'single'"),
    ],
)
def test_predictor_tuning_names_what_is_wrong(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SolverTuning(**kwargs)


def test_settings_attributes_are_netcdf_safe():
    attrs = TrackingSettings().as_attrs()
    assert attrs["setting_epsilon"] == "auto" and attrs["setting_intorder"] == -1
    scalars = {k: v for k, v in attrs.items() if k != "setting_tuning_predictor_factors"}
    assert all(isinstance(v, str | int | float) for v in scalars.values())
    assert attrs["setting_tuning_predictor_factors"] == [0.0, 0.5, 1.0]  # a NetCDF number list
    # every tangent factorised: written as a word, not a number that reads as an accuracy
    exact = TrackingSettings(tuning=SolverTuning(step_accuracy=None)).as_attrs()
    assert exact["setting_tuning_step_accuracy"] == "none"


def test_robust_weight_is_for_the_penalty_method_only():
    # the multiplier update assumes the quadratic penalty
    assert TrackingSettings().effective_robust_scale == 0.5
    assert TrackingSettings(method="augmented-lagrangian").effective_robust_scale is None
    assert TrackingSettings(robust_scale=None).effective_robust_scale is None


def test_remaining_increments_are_bounded_by_a_geometric_tail():
    from harpx.tracking.equilibrium import _remaining

    FAST = SolverTuning().fast

    # increments s0 ρ^k: the tail after s_k sums to exactly ρ s_k / (1 - ρ)
    rho = 0.2
    steps = [0.5 * rho**k for k in range(3)]
    tail = sum(0.5 * rho**k for k in range(3, 200))
    assert _remaining(steps) == pytest.approx(tail, rel=1e-12)
    # no bound from one increment, nor from a contraction slower than FAST
    assert _remaining([0.1]) == np.inf
    assert _remaining([0.1, FAST * 0.1]) == np.inf


def test_a_solve_started_from_the_last_reuses_its_evaluations(ideal, rng, monkeypatch):
    import harpx.tracking.equilibrium as eq
    from harpx.mechanics.linsolve import LinearSolver

    body, constraint = ideal
    u0 = 0.3 * rng.standard_normal(body.ndof)
    calls = []
    counted = eq.internal_forces
    monkeypatch.setattr(eq, "internal_forces", lambda *a, **k: calls.append(1) or counted(*a, **k))

    def solve(u, start=None, iterations=2):
        return eq.equilibrate(body, constraint, u, solver=LinearSolver(), max_iterations=iterations,
                              tolerance=1e-9, start=start)  # fmt: skip

    first = solve(u0)
    assert not first.converged and first.internal is not None
    calls.clear()
    again = solve(first.u)
    fresh = len(calls)
    calls.clear()
    reused = solve(first.u, start=first)
    # one evaluation of the internal forces fewer, and the same iterates to rounding
    assert len(calls) == fresh - 1
    np.testing.assert_allclose(reused.u, again.u, rtol=0, atol=1e-12)
    # a start that did not end at u is not reused
    calls.clear()
    solve(u0, start=first)
    assert len(calls) == fresh


class _ScriptedSolver:
    """Returns scripted Gauss–Newton increments: a rigid x translation of a given size."""

    def __init__(self, body, sizes):
        self.sizes = list(sizes)
        self.unit = np.zeros((body.ndof // 3, 3))
        self.unit[:, 0] = 1.0

    def solve(self, K, b, **kwargs):
        return self.sizes.pop(0) * self.unit.ravel()


@pytest.mark.parametrize("tuning", [SolverTuning(), SolverTuning(damp_after=5, damp_small_after=2)])
def test_cycling_steps_are_damped_small_ones_first(ideal, tuning):
    # behaviour, for any tuning: steps that stop shrinking (cycling between tag basins) are
    # damped so that the accumulated motion stays bounded; small ones (below small_step of
    # the trust radius: no longer searching for a basin) soon, large ones (which carry
    # points into the right basin) only after damp_after iterations
    import harpx.tracking.equilibrium as eq

    body, constraint = ideal
    radius = 0.5 * np.pi / constraint.max_wavenumber  # the trust radius, 2 mm here
    assert radius == pytest.approx(2.0)

    def steps(size: float, count: int) -> np.ndarray:
        res = eq.equilibrate(body, constraint, np.zeros(body.ndof), max_iterations=count,
                             tolerance=1e-9, solver=_ScriptedSolver(body, [size] * count),
                             tuning=tuning)  # fmt: skip
        assert not res.converged
        return np.asarray(res.step_norms)

    small = steps(0.5 * tuning.small_step * radius, 16)
    early = tuning.damp_small_after
    np.testing.assert_allclose(small[:early], small[0], rtol=1e-12)  # undamped at first
    assert small[early] < small[0]  # then damped
    # damped again whenever the damped steps cycle: the total stays within a few steps
    assert small[-1] <= small[0] / 8 and small.sum() < (early + 3) * small[0]
    large = steps(0.5 * radius, tuning.damp_after + 3)
    np.testing.assert_allclose(large[: tuning.damp_after], large[0], rtol=1e-12)
    assert large[-1] < large[0]
