"""Test helpers shared by the harpx test suite."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import dask
import numpy as np


class _CountingScheduler:
    """A dask scheduler that fails when asked to compute more than ``max_computes`` times."""

    def __init__(self, max_computes: int) -> None:
        self.count = 0
        self.max_computes = max_computes

    def __call__(self, dsk, keys, **kwargs):  # type: ignore[no-untyped-def]
        self.count += 1
        if self.count > self.max_computes:
            raise RuntimeError(
                f"dask computed {self.count} times; at most {self.max_computes} expected"
            )
        return dask.get(dsk, keys, **kwargs)


@contextlib.contextmanager
def raise_if_dask_computes(max_computes: int = 0) -> Iterator[None]:
    """Fail if dask computes anything inside the block (beyond ``max_computes`` times)."""
    scheduler = _CountingScheduler(max_computes)
    with dask.config.set(scheduler=scheduler):
        yield


def still(X, t):  # type: ignore[no-untyped-def]
    """No motion: u(X, t) = 0 (mm)."""
    return np.zeros_like(X)


def shear(X, t):  # type: ignore[no-untyped-def]
    """Translation plus smooth shear (mm): |u| up to 8.2 mm, gradients <= 0.25 at t = 100 ms."""
    s = t / 100.0
    u = np.empty_like(X)
    u[:, 0] = s * (5.0 + 1.5 * np.sin(2 * np.pi * X[:, 1] / 50))
    u[:, 1] = s * (3.0 + 2.0 * np.cos(2 * np.pi * X[:, 0] / 50))
    u[:, 2] = s * np.sin(2 * np.pi * X[:, 0] / 50)
    return u
