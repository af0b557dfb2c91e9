"""FE tracking on tetrahedral bodies: the phase constraint quadrature and point location."""

from __future__ import annotations

import numpy as np
import pytest
import skfem

from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box, tetrahedralize
from harpx.tracking.constraint import constraint_quadrature
from harpx.tracking.resample import interpolate_displacement, locate
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track
from tests._ideal import ideal_phase

NEO = NeoHookean(c1=1.0, kappa=120.0)


def test_tet_constraint_quadrature_is_dense_and_exact():
    body = Body(tetrahedralize(box((2.0, 2.0, 2.0), (2, 2, 2))), NEO, element="tet10")
    points, weights = constraint_quadrature(body, 0.5)
    # longest edge √3 mm / (1.5 · 0.5 mm) -> m = 3: the centroids of 27 sub-tetrahedra
    assert points.shape == (3, 27)
    assert np.all(points > 0) and np.all(points.sum(axis=0) < 1.0)
    # centroid rule: exact for linear integrands (∫x = 1/24 on the unit tetrahedron)
    np.testing.assert_allclose((points * weights).sum(axis=1), 1 / 24, rtol=1e-13)
    np.testing.assert_allclose(weights.sum(), 1 / 6, rtol=1e-14)
    # neighbouring points no farther apart than the spacing (0.5 mm) in physical space
    X = np.asarray(
        skfem.CellBasis(body.mesh, body._scalar_element, quadrature=(points, weights))
        .global_coordinates()
    ).transpose(1, 2, 0).reshape(-1, 3)  # fmt: skip
    from scipy.spatial import cKDTree

    gap = cKDTree(X).query(X, k=2)[0][:, 1].max()
    assert gap <= 0.5, gap


@pytest.mark.parametrize("curved", [False, True])
def test_locate_in_tetrahedra(curved, rng):
    mesh = skfem.MeshTet2.init_ball(nrefs=1) if curved else skfem.MeshTet1.init_ball(nrefs=1)
    body = Body(mesh, NEO)
    H = 0.1 * rng.standard_normal((3, 3))
    u = (body.dof_points @ H.T).ravel()  # affine: in both FE spaces
    X = rng.uniform(-0.4, 0.4, (200, 3))
    values, inside = interpolate_displacement(body, u[None], X)
    assert inside.all()  # the cube of half-width 0.4 lies inside the coarse ball mesh
    np.testing.assert_allclose(values[0], X @ H.T, atol=1e-9)
    cells, _ = locate(mesh, np.array([[0.0, 0.0, 1.5]]))
    assert cells[0] == -1  # outside: never extrapolated


class _Affine:
    """u(X, t) = (t / 100 ms) (A X + c): an affine motion, exactly invertible."""

    A = np.array([[0.04, 0.06, 0.0], [-0.03, 0.02, 0.0], [0.0, 0.05, -0.03]])
    c = np.array([3.0, -2.0, 1.0])  # mm at t = 100 ms

    def __call__(self, X, t):
        return (t / 100.0) * (X @ self.A.T + self.c)

    def inverse(self, x, t):
        s = t / 100.0
        return np.linalg.solve(np.eye(3) + s * self.A, (x - s * self.c).T).T


def test_track_tet_body():
    half = np.array([12.0, 12.0, 6.0])  # box body, mm

    def inside(X):
        return np.all(np.abs(X) <= half, axis=1) * 1.0

    # coarse 2 mm grid so the test is fast; the moved box stays inside the field of view
    ds = ideal_phase(_Affine(), shape=(12, 18, 18), spacing=(2.0, 2.0, 2.0),
                     times=[0.0, 50.0, 100.0], body=inside)  # fmt: skip
    spec = tetrahedralize(box(tuple(2 * half), (3, 3, 2), origin=tuple(-half)))
    body = Body(spec, NEO)
    assert body.element == "tet4"
    tracked = track(ds, body, epsilon=0.02)
    assert tracked.cells.attrs["element"] == "tet4"
    eps = tracked.epsilon.values[1:]
    assert tracked.target_reached.all() and np.all(eps <= 0.02), f"epsilon per frame {eps}"
    err = tracking_error(tracked, ds)
    print(f"tet4 tracking error: mean {float(err.mean_all):.3f} mm, p95 {float(err.p95_all):.3f}")
    # affine motion: in the tet4 space; ideal phase, ε ≤ 0.02 rad ≈ 0.025 mm of an 8 mm tag
    # period; the remaining error is the penalty's pull against the elastic energy
    assert float(err.mean_all) < 0.1, err.mean.values
    assert float(err.max_all) < 0.5, err.max.values
    assert float(err.coverage) > 0.95
