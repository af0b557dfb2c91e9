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
    assert solver.factorizations == 1
    assert solver.reused == 3
    assert 0 < solver.last_iterations <= solver.reuse_iterations


def test_a_far_matrix_or_a_refresh_is_factorised_afresh(rng):
    b = rng.standard_normal(10**3)
    solver = LinearSolver("pardiso", reuse=1e-8, reuse_iterations=3)
    solver.solve(_laplacian(10, 0.1), b)
    x = solver.solve(_laplacian(10, 30.0), b)  # far: CG needs many iterations or fails
    exact = sparse.linalg.spsolve(_laplacian(10, 30.0).tocsc(), b)
    assert np.linalg.norm(x - exact) <= 1e-7 * np.linalg.norm(exact)
    solver.refresh()
    before = solver.factorizations
    solver.solve(_laplacian(10, 30.0), b)
    assert solver.factorizations == before + 1


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
