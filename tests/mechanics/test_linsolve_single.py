"""PARDISO with single-precision factors (``factors="single"``): refined to the accuracy asked."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse import linalg as spla

from harpx.mechanics.linsolve import LinearSolver, available_methods
from tests.mechanics.test_linsolve_reuse import _convection, _laplacian

pytestmark = pytest.mark.skipif(
    "pardiso" not in available_methods(), reason="PARDISO (pypardiso) is not available"
)

N = 12
#: smallest eigenvalue of the 12³ seven-point Laplacian: 3 (2 - 2 cos(π / 13))
LOWEST = 6.0 * (1.0 - np.cos(np.pi / (N + 1)))


def _relative_error(K: sparse.csr_matrix, x: np.ndarray, b: np.ndarray) -> float:
    exact = spla.spsolve(K.tocsc(), b)
    return float(np.linalg.norm(x - exact) / np.linalg.norm(exact))


def test_single_factors_solve_fresh_and_nearby_matrices_to_double_accuracy(rng):
    # single-precision factors alone leave a relative error of 7e-7 here (measured: their
    # solve without refinement), above the bound below; the refinement of a fresh
    # factorisation and the reuse loop both stop at a 1e-8 residual
    b = rng.standard_normal(N**3)
    solver = LinearSolver("pardiso", reuse=1e-8, factors="single")
    for k, shift in enumerate((0.10, 0.11, 0.12, 0.125)):
        K = _laplacian(N, shift)
        x = solver.solve(K, b)
        assert _relative_error(K, x, b) <= 1e-7, k
        assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b), k
    assert (solver.factors, solver.factorizations, solver.reused) == ("single", 1, 3)


def test_single_factors_of_nearby_non_symmetric_matrices_reach_the_accuracy_asked(rng):
    # the non-symmetric mode (scaling and weighted matching) in single precision: the fresh
    # factorisation refined, the later matrices by BiCGSTAB with those factors
    b = rng.standard_normal(10**3)
    solver = LinearSolver("pardiso", reuse=1e-8, factors="single")
    for k, speed in enumerate((1.0, 1.05, 1.1, 1.12)):
        K = _convection(10, speed, 0.1)
        x = solver.solve(K, b, symmetric=False)
        assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b), k
        assert _relative_error(K, x, b) <= 1e-6, k
    assert (solver.factors, solver.factorizations, solver.reused) == ("single", 1, 3)


def test_single_factors_of_an_indefinite_matrix_are_refined_without_cg(rng):
    # refinement needs no definiteness: the Laplacian shifted below its lowest eigenvalue
    # (the single-precision solve alone: relative error 1e-5)
    b = rng.standard_normal(N**3)
    K = _laplacian(N, -1.0)
    solver = LinearSolver("pardiso", reuse=1e-10, factors="single")
    assert _relative_error(K, solver.solve(K, b), b) <= 1e-9
    assert solver.factors == "single"


@pytest.mark.parametrize(("gap", "kept"), [(1e-4, "single"), (1e-6, "double")])
def test_a_matrix_too_ill_conditioned_for_single_precision_turns_the_solver_to_double(
    rng, gap, kept
):
    # lowest eigenvalue ``gap``: condition ~ 12 / gap. At 1e4 the single factors' refinement
    # contracts by ~1e-3 a step and converges; at 1e6 (×6e-8 ≈ 0.7) it does not within its
    # steps, and the solver analyses and factorises again in double precision, for good
    b = rng.standard_normal(N**3)
    K = _laplacian(N, gap - LOWEST)
    solver = LinearSolver("pardiso", reuse=1e-8, factors="single")
    x = solver.solve(K, b)
    assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b)
    assert solver.factors == kept
    assert solver.analyses == (1 if kept == "single" else 2)


def test_factor_precision_is_checked_and_needs_reuse():
    with pytest.raises(ValueError, match="factors='half' is not 'double' or 'single'"):
        LinearSolver("pardiso", reuse=1e-2, factors="half")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="factors='single' needs reuse"):
        LinearSolver("pardiso", factors="single")
    # other methods factorise in double precision whatever is asked
    assert LinearSolver("superlu", reuse=1e-2, factors="single").factors == "double"
