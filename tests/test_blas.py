"""Single-threaded blocked matrix products (harpx._blas)."""

from __future__ import annotations

import numpy as np
import pytest

from harpx._blas import SINGLE_THREAD_FLOPS, column_block, matmul_one_thread


@pytest.mark.parametrize(("m", "k", "n"), [(64, 27, 38880), (3, 5, 7), (200, 300, 1001)])
def test_blocked_product_is_the_product(m: int, k: int, n: int) -> None:
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((m, k)), rng.standard_normal((k, n))
    # every column is one dot-product sequence either way: equal to rounding of the order
    np.testing.assert_allclose(matmul_one_thread(a, b), a @ b, rtol=0, atol=1e-12 * k)


def test_blocks_stay_below_the_threading_threshold() -> None:
    # the tracker's constraint tangent: (64, 27) @ (27, 9 ncell)
    block = column_block(64, 27)
    assert 64 * 27 * block <= SINGLE_THREAD_FLOPS < 64 * 27 * (block + 1)
    assert column_block(10**4, 10**4) == 8  # never fewer columns than the minimum


def test_tall_blocked_product_and_reductions_match_numpy() -> None:
    from harpx._blas import dot_one_thread, norm_one_thread

    rng = np.random.default_rng(1)
    a, b = rng.standard_normal((4250, 8)), rng.standard_normal((8, 8))  # rows are blocked
    np.testing.assert_allclose(matmul_one_thread(a, b), a @ b, rtol=0, atol=1e-12)
    x, y = rng.standard_normal(15444), rng.standard_normal(15444)
    assert dot_one_thread(x, y) == pytest.approx(float(x @ y), rel=1e-12)
    assert norm_one_thread(x) == pytest.approx(float(np.linalg.norm(x)), rel=1e-12)
