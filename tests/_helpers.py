"""Test helpers shared by the harpx test suite."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import dask


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
