"""What users hand to a Body: masks and ids of regions and facets, nodal fibres, parameters.

Truths are constructed inputs (the facets on z = 0 found from the coordinates, cells found
from their centres), closed forms (the Gauss points of a box cell, the Poisson ratio of the
linearised neo-Hookean law) and finite differences of the laws' own Cauchy stress.
"""

from __future__ import annotations

import numpy as np
import pytest

from harpx.errors import HarpxWarning
from harpx.mechanics import (
    Body,
    Fixed,
    Guccione,
    NeoHookean,
    Prescribed,
    box,
    solve,
    tetrahedralize,
)
from harpx.mechanics.loads import Pressure

MAT = NeoHookean(c1=1.0, kappa=120.0)
GUC = Guccione(c=0.88, bf=8.0, bt=6.0, bfs=12.0, kappa=100.0)


@pytest.fixture(scope="module")
def column():
    """1 x 1 x 2 mm column of 2 x 2 x 4 hex8 cells, its z = 0 facet mask and z < 1 cells."""
    spec = box((1.0, 1.0, 2.0), (2, 2, 4))
    body = Body(spec, MAT)
    p, f = body.mesh.p, body.mesh.facets
    bottom = np.all(np.isclose(p[2, f], 0.0), axis=0)  # (nfacet,) bool
    lower = body.quadrature_points.mean(axis=1)[:, 2] < 1.0  # (ncell,) bool
    return spec, body, bottom, lower


# ------------------------------------------------------------------ masks and ids


def test_boolean_facet_mask_selects_the_masked_facets(column):
    _, body, bottom, _ = column
    assert bottom.sum() == 4  # 2 x 2 quads on z = 0
    np.testing.assert_array_equal(body.facets(bottom), np.flatnonzero(bottom))
    np.testing.assert_array_equal(np.sort(body.facets(bottom)), np.sort(body.boundaries["bottom"]))
    np.testing.assert_array_equal(body.facet_dofs(bottom), body.facet_dofs("bottom"))


def test_fixed_by_a_boolean_mask_holds_the_masked_face(column):
    # the face z = 0 held through a mask, the top pulled 0.3 mm along x: the z = 0 face does
    # not move (its dofs are constrained: exactly 0), as with Fixed("bottom")
    _, body, bottom, _ = column
    top = body.boundaries["top"]

    def pull(X, s):
        return np.column_stack([0.3 * s + 0 * X[:, 0], 0 * X[:, 0], 0 * X[:, 0]])

    by_mask = solve(body, [Fixed(bottom), Prescribed(top, pull)], steps=2)
    by_name = solve(body, [Fixed("bottom"), Prescribed(top, pull)], steps=2)
    z0 = np.isclose(body.dof_points[:, 2], 0.0)
    assert np.abs(by_mask.u.reshape(-1, 3)[z0]).max() == 0.0
    np.testing.assert_allclose(by_mask.u, by_name.u, atol=1e-12)


def test_pressure_on_a_boolean_mask_equals_pressure_on_the_named_boundary(column):
    _, body, bottom, _ = column
    u = np.zeros(body.ndof)
    r_mask = Pressure(bottom, 2.0).residual_tangent(body, u, 1.0)[0]
    r_name = Pressure("bottom", 2.0).residual_tangent(body, u, 1.0)[0]
    np.testing.assert_allclose(r_mask, r_name, atol=1e-14)
    # 2 kPa on 1 mm^2 pushing into the body along +z: total force 2 mN on the face
    np.testing.assert_allclose(abs(r_mask.reshape(-1, 3)[:, 2].sum()), 2.0, rtol=1e-12)


def test_regions_and_boundaries_given_as_boolean_masks(column):
    spec, body, bottom, lower = column
    masked = Body(spec, MAT, regions={"apex": lower, "base": ~lower}, boundaries={"b": bottom})
    assert lower.sum() == 8  # the two lower layers of 2 x 2 cells
    np.testing.assert_array_equal(masked.regions["apex"], np.flatnonzero(lower))
    np.testing.assert_array_equal(masked.regions["base"], np.flatnonzero(~lower))
    np.testing.assert_array_equal(masked.boundaries["b"], np.flatnonzero(bottom))


def test_integral_float_ids_are_ids(column):
    spec, body, _, _ = column
    masked = Body(spec, MAT, regions={"a": [1.0, 5.0]}, boundaries={"b": np.array([3.0])})
    np.testing.assert_array_equal(masked.regions["a"], [1, 5])
    np.testing.assert_array_equal(masked.boundaries["b"], [3])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"regions": {"apex": np.ones(17, bool)}}, r"region 'apex' is a boolean mask .*\(16,\)"),
        ({"boundaries": {"b": np.ones(16, bool)}}, r"boundary 'b' is a boolean mask .*\(68,\)"),
        ({"regions": {"apex": [1.5, 2.0]}}, r"region 'apex' holds cell id 1.5, which is not"),
        ({"boundaries": {"b": [68]}}, r"boundary 'b' holds facet id 68, outside \[0, 68\)"),
        ({"boundaries": {"b": [-1]}}, r"boundary 'b' holds facet id -1"),
        ({"regions": {"apex": np.arange(16) % 2}}, r"region 'apex' is 16 integer ids .* 0 or 1"),
        ({"regions": {"apex": [[0, 1]]}}, r"region 'apex' has shape \(1, 2\)"),
    ],
)
def test_bad_region_and_boundary_sets_are_refused_by_name(column, kwargs, match):
    spec, body, _, _ = column
    assert body.ncell == 16 and body.mesh.facets.shape[1] == 68
    with pytest.raises(ValueError, match=match):
        Body(spec, MAT, **kwargs)


def test_bad_facet_masks_for_loads_are_refused(column):
    _, body, bottom, _ = column
    boundary_only = bottom[body.mesh.boundary_facets()]  # one entry per boundary facet
    with pytest.raises(ValueError, match=r"facet ids is a boolean mask .*shape \(68,\)"):
        body.facets(boundary_only)
    with pytest.raises(ValueError, match="selects no facet"):
        Fixed(np.zeros(68, bool)).dofs(body)
    with pytest.raises(ValueError, match="facet id 2.5, which is not an integer"):
        body.facets([2.5])


# ------------------------------------------------------------------ fibres per node


def _turning(X):
    """Unit fibres turning about z with x: angle 0.6 rad per mm (a constructed field)."""
    a = 0.6 * X[:, 0]
    return np.column_stack([np.cos(a), np.sin(a), 0.0 * a])


@pytest.mark.parametrize(
    ("element", "gauss"),
    [("hex8", [-1.0 / np.sqrt(3.0), 1.0 / np.sqrt(3.0)]), ("hex20", [-(0.6**0.5), 0.0, 0.6**0.5])],
)
def test_fibres_per_vertex_are_interpolated_to_the_gauss_points(element, gauss):
    # cells of width h = 1 mm in x from x0 = 0, 1, 2; a field of x only: at a Gauss point
    # at x = x0 + h (1 + g) / 2 the trilinear interpolant of the vertex fibres is
    # w0 f(x0) + w1 f(x0 + h), w1 = (1 + g) / 2, normalised
    body = Body(box((3.0, 1.0, 1.0), (3, 1, 1)), GUC, element=element,
                fibers=_turning(box((3.0, 1.0, 1.0), (3, 1, 1)).mesh.p.T))  # fmt: skip
    assert body.fibers_per == "node"
    x = body.quadrature_points[..., 0]
    x0 = np.floor(x)
    g = 2.0 * (x - x0) - 1.0
    np.testing.assert_allclose(np.unique(np.round(g, 12)), gauss, atol=1e-12)
    w1 = (0.5 * (1.0 + g))[..., None]
    ends = [_turning(np.stack([e, 0 * e, 0 * e], axis=-1).reshape(-1, 3)) for e in (x0, x0 + 1)]
    want = (1 - w1) * ends[0].reshape(x.shape + (3,)) + w1 * ends[1].reshape(x.shape + (3,))
    want /= np.linalg.norm(want, axis=-1)[..., None]
    np.testing.assert_allclose(body.fibers_qp, want, atol=1e-14)
    # and close to the field itself: the chord of a 0.6 rad turn across a cell is at most
    # atan(w sin 0.6 / (1 - w + w cos 0.6)) - 0.6 w = 0.22 degrees off (w = 0.79)
    exact = _turning(body.quadrature_points.reshape(-1, 3)).reshape(want.shape)
    angle = np.degrees(np.arccos(np.clip(np.einsum("eqi,eqi->eq", want, exact), -1, 1)))
    assert angle.max() < 0.25


def test_fibres_per_dof_node_use_the_quadratic_shape_functions():
    # hex20 given fibres at its 20-node dof points, a field of x only: the serendipity
    # interpolant is the quadratic through x0, x0 + h/2, x0 + h (h = 1 mm) along x,
    # L = ((1 - t)(1 - 2t), 4t(1 - t), t(2t - 1)) at t = x - x0, then normalised
    spec = box((3.0, 1.0, 1.0), (3, 1, 1))
    points = Body(spec, MAT, element="hex20").dof_points
    body = Body(spec, GUC, element="hex20", fibers=_turning(points))
    assert body.fibers_per == "node" and len(points) == 44 and len(body.nodes) == 16
    x = body.quadrature_points[..., 0].reshape(-1)
    x0 = np.floor(x)
    t = (x - x0)[:, None]
    on_x = [_turning(np.column_stack([x0 + d, 0 * x, 0 * x])) for d in (0.0, 0.5, 1.0)]
    want = (1 - t) * (1 - 2 * t) * on_x[0] + 4 * t * (1 - t) * on_x[1] + t * (2 * t - 1) * on_x[2]
    want /= np.linalg.norm(want, axis=-1)[:, None]
    np.testing.assert_allclose(body.fibers_qp.reshape(-1, 3), want, atol=1e-14)


def test_node_fibres_of_either_sign_are_the_same_fibres():
    spec = box((3.0, 1.0, 1.0), (3, 1, 1))
    nodal = _turning(spec.mesh.p.T)
    flipped = nodal * np.where(np.arange(len(nodal)) % 3 == 0, -1.0, 1.0)[:, None]
    a = Body(spec, GUC, fibers=nodal).fibers_qp
    b = Body(spec, GUC, fibers=flipped).fibers_qp
    dots = np.einsum("eqi,eqi->eq", a, b)
    np.testing.assert_allclose(np.abs(dots), 1.0, atol=1e-14)


def test_hex8_per_corner_fibres_are_refused():
    # nodal[body.cells] has the shape of per-Gauss-point fibres on hex8, (ncell, 8, 3), but
    # Gauss point k is not at corner k
    spec = box((3.0, 1.0, 1.0), (3, 1, 1))
    body = Body(spec, GUC, fibers=_turning)
    with pytest.raises(ValueError, match=r"per-corner values .* shape \(16, 3\)"):
        Body(spec, GUC, fibers=_turning(body.nodes)[body.cells])


def test_hex8_per_gauss_point_fibres_are_still_accepted():
    # what harpx itself passes on (e.g. with_active_law: fibers=body.fibers_qp)
    spec = box((3.0, 1.0, 1.0), (3, 1, 1))
    body = Body(spec, GUC, fibers=_turning)
    again = Body(spec, GUC, fibers=body.fibers_qp)
    assert again.fibers_per == "quadrature point"
    np.testing.assert_array_equal(again.fibers_qp, body.fibers_qp)
    # per cell, varying from cell to cell, given per point: accepted as it is
    per_cell = np.repeat(_turning(body.quadrature_points.mean(axis=1))[:, None], 8, axis=1)
    np.testing.assert_allclose(Body(spec, GUC, fibers=per_cell).fibers_qp, per_cell, atol=1e-15)


def test_single_hex8_cell_per_point_fibres_warn_and_flag():
    spec = box((1.0, 1.0, 1.0), (1, 1, 1))
    body = Body(spec, GUC, fibers=_turning)
    with pytest.warns(HarpxWarning, match="no node is shared by two cells"):
        one = Body(spec, GUC, fibers=body.fibers_qp)
    assert one.fibers_per == "quadrature point or corner"
    np.testing.assert_array_equal(one.fibers_qp, body.fibers_qp)


def test_as_many_nodes_as_cells_reads_per_cell_and_warns():
    # 2 x 1 x 1 hexahedra cut into 12 tetrahedra with 12 vertices: (12, 3) is per cell
    spec = tetrahedralize(box((2.0, 1.0, 1.0), (2, 1, 1)))
    body = Body(spec, MAT)
    assert body.ncell == 12 and len(body.nodes) == 12
    fib = _turning(body.quadrature_points.mean(axis=1))
    with pytest.warns(HarpxWarning, match="as many nodes as cells"):
        both = Body(spec, GUC, fibers=fib)
    assert both.fibers_per == "cell or node"
    np.testing.assert_allclose(both.fibers_qp[:, 0], fib, atol=1e-15)
    uniform = Body(spec, GUC, fibers=np.tile([0.0, 0.0, 2.0], (12, 1)))  # no warning
    assert uniform.fibers_per == "cell"


def test_fibres_of_another_shape_name_all_accepted_shapes():
    spec = box((3.0, 1.0, 1.0), (3, 1, 1))
    with pytest.raises(ValueError, match=r"\(3, 3\) per cell, \(16, 3\) per node .*\(3, 8, 3\)"):
        Body(spec, GUC, fibers=np.ones((5, 3)))


# ------------------------------------------------------------------ material parameters


def _small_strain_poisson(mat, fiber=None, h=1e-6):
    """Smallest Poisson ratio along x, y, z from central differences of the Cauchy stress."""
    D = np.zeros((3, 3))
    for b in range(3):
        step = np.zeros((3, 3))
        step[b, b] = h
        plus = mat.cauchy_stress(np.eye(3) + step, fiber)
        minus = mat.cauchy_stress(np.eye(3) - step, fiber)
        D[:, b] = np.diag(plus - minus) / (2 * h)
    S = np.linalg.inv(D)
    nu = -S / np.diag(S)[:, None]
    return nu[~np.eye(3, dtype=bool)].min()


def test_swapped_neo_hookean_parameters_warn():
    with pytest.warns(HarpxWarning, match=r"kappa=1.0 kPa is small for c1=120.0 kPa.*-0.981"):
        mat = NeoHookean(c1=120.0, kappa=1.0)
    # closed form (3 kappa - 4 C1) / (2 (3 kappa + 2 C1)) = -477 / 486
    assert mat.poisson_ratio == pytest.approx(-477.0 / 486.0, rel=1e-14)
    assert _small_strain_poisson(mat) == pytest.approx(mat.poisson_ratio, abs=1e-7)
    with pytest.warns(HarpxWarning, match="nearly incompressible"):
        NeoHookean(c1=1.0, kappa=0.5)


def test_nearly_incompressible_and_compressible_neo_hookean_do_not_warn():
    # pyproject turns a HarpxWarning into an error: constructing these must be silent
    assert MAT.poisson_ratio == pytest.approx((360.0 - 4.0) / (2 * 362.0), rel=1e-14)
    assert NeoHookean(c1=1.0, kappa=10.0).poisson_ratio == pytest.approx(26.0 / 64.0)


def test_guccione_with_a_tiny_bulk_modulus_warns():
    with pytest.warns(HarpxWarning, match=r"Guccione: kappa=1.0 kPa is small for c=0.88 kPa"):
        mat = Guccione(c=0.88, bf=18.5, bt=3.58, bfs=1.63, kappa=1.0)
    fiber = np.array([1.0, 0.0, 0.0])
    assert mat.poisson_ratio < -0.4
    assert _small_strain_poisson(mat, fiber) == pytest.approx(mat.poisson_ratio, abs=1e-7)
    myocardium = Guccione(c=0.88, bf=18.5, bt=3.58, bfs=1.63, kappa=350.0)  # silent
    assert _small_strain_poisson(myocardium, fiber) == pytest.approx(
        myocardium.poisson_ratio, abs=1e-7
    )
    assert myocardium.poisson_ratio > 0.0
