"""PARDISO solves nearby matrices with the factorisation of an earlier one (``reuse``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from harpx.mechanics.linsolve import LinearSolver, available_methods

pytestmark = pytest.mark.skipif(
    "pardiso" not in available_methods(), reason="PARDISO (pypardiso) is not available"
)


def _laplacian(n: int, shift: float) -> sparse.csr_matrix:
    """3D seven-point Laplacian plus ``shift`` on the diagonal (SPD), n³ unknowns."""
    one = sparse.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    eye = sparse.identity(n)
    lap = (sparse.kron(sparse.kron(one, eye), eye) + sparse.kron(sparse.kron(eye, one), eye)
           + sparse.kron(sparse.kron(eye, eye), one))  # fmt: skip
    return (lap + shift * sparse.identity(n**3)).tocsr()


def test_nearby_matrices_are_solved_with_the_earlier_factorisation_to_the_accuracy_asked(rng):
    b = rng.standard_normal(12**3)
    solver = LinearSolver("pardiso", reuse=1e-8)
    for k, shift in enumerate((0.10, 0.11, 0.12, 0.125)):  # a Newton-like drift
        K = _laplacian(12, shift)
        x = solver.solve(K, b)
        exact = sparse.linalg.spsolve(K.tocsc(), b)
        # CG preconditioned by an earlier factorisation, stopped at 1e-8: the error is that
        # of the stopping rule (a factor 10 of slack for the conditioning), not of rounding
        assert np.linalg.norm(x - exact) <= 1e-7 * np.linalg.norm(exact), k
        # the stopping rule itself: the true relative residual
        assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b), k
    assert solver.factorizations == 1
    assert solver.reused == 3
    assert solver.reuse_failures == 0
    assert 0 < solver.last_iterations <= solver.reuse_iterations


def test_a_far_matrix_or_a_refresh_is_factorised_afresh(rng):
    b = rng.standard_normal(10**3)
    solver = LinearSolver("pardiso", reuse=1e-8, reuse_iterations=3)
    solver.solve(_laplacian(10, 0.1), b)
    x = solver.solve(_laplacian(10, 30.0), b)  # far: CG needs many iterations or fails
    exact = sparse.linalg.spsolve(_laplacian(10, 30.0).tocsc(), b)
    assert np.linalg.norm(x - exact) <= 1e-7 * np.linalg.norm(exact)
    assert (solver.factorizations, solver.reused, solver.reuse_failures) == (2, 0, 1)
    solver.refresh()
    before = solver.factorizations
    solver.solve(_laplacian(10, 30.0), b)
    assert solver.factorizations == before + 1


def test_a_factorisation_that_costs_many_iterations_raises_the_loops_budget(rng):
    # 8 000 unknowns of a 3D Laplacian: its factors fill in, so one factorisation costs
    # several iterations of the loop (PARDISO's operation counts); a 1-iteration budget is
    # raised, and a nearby matrix that needs more than one iteration is still reused
    b = rng.standard_normal(20**3)
    solver = LinearSolver("pardiso", reuse=1e-8, reuse_iterations=1)
    assert solver.iteration_budget == 1  # nothing analysed yet
    solver.solve(_laplacian(20, 0.1), b)
    assert 3 <= solver.iteration_budget <= 8  # 5 measured
    K = _laplacian(20, 0.102)
    x = solver.solve(K, b)
    assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b)
    assert (solver.factorizations, solver.reused) == (1, 1)
    assert 1 < solver.last_iterations <= solver.iteration_budget
    # a small system's factorisation is cheap: the budget stays at reuse_iterations
    small = LinearSolver("pardiso", reuse=1e-8)
    small.solve(_laplacian(8, 0.1), b[: 8**3])
    assert small.iteration_budget == small.reuse_iterations == 15


def test_reuse_out_of_range_is_named():
    with pytest.raises(ValueError, match="reuse=2"):
        LinearSolver("pardiso", reuse=2.0)


def test_a_thread_count_applies_to_the_call_and_leaves_mkls_setting_as_it_was(rng):
    import ctypes

    b = rng.standard_normal(8**3)
    solver = LinearSolver("pardiso", threads=1)
    K = _laplacian(8, 0.2)
    x = solver.solve(K, b)
    assert np.linalg.norm(K @ x - b) <= 1e-10 * np.linalg.norm(b)
    threads = solver._pardiso.libmkl.MKL_Get_Max_Threads
    threads.restype = ctypes.c_int
    before = threads()
    solver.solve(K, b)
    assert threads() == before
    reusing = LinearSolver("pardiso", reuse=1e-8, threads=1)
    reusing.solve(K, b)
    reusing.solve(_laplacian(8, 0.21), b)  # the Krylov loop's solve phases, on one thread
    assert reusing.reused == 1
    assert threads() == before
    with pytest.raises(ValueError, match="threads=0"):
        LinearSolver("pardiso", threads=0)


def test_a_singular_matrix_after_a_regular_one_is_solved_as_without_reuse(rng):
    """A frame without data leaves the tracking tangent singular: CG's fallback
    factorisation refuses it where a plain factorisation perturbs its pivots; the solver
    then factorises plainly."""
    n = 8
    ends = np.full(n, 2.0)
    ends[[0, -1]] = 1.0  # free ends: constants span the null space
    one = sparse.diags([-np.ones(n - 1), ends, -np.ones(n - 1)], [-1, 0, 1])
    eye = sparse.identity(n)
    neumann = (sparse.kron(sparse.kron(one, eye), eye) + sparse.kron(sparse.kron(eye, one), eye)
               + sparse.kron(sparse.kron(eye, eye), one)).tocsr()  # fmt: skip
    b = rng.standard_normal(n**3)
    b -= b.mean()  # consistent: orthogonal to the null space
    plain = LinearSolver("pardiso").solve(neumann, b)
    solver = LinearSolver("pardiso", reuse=1e-8)
    solver.solve(_laplacian(n, 0.1), b)
    x = solver.solve(neumann, b)
    # both solve the consistent system (a solution up to a constant)
    for y in (plain, x):
        assert np.linalg.norm(neumann @ y - b) <= 1e-6 * np.linalg.norm(b)


def _convection(n: int, speed: float, shift: float) -> sparse.csr_matrix:
    """The Laplacian plus an upwind convection term along the first axis (non-symmetric)."""
    upwind = sparse.diags([-1.0, 1.0], [-1, 0], shape=(n, n))
    eye = sparse.identity(n)
    return (_laplacian(n, shift) + speed * sparse.kron(sparse.kron(upwind, eye), eye)).tocsr()


def test_nearby_non_symmetric_matrices_are_solved_by_bicgstab_to_the_accuracy_asked(rng):
    b = rng.standard_normal(10**3)
    solver = LinearSolver("pardiso", reuse=1e-8)
    for k, speed in enumerate((1.0, 1.05, 1.1, 1.12)):
        K = _convection(10, speed, 0.1)
        x = solver.solve(K, b, symmetric=False)
        exact = sparse.linalg.spsolve(K.tocsc(), b)
        assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b), k
        # the condition number of these matrices is a few hundred: 1e-8 in the residual is
        # below 1e-6 in the solution
        assert np.linalg.norm(x - exact) <= 1e-6 * np.linalg.norm(exact), k
    assert (solver.factorizations, solver.reused, solver.reuse_failures) == (1, 3, 0)
    assert 0 < solver.last_iterations <= solver.reuse_iterations


def test_the_upper_triangle_alone_is_read_for_a_symmetric_matrix_also_when_reused(rng):
    b = rng.standard_normal(8**3)
    full, upper = LinearSolver("pardiso", reuse=1e-8), LinearSolver("pardiso", reuse=1e-8)
    for shift in (0.1, 0.11):
        K = _laplacian(8, shift)
        x, y = full.solve(K, b), upper.solve(sparse.triu(K, format="csr"), b)
        assert np.linalg.norm(x - y) <= 1e-7 * np.linalg.norm(x)
    assert full.reused == upper.reused == 1


def test_a_zero_right_hand_side_returns_zero_without_factorising(rng):
    """PARDISO's own iterative mode (iparm(4)) never returned here: the tracker met it at a
    frame without a tag pattern, whose Gauss-Newton right-hand side is zero."""
    solver = LinearSolver("pardiso", reuse=1e-8)
    solver.solve(_laplacian(8, 0.1), rng.standard_normal(8**3))
    for symmetric in (True, False):
        x = solver.solve(_laplacian(8, 0.12), np.zeros(8**3), symmetric=symmetric)
        assert not np.any(x)
    # the second call (non-symmetric) is a new pattern key: factorised
    assert (solver.factorizations, solver.reused) == (2, 1)


def _neumann(n: int) -> sparse.csr_matrix:
    """The Laplacian with free ends: singular, the constants span its null space."""
    ends = np.full(n, 2.0)
    ends[[0, -1]] = 1.0
    one = sparse.diags([-np.ones(n - 1), ends, -np.ones(n - 1)], [-1, 0, 1])
    eye = sparse.identity(n)
    return (sparse.kron(sparse.kron(one, eye), eye) + sparse.kron(sparse.kron(eye, one), eye)
            + sparse.kron(sparse.kron(eye, eye), one)).tocsr()  # fmt: skip


@pytest.mark.parametrize("symmetric", [True, False])
def test_a_singular_inconsistent_system_falls_back_to_the_plain_factorisation(rng, symmetric):
    """No solution exists: the Krylov loop stops at its limit (the test returns), and the
    matrix is factorised as without reuse (PARDISO perturbs the zero pivot)."""
    n = 8
    b = rng.standard_normal(n**3)  # with a mean: no solution
    plain, solver = LinearSolver("pardiso"), LinearSolver("pardiso", reuse=1e-8)
    for s in (plain, solver):  # the same sequence: the analysis (and scaling) of the first
        s.solve(_laplacian(n, 0.1), b, symmetric=symmetric)
    expected = plain.solve(_neumann(n), b, symmetric=symmetric)
    x = solver.solve(_neumann(n), b, symmetric=symmetric)
    assert (solver.factorizations, solver.reused, solver.reuse_failures) == (2, 0, 1)
    assert solver.last_iterations <= solver.reuse_iterations
    # the plain solver's factorisation: its (large, pivot-perturbed) answer up to rounding
    assert np.linalg.norm(x - expected) <= 1e-6 * np.linalg.norm(expected)


def test_a_non_finite_matrix_is_factorised_afresh_not_iterated(rng):
    b = rng.standard_normal(8**3)
    solver = LinearSolver("pardiso", reuse=1e-8)
    solver.solve(_laplacian(8, 0.1), b)
    K = _laplacian(8, 0.1)
    K.data[5] = np.nan
    x = solver.solve(K, b)
    assert not np.all(np.isfinite(x))  # as PARDISO's plain answer
    assert (solver.factorizations, solver.reused, solver.reuse_failures) == (2, 0, 1)
    # its factors are not held: the next matrix is factorised too
    solver.solve(_laplacian(8, 0.1), b)
    assert (solver.factorizations, solver.reused) == (3, 0)


def test_a_changed_pattern_is_analysed_and_factorised_afresh(rng):
    b = rng.standard_normal(8**3)
    solver = LinearSolver("pardiso", reuse=1e-8)
    solver.solve(_laplacian(8, 0.1), b)
    K = (_laplacian(8, 0.1) + sparse.diags([0.01], [3], shape=(8**3, 8**3))).tocsr()
    K = (K + K.T).tocsr()  # symmetric, a wider pattern
    x = solver.solve(K, b)
    assert np.linalg.norm(K @ x - b) <= 1e-10 * np.linalg.norm(b)
    assert (solver.analyses, solver.factorizations, solver.reused) == (2, 2, 0)


def test_step_measure_bounds_the_error_of_the_solution_where_the_residual_does_not(rng):
    # SPD matrices whose diagonal drifts away from the factorised one, a random (rough)
    # right-hand side, and a soft lowest mode (shift 1e-3): a relative residual of 1 % then
    # leaves 2 % error in x (measured 0.021 at drift 0.5), along the soft modes the residual
    # hardly sees; the step measure (the held factorisation's solve of the residual) stops
    # when x itself is within 1 % (measured 0.0024-0.0033), a few more iterations later
    n = 14
    b = rng.standard_normal(n**3)
    drift = rng.uniform(0.0, 1.0, n**3)
    errors = {}
    for measure in ("residual", "step"):
        solver = LinearSolver("pardiso", reuse=1e-2, reuse_measure=measure, reuse_iterations=50)
        errors[measure] = []
        for c in (0.0, 0.5, 1.0, 1.5):
            K = (_laplacian(n, 1e-3) + sparse.diags(c * drift)).tocsr()
            x = solver.solve(K, b)
            exact = sparse.linalg.spsolve(K.tocsc(), b)
            errors[measure].append(np.linalg.norm(x - exact) / np.linalg.norm(exact))
        assert solver.factorizations == 1  # every later matrix reused the first factors
    assert max(errors["step"]) <= 1e-2
    assert max(errors["residual"]) > 1e-2
    with pytest.raises(ValueError, match="reuse_measure='error'"):
        LinearSolver("pardiso", reuse=1e-2, reuse_measure="error")  # type: ignore[arg-type]


def test_release_cores_sets_the_openmp_wait_to_zero_during_calls_only(rng, monkeypatch):
    from harpx.mechanics import linsolve

    wait = linsolve._openmp_wait()
    if wait is None:
        pytest.skip("MKL does not run on the Intel OpenMP runtime here")
    get, _ = wait
    before = get()
    seen = []
    call = LinearSolver._call

    def spy(*args):
        seen.append(get())
        return call(*args)

    monkeypatch.setattr(LinearSolver, "_call", staticmethod(spy))
    K = _laplacian(8, 0.1)
    b = rng.standard_normal(8**3)
    x = LinearSolver("pardiso", release_cores=True).solve(K, b)
    np.testing.assert_allclose(K @ x, b, atol=1e-10)
    assert seen and set(seen) == {0}  # the threads sleep at once after each call
    assert get() == before  # and the caller's own setting is back
    LinearSolver("pardiso").solve(K, b)
    assert seen[-1] == before  # without it, the runtime's setting is left alone


def test_a_new_pardiso_solver_is_what_the_constructor_makes_even_after_the_template_solved():
    # harpx copies pypardiso's import-time solver (its MKL is already found) and resets what
    # a solver owns; after that solver has factorised another matrix, a copy must still equal
    # a freshly constructed one (and share no array with the template)
    import pypardiso

    from harpx.mechanics.linsolve import _new_pardiso

    A = sparse.csr_matrix(np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]]))
    pypardiso.spsolve(A, np.ones(3))  # the template now holds a factorisation
    ours, fresh = vars(_new_pardiso(11)), vars(pypardiso.PyPardisoSolver(mtype=11))
    assert ours.keys() == fresh.keys()
    for key, value in fresh.items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(ours[key], value, err_msg=key)
            assert ours[key] is not getattr(pypardiso.ps, key)
        elif sparse.issparse(value):
            assert ours[key].shape == value.shape, key
        elif key not in ("libmkl", "_mkl_pardiso"):
            assert ours[key] == value, key
    B = sparse.csr_matrix(np.array([[2.0, 0.0], [0.0, 5.0]]))
    np.testing.assert_allclose(_new_pardiso(11).solve(B, np.array([2.0, 5.0])), [1.0, 1.0])
