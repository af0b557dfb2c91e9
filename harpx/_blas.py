"""Matrix products that keep OpenBLAS on the calling thread.

numpy hands a product of more than 65536 × 4 multiply-adds to OpenBLAS's worker threads.
Those threads then busy-wait for a while after the product, and on a machine with as many
cores as threads they take a core from whatever runs next — on the tracker's hot path that is
the sparse factorisation, whose own (MKL) threads it slows markedly. The same holds for
a dot product (or a norm) of more than 10 000 terms, which OpenBLAS also threads. The
products here are cut into blocks below that threshold instead, and dot products and norms
are summed without BLAS: everything runs on the calling thread, and nothing about OpenBLAS's
own settings is changed.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "SINGLE_THREAD_FLOPS",
    "column_block",
    "dot_one_thread",
    "matmul_one_thread",
    "norm_one_thread",
]

#: Multiply-adds of one product below OpenBLAS's threshold for threading (65536 × 4).
SINGLE_THREAD_FLOPS = 65536 * 4 - 1


def column_block(rows: int, inner: int, minimum: int = 8) -> int:
    """Columns of a ``(rows, inner) @ (inner, columns)`` block that stays single-threaded."""
    return max(minimum, SINGLE_THREAD_FLOPS // max(rows * inner, 1))


def matmul_one_thread(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a @ b`` for 2-D float64 ``a`` (m, k) and ``b`` (k, n), in single-threaded blocks.

    Blocks of columns of ``b``, or of rows of ``a`` when ``a`` is the taller; the same
    numbers as ``a @ b`` (each entry is one dot product either way).
    """
    m, k = a.shape
    n = b.shape[1]
    out = np.empty((m, n))
    if m <= n:
        block = column_block(m, k)
        for start in range(0, n, block):  # a few hundred blocks, not a loop over data
            np.matmul(a, b[:, start : start + block], out=out[:, start : start + block])
    else:
        block = column_block(n, k)
        for start in range(0, m, block):
            np.matmul(a[start : start + block], b, out=out[start : start + block])
    return out


def dot_one_thread(a: NDArray[np.floating], b: NDArray[np.floating]) -> float:
    """``a · b`` of two 1-D arrays without BLAS (OpenBLAS threads a dot of > 10 000 terms)."""
    return float(np.einsum("i,i->", a, b))


def norm_one_thread(x: NDArray[np.floating]) -> float:
    """Euclidean norm of a 1-D array, as :func:`numpy.linalg.norm`, on the calling thread."""
    return float(np.sqrt(np.einsum("i,i->", x, x)))
