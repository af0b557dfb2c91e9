"""A singular matrix is a ConvergenceError of the direct solvers, as their contract says."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from harpx.errors import ConvergenceError
from harpx.mechanics.linsolve import LinearSolver

#: rows 0 and 1 are equal: exactly singular (SuperLU finds a zero pivot)
SINGULAR = sparse.csr_matrix(np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 2.0]]))


@pytest.mark.parametrize("method", ["superlu", "superlu-colamd"])
@pytest.mark.parametrize("symmetric", [True, False])
def test_superlu_names_a_singular_matrix(method: str, symmetric: bool) -> None:
    with pytest.raises(ConvergenceError, match="SuperLU could not factorise the 3-dof matrix"):
        LinearSolver(method).solve(SINGULAR, np.array([1.0, 2.0, 3.0]), symmetric=symmetric)


@pytest.mark.parametrize("method", ["superlu", "superlu-colamd"])
def test_superlu_still_solves_a_regular_matrix(method: str) -> None:
    K = sparse.csr_matrix(np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 2.0]]))
    x = LinearSolver(method).solve(K, np.array([3.0, 3.0, 4.0]))
    np.testing.assert_allclose(x, [1.0, 1.0, 2.0], rtol=1e-14)
