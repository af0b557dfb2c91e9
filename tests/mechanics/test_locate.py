"""Point location: containing cell and reference coordinates in trilinear hex meshes."""

from __future__ import annotations

import numpy as np

from harpx.mechanics.body import Body
from harpx.mechanics.locate import (
    SKFEM_CORNERS,
    HexLocator,
    interpolation_matrix,
    locate,
    trilinear,
)
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box


def _body() -> Body:
    # coarse mesh so the test is fast
    return Body(box((3.0, 2.0, 1.0), (3, 2, 2)), NeoHookean(c1=1.0, kappa=100.0))


def test_round_trip_in_a_distorted_mesh(rng):
    body = _body()
    nodes = body.nodes + rng.normal(scale=0.05, size=body.nodes.shape)  # cells stay convex
    cells = rng.integers(0, body.ncell, 500)
    xi = rng.uniform(0.02, 0.98, (500, 3))
    points = np.einsum("ma,mai->mi", trilinear(xi), nodes[body.cells[cells]])
    found, xi_found = HexLocator(nodes, body.cells).locate(points)
    # interior points belong to one cell; Newton converges to round-off (tolerance 1e-10)
    np.testing.assert_array_equal(found, cells)
    np.testing.assert_allclose(xi_found, xi, atol=1e-10)


def test_points_outside_are_minus_one():
    body = _body()
    outside = np.array([[-0.1, 1.0, 0.5], [3.2, 1.0, 0.5], [1.5, 1.0, 1.0 + 1e-3]])
    found, xi = HexLocator(body.nodes, body.cells).locate(outside)
    np.testing.assert_array_equal(found, [-1, -1, -1])
    np.testing.assert_array_equal(xi, 0.0)


def test_skfem_and_vtk_orders_give_the_same_point(rng):
    body = _body()
    points = rng.uniform([0.01, 0.01, 0.01], [2.99, 1.99, 0.99], (200, 3))
    c_skfem, xi_skfem = locate(body.mesh, points)
    c_vtk, xi_vtk = HexLocator(body.nodes, body.cells).locate(points)
    np.testing.assert_array_equal(c_skfem, c_vtk)  # same cell ids in both orders
    verts = body.mesh.p.T[body.mesh.t.T]
    back = np.einsum("ma,mai->mi", trilinear(xi_skfem, SKFEM_CORNERS), verts[c_skfem])
    np.testing.assert_allclose(back, points, atol=1e-12)  # map inversion to round-off
    back = np.einsum("ma,mai->mi", trilinear(xi_vtk), body.nodes[body.cells[c_vtk]])
    np.testing.assert_allclose(back, points, atol=1e-12)


def test_interpolation_matrix_reproduces_a_linear_field_and_flags_outside_points():
    body = Body(box((2.0, 1.0, 1.0), (3, 2, 2)), NeoHookean(c1=1.0, kappa=100.0))
    grad = np.array([[0.1, -0.2, 0.05], [0.3, 0.0, -0.1], [0.02, 0.04, 0.2]])
    nodal = body.dof_points @ grad.T  # a linear field, which hex8 reproduces exactly
    rng = np.random.default_rng(1)
    points = rng.uniform([-0.5, -0.2, -0.2], [2.5, 1.2, 1.2], size=(500, 3))
    expected_inside = np.all((points >= 0.0) & (points <= [2.0, 1.0, 1.0]), axis=1)
    # small chunks: the result does not depend on how the points are split
    inside, matrix = interpolation_matrix(body, points, chunk=37)
    np.testing.assert_array_equal(inside, expected_inside)
    assert matrix.shape == (int(expected_inside.sum()), body.dof_points.shape[0])
    np.testing.assert_allclose(matrix @ nodal, points[inside] @ grad.T, atol=1e-12)
