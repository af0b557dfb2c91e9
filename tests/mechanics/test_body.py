"""Body: quadrature, dof layout, fields, fibres/regions/growth set-up, meshio round trip."""

from __future__ import annotations

import meshio
import numpy as np
import pytest
import skfem

from harpx.io.mesh import read_body
from harpx.mechanics import (
    ActiveContraction,
    Body,
    FiberGrowth,
    Guccione,
    NeoHookean,
    box,
    cylinder,
)

MAT = NeoHookean(c1=1.0, kappa=120.0)


@pytest.mark.parametrize(("element", "nqp", "nb"), [("hex8", 8, 8), ("hex20", 27, 20)])
def test_quadrature_and_dofs(element, nqp, nb):
    body = Body(box((1.0, 2.0, 1.0), (2, 2, 1)), MAT, element=element)
    assert body.nqp == nqp and body.nbasis == nb
    assert body.grad_N.shape == (4, nqp, nb, 3)
    # volume identity of the Gauss rule on an affine box
    np.testing.assert_allclose(body.cell_volume.sum(), 2.0, rtol=1e-13)
    # dof ordering agrees with skfem's ElementVector on the same mesh
    vb = body.basis
    assert vb.N == body.ndof
    np.testing.assert_array_equal(vb.element_dofs.T.reshape(4, nb, 3), body.element_dofs)
    assert body.node_dofs.shape == (body.n_dof_nodes, 3)
    np.testing.assert_allclose(body.dof_points[: len(body.nodes)], body.nodes)


def test_hex20_vtk_cells_edges_are_midpoints():
    body = Body(cylinder(1.0, 1.0, n_radial=1, n_circumferential=8, n_axial=1), MAT,
                element="hex20")  # fmt: skip
    assert body.cells.shape == (body.ncell, 20)
    c = body.dof_points[body.cells]
    edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4),
             (0, 4), (1, 5), (2, 6), (3, 7)]  # fmt: skip
    for k, (a, b) in enumerate(edges):
        # straight edges: the edge node is the exact midpoint (round-off)
        np.testing.assert_allclose(c[:, 8 + k], 0.5 * (c[:, a] + c[:, b]), atol=1e-13)
    # VTK corner order has positive volume orientation: (p1-p0) x (p3-p0) . (p4-p0) > 0
    p = body.nodes[body.cells[:, :8]]
    vol = np.einsum("ni,ni->n", np.cross(p[:, 1] - p[:, 0], p[:, 3] - p[:, 0]), p[:, 4] - p[:, 0])
    assert np.all(vol > 0)


@pytest.mark.parametrize("element", ["hex8", "hex20"])
def test_affine_fields_are_exact(element, rng):
    body = Body(box((1.0, 1.0, 2.0), (2, 1, 2)), MAT, element=element)
    H = 0.1 * rng.standard_normal((3, 3))
    u = (body.dof_points @ H.T).ravel()
    F = body.deformation_gradient(u)
    # affine displacement: F is reproduced to round-off at every Gauss point
    np.testing.assert_allclose(F, np.broadcast_to(np.eye(3) + H, F.shape), atol=1e-13)
    np.testing.assert_allclose(body.jacobian(u), np.linalg.det(np.eye(3) + H), rtol=1e-13)
    E = body.green_strain(u)
    C = (np.eye(3) + H).T @ (np.eye(3) + H)
    np.testing.assert_allclose(E, np.broadcast_to(0.5 * (C - np.eye(3)), E.shape), atol=1e-13)
    np.testing.assert_allclose(body.nodal_displacement(u), u.reshape(-1, 3))


@pytest.mark.parametrize("element", ["hex8", "hex20"])
def test_interpolation_operator(element, rng):
    body = Body(box((1.0, 1.0, 1.0), (2, 2, 1)), MAT, element=element)
    X_q, w_q, N = body.interpolation_operator(intorder=5)
    assert X_q.shape == (body.ncell * 27, 3) and N.shape == (3 * len(X_q), body.ndof)
    np.testing.assert_allclose(w_q.sum(), 1.0, rtol=1e-13)  # quadrature volume identity
    H = rng.standard_normal((3, 3))
    c = rng.standard_normal(3)
    u = (body.dof_points @ H.T + c).ravel()
    # affine fields are interpolated exactly (round-off)
    np.testing.assert_allclose((N @ u).reshape(-1, 3), X_q @ H.T + c, atol=1e-12)
    # cell-major ordering: the first 27 points lie in cell 0
    lo, hi = body.dof_points[body.cells[0]].min(0), body.dof_points[body.cells[0]].max(0)
    assert np.all((X_q[:27] >= lo) & (X_q[:27] <= hi))


def test_facet_dofs_and_bad_names():
    body = Body(box((1.0, 1.0, 1.0), (2, 2, 2)), MAT, element="hex20")
    d = body.facet_dofs("left", components=(0,))
    assert np.all(d % 3 == 0)
    np.testing.assert_allclose(body.dof_points[d // 3, 0], 0.0, atol=1e-14)
    assert len(d) == 21  # 9 vertices + 12 edge nodes on a 2x2 face
    with pytest.raises(KeyError, match="no boundary named 'nope'"):
        body.facet_dofs("nope")
    with pytest.raises(ValueError, match="components"):
        body.facet_dofs("left", components=(3,))
    with pytest.raises(ValueError, match="linear-dilatation' is not available for element='hex8'"):
        Body(box(), MAT, volumetric="linear-dilatation")
    with pytest.raises(ValueError, match="volumetric='plain'"):
        Body(box(), MAT, volumetric="plain")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="element='hex27'"):
        Body(box(), MAT, element="hex27")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="skfem.MeshHex1, MeshHex2, MeshTet1 or MeshTet2"):
        Body(skfem.MeshTri(), MAT)
    with pytest.raises(ValueError, match="expected \\(81,\\) dofs"):
        body_small = Body(box(), MAT)
        body_small.jacobian(np.zeros(5))


def test_fibers_regions_active_growth():
    spec = box((2.0, 1.0, 1.0), (2, 1, 1))
    gucc = Guccione(c=2.0, bf=8.0, bt=2.0, bfs=4.0, kappa=120.0)
    with pytest.raises(ValueError, match="needs 'fibers'"):
        Body(spec, gucc)
    with pytest.raises(ValueError, match="active contraction needs 'fibers'"):
        Body(spec, MAT, active=ActiveContraction(t_max=1.0))
    fib = np.array([[2.0, 0.0, 0.0], [0.0, 0.0, 3.0]])
    regions = {"a": np.array([0]), "b": np.array([1])}
    body = Body(spec, gucc, fibers=fib, regions=regions, active=ActiveContraction(),
                t_max={"a": 5.0})  # fmt: skip
    np.testing.assert_allclose(body.fibers, [[1, 0, 0], [0, 0, 1]])  # normalised
    assert body.fibers_qp.shape == (2, 8, 3)
    np.testing.assert_allclose(body.t_max, [5.0, 0.0])
    with pytest.raises(ValueError, match="region 'c'"):
        body.set_t_max({"c": 1.0})
    with pytest.raises(ValueError, match=r"t_max has shape \(3,\); expected .* \(2,\)"):
        body.set_t_max([1.0, 2.0, 3.0])  # numpy's broadcast error named no variable
    body.set_t_max([1.0, 2.0])
    np.testing.assert_array_equal(body.t_max, [1.0, 2.0])
    body.set_t_max({"a": 5.0})
    with pytest.raises(ValueError, match="fibers has shape"):
        Body(spec, gucc, fibers=np.ones((3, 3)))
    grown = Body(spec, MAT, fibers=fib, growth=FiberGrowth(1.2))
    np.testing.assert_allclose(grown.growth_jacobian, 1.2, rtol=1e-13)  # det Fg = θ
    per_cell = Body(spec, MAT, fibers=fib, growth=np.array([1.1, 0.9]))
    np.testing.assert_allclose(per_cell.growth_jacobian, [1.1, 0.9], rtol=1e-13)
    # fibre stretch of a uniform stretch along x: 1.1 in cell 0 (x-fibre), 1 in cell 1 (z)
    u = (0.1 * body.dof_points * [1.0, 0.0, 0.0]).ravel()
    np.testing.assert_allclose(body.fiber_stretch(u), [1.1, 1.0], rtol=1e-13)
    with pytest.raises(ValueError, match="fiber_stretch needs 'fibers'"):
        Body(spec, MAT).fiber_stretch(u)


def test_a_growth_tensor_field_needs_no_fibres_but_fibre_growth_does():
    # a tensor per Gauss point uses no fibre; the same field was refused by the constructor
    # ("fibre growth needs 'fibers'") while Body.set_growth accepted it
    from harpx.mechanics.fiber_laws import FiberGrowth
    from harpx.physiology.growth import GrowthField

    spec = box((2.0, 1.0, 1.0), (2, 1, 1))
    Fg = np.broadcast_to(np.diag([1.1, 1.0, 1.0]), (2, 8, 3, 3))
    body = Body(spec, MAT, growth=GrowthField(Fg))
    np.testing.assert_allclose(body.growth_jacobian, [1.1, 1.1], rtol=1e-14)
    plain = Body(spec, MAT)
    plain.set_growth(GrowthField(Fg))
    np.testing.assert_array_equal(plain.growth_tensor, body.growth_tensor)
    for growth in (FiberGrowth(1.1), np.full(2, 1.1)):
        with pytest.raises(ValueError, match="fibre growth needs 'fibers'"):
            Body(spec, MAT, growth=growth)
        with pytest.raises(ValueError, match="fibre growth needs 'fibers'"):
            plain.set_growth(growth)


@pytest.mark.parametrize("element", ["hex8", "hex20"])
def test_meshio_round_trip(tmp_path, element):
    spec = cylinder(1.0, 2.0, n_radial=1, n_circumferential=8, n_axial=2, wall_thickness=0.2)
    fib = np.tile([0.0, 0.0, 1.0], (spec.mesh.nelements, 1))
    body = Body(spec, MAT, fibers=fib, element=element)
    path = tmp_path / "body.vtu"
    meshio.write(path, body.to_meshio(np.zeros(body.ndof)))
    back = read_body(path, MAT, element=element)
    # exact round trip of geometry, connectivity, names and fibres (binary VTU)
    np.testing.assert_array_equal(back.nodes, body.nodes)
    np.testing.assert_array_equal(back.cells, body.cells)
    assert sorted(back.regions) == sorted(body.regions)
    for k in body.regions:
        np.testing.assert_array_equal(np.sort(back.regions[k]), np.sort(body.regions[k]))
    for k in body.boundaries:
        np.testing.assert_array_equal(np.sort(back.boundaries[k]), np.sort(body.boundaries[k]))
    np.testing.assert_array_equal(back.fibers, body.fibers)


def test_from_meshio_needs_no_file_and_paths_go_through_io(tmp_path):
    body = Body(box((1.0, 1.0, 1.0), (2, 1, 1)), MAT, fibers=np.tile([1.0, 0.0, 0.0], (2, 1)))
    back = Body.from_meshio(body.to_meshio(), MAT)
    np.testing.assert_array_equal(back.nodes, body.nodes)
    np.testing.assert_array_equal(back.cells, body.cells)
    np.testing.assert_array_equal(back.fibers, body.fibers)
    # mechanics reads no files: a path (or a meshio mesh) names the entry point to use
    with pytest.raises(TypeError, match=r"read it with harpx\.io\.mesh\.read_body"):
        Body(tmp_path / "body.vtu", MAT)
    with pytest.raises(TypeError, match=r"Body\.from_meshio\(mesh\)"):
        Body(body.to_meshio(), MAT)


def test_read_hexahedron20_file(tmp_path):
    body = Body(box((1.0, 1.0, 1.0), (2, 1, 1)), MAT, element="hex20")
    m = meshio.Mesh(body.dof_points, [("hexahedron20", body.cells)])
    path = tmp_path / "q.vtu"
    meshio.write(path, m)
    back = read_body(path, MAT, element="hex20")
    assert back.ndof == body.ndof and back.ncell == 2
    np.testing.assert_allclose(back.dof_points[back.cells], body.dof_points[body.cells])
    with pytest.raises(ValueError, match="expected 'hexahedron'"):
        meshio.write(tmp_path / "t.vtu", meshio.Mesh(np.eye(3), [("triangle", [[0, 1, 2]])]))
        read_body(tmp_path / "t.vtu", MAT)
