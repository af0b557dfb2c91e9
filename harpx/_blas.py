"""Matrix products that keep OpenBLAS on the calling thread.

numpy hands a product of more than 65536 × 4 multiply-adds to OpenBLAS's worker threads.
Those threads then busy-wait for a while after the product, and on a machine with as many
cores as threads they take a core from whatever runs next — on the tracker's hot path that is
the sparse factorisation, whose own (MKL) threads it slows by a third (paper phantom, 2
cores: 0.073 s per factorisation alone, 0.112 s after a threaded product). The products here
are cut into column blocks below that threshold instead: each block runs on the calling
thread, and nothing about OpenBLAS's own settings is changed.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["SINGLE_THREAD_FLOPS", "column_block", "matmul_one_thread"]

#: Multiply-adds of one product below OpenBLAS's threshold for threading (65536 × 4).
SINGLE_THREAD_FLOPS = 65536 * 4 - 1


def column_block(rows: int, inner: int, minimum: int = 8) -> int:
    """Columns of a ``(rows, inner) @ (inner, columns)`` block that stays single-threaded."""
    return max(minimum, SINGLE_THREAD_FLOPS // max(rows * inner, 1))


def matmul_one_thread(a: NDArray[np.floating], b: NDArray[np.floating]) -> NDArray[np.floating]:
    """``a @ b`` for 2-D ``a`` (m, k) and ``b`` (k, n), in single-threaded column blocks.

    The same numbers as ``a @ b`` (each column is computed by one product either way).
    """
    m, k = a.shape
    out = np.empty((m, b.shape[1]), dtype=np.result_type(a, b))
    block = column_block(m, k)
    for start in range(0, b.shape[1], block):  # a few hundred blocks, not a loop over data
        np.matmul(a, b[:, start : start + block], out=out[:, start : start + block])
    return out
