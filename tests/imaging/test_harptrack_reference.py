"""Conventional HARP against a plain reference implementation of the same iteration.

``track_harp`` samples only the points still moving, runs its Gauss–Newton algebra only on
the points that step and solves three-tag normal equations by the adjugate. The reference
below is the textbook loop written directly on :meth:`PhaseSampler.sample` (every active
point sampled, ``numpy.linalg`` for every point), the implementation before those changes;
both must track to the same positions.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from numpy.typing import NDArray

from harpx.errors import HarpxWarning
from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import TOLERANCE, _symmetric_solver, track_harp
from harpx.imaging.sample import PhaseSampler, wrap
from harpx.imaging.synth import synthesize_tagged


def _reference_harp(ds: xr.Dataset, X: NDArray[np.float64], iterations: int = 10) -> NDArray:
    """Positions (time, n, 3) in mm by the plain per-point Gauss–Newton loop (whole grid)."""
    phi0, valid0 = PhaseSampler(ds, 0).phase(X)
    _, s, vt = np.linalg.svd(PhaseSampler(ds, 0).wavevectors, full_matrices=False)
    basis = vt[: int(np.sum(s > 1e-9 * s.max()))].T
    rank = basis.shape[1]
    limit = np.array([float(np.diff(ds[a].values[:2])[0]) for a in ("x", "y", "z")])
    position = X.copy()
    out = np.full((ds.sizes["time"], *X.shape), np.nan)
    out[0] = X
    for t in range(1, ds.sizes["time"]):
        sampler = PhaseSampler(ds, t)
        active = valid0.copy()
        for _ in range(iterations):
            index = np.flatnonzero(active)
            if index.size == 0:
                break
            phi, grad, valid = sampler.sample(position[index])
            error = wrap(phi - phi0[index])
            done = valid & (np.linalg.norm(error, axis=1) < TOLERANCE)
            gb = grad @ basis
            normal = np.einsum("mti,mtj->mij", gb, gb)
            rhs = np.einsum("mti,mt->mi", gb, error)
            scale = np.trace(normal, axis1=1, axis2=2) / rank
            healthy = np.linalg.det(normal) > 1e-10 * np.maximum(scale, 1e-300) ** rank
            update = valid & ~done & healthy
            step = np.zeros((index.size, 3))
            if update.any():
                solved = np.linalg.solve(normal[update], rhs[update][..., None])[..., 0]
                step[update] = -(solved @ basis.T)
            position[index] += np.clip(step, -limit, limit)
            active[index[done | ~valid | ~healthy]] = False
        out[t] = position
    return out


@pytest.fixture(scope="module")
def scene() -> xr.Dataset:
    # three tags, 6 mm period, a smooth motion of up to 1.6 mm a frame: several one-voxel
    # steps per frame, and points near the edges that leave the tissue signal
    def motion(X: NDArray[np.float64], t: float) -> NDArray[np.float64]:
        return 2.0 * t / 100 * np.sin(X[:, [1, 2, 0]] / 5 + 0.3)

    tagged = synthesize_tagged(motion, shape=(8, 24, 20), spacing=(1.5,) * 3,
                               times=[0.0, 50.0, 100.0, 150.0], tag_period=6.0, snr=20.0,
                               oversample=1, rng=0)  # fmt: skip
    return extract_phase(tagged)


def test_track_harp_matches_the_reference_loop(scene: xr.Dataset) -> None:
    pts = np.random.default_rng(1).uniform([-12, -15, -4], [12, 15, 4], (600, 3))
    with pytest.warns(HarpxWarning, match="lost"):  # points leaving the field of view
        out = track_harp(scene, points=pts)
    expected = _reference_harp(scene, pts)
    got = out.points.values + out.displacement.values
    moved = np.isfinite(got).all(axis=-1)
    assert moved[1:].mean() > 0.9  # most points are tracked through every frame
    assert np.abs(expected[1:, :, 0] - pts[:, 0]).max() > 2.0  # and they move
    # same iteration, same samples to ~1e-11 of the data (the cropped prefilter), the
    # normal equations solved by the adjugate instead of LU: equal to far below 1e-6 mm
    np.testing.assert_allclose(got[moved], expected[moved], rtol=0, atol=1e-6)
    assert out.iterations.values[1:].max() > 2  # several Gauss-Newton sweeps were needed


def test_symmetric_solver_agrees_with_lapack() -> None:
    rng = np.random.default_rng(2)
    g = rng.normal(size=(500, 3, 3))
    normal = np.einsum("mti,mtj->mij", g, g)  # symmetric positive (semi)definite
    rhs = rng.normal(size=(500, 3))
    det, solve = _symmetric_solver(normal)
    np.testing.assert_allclose(det, np.linalg.det(normal), rtol=1e-10, atol=1e-12)
    select = det > 1e-3
    expected = np.linalg.solve(normal[select], rhs[select][..., None])[..., 0]
    np.testing.assert_allclose(solve(select, rhs[select]), expected, rtol=1e-8, atol=1e-10)
    # an exact case: diag(2, 4, 8) and its right-hand side (2, 4, 8) -> (1, 1, 1)
    det, solve = _symmetric_solver(np.diag([2.0, 4.0, 8.0])[None])
    assert det.tolist() == [64.0]
    assert solve(np.array([True]), np.array([[2.0, 4.0, 8.0]])).tolist() == [[1.0, 1.0, 1.0]]
    # with two tags (rank 2) LAPACK is used as it is
    two = normal[:, :2, :2]
    det2, solve2 = _symmetric_solver(two)
    np.testing.assert_array_equal(det2, np.linalg.det(two))
    np.testing.assert_array_equal(
        solve2(select, rhs[select, :2]),
        np.linalg.solve(two[select], rhs[select, :2, None])[..., 0],
    )
