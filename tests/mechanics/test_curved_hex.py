"""Curved (isoparametric) hex20: 27-node geometry from ``curved_hex_mesh``.

Volume of a thick-walled cylinder sector and its inflation against the closed form
(incompressible neo-Hookean tube, as in ``test_locking.py``), straight vs curved cells;
the curved ventricle's boundary nodes on the analytic ellipsoids; the limits (point
location, hex8) as clear errors.
"""

from __future__ import annotations

import numpy as np
import pytest
import skfem

from harpx.anatomy.ventricle import VentricleGeometry, cavity_volume, ventricle
from harpx.mechanics import Body, Fixed, NeoHookean, Pressure, solve, tube
from harpx.mechanics.mesh import box, curved_hex_mesh

C1 = 1.0
MAT = NeoHookean(c1=C1, kappa=1e4 * C1)


def _closed_form_pressure(a, A=1.0, B=2.0):
    b = np.sqrt(B**2 + a**2 - A**2)
    la, lb = a / A, b / B
    return 2 * C1 * (np.log(la / lb) + 1 / (2 * lb**2) - 1 / (2 * la**2))


@pytest.mark.parametrize(
    ("n_circumferential", "straight_bound", "curved_bound"),
    # measured -9.97e-2 / -2.55e-2 / -6.41e-3 straight, -7.8e-4 / -4.9e-5 / -3.1e-6 curved
    # (2 / 4 / 8 cells per quarter): the chord error ~Δθ², the quadratic arc ~Δθ⁴
    [(2, 0.09, 1.5e-3), (8, 6.0e-3, 1e-5)],
)
def test_curved_tube_volume(n_circumferential, straight_bound, curved_bound):
    exact = 0.25 * np.pi * (2.0**2 - 1.0**2) * 0.2  # quarter of a tube A = 1, B = 2, h = 0.2
    rel = {}
    for curved in (False, True):
        spec = tube(1.0, 2.0, 0.2, n_radial=2, n_circumferential=n_circumferential,
                    angle=np.pi / 2, curved=curved)  # fmt: skip
        body = Body(spec, MAT, element="hex20")
        rel[curved] = body.cell_volume.sum() / exact - 1.0
    print(f"n_circumferential={n_circumferential}: volume error straight {rel[False]:+.2e}, "
          f"curved {rel[True]:+.2e}")  # fmt: skip
    assert rel[False] < -straight_bound  # flat faces cut the outer arc: too small
    assert abs(rel[True]) < curved_bound


def test_curved_tube_geometry_nodes_on_circles():
    spec = tube(1.0, 2.0, 0.5, n_radial=1, n_circumferential=6, n_axial=1, curved=True)
    mesh = spec.mesh
    assert isinstance(mesh, skfem.MeshHex2)
    body = Body(spec, MAT)
    assert body.element == "hex20" and body.nodes.shape[0] == mesh.nvertices
    for name, radius in (("inner", 1.0), ("outer", 2.0)):
        dofs = body.facet_dofs(name, (0,)) // 3
        r = np.hypot(*body.dof_points[dofs, :2].T)
        np.testing.assert_allclose(r, radius, rtol=1e-13)
    # facet geometry nodes (face centres) on the circles too: skfem's facet dofs of Hex2
    fdofs = mesh.dofs.get_facet_dofs(spec.boundaries["outer"]).flatten()
    np.testing.assert_allclose(np.hypot(*mesh.doflocs[:2, fdofs]), 2.0, rtol=1e-13)
    # the full tube with 60° cells: volume π (B² - A²) h, measured -0.24 % (straight -17 %)
    np.testing.assert_allclose(body.cell_volume.sum(), np.pi * 3.0 * 0.5, rtol=4e-3)


def _inflate(n_circumferential, curved):
    spec = tube(1.0, 2.0, 0.2, n_radial=2, n_circumferential=n_circumferential, n_axial=1,
                angle=np.pi / 2, curved=curved)  # fmt: skip
    body = Body(spec, MAT, element="hex20", volumetric="linear-dilatation")
    p = _closed_form_pressure(1.5)
    loads = [Fixed("bottom", (2,)), Fixed("top", (2,)), Fixed("start", (1,)), Fixed("end", (0,)),
             Pressure("inner", p)]  # fmt: skip
    res = solve(body, loads, steps=5)
    inner = body.facet_dofs("inner", (0,)) // 3
    inner = inner[inner < len(body.nodes)]  # vertices: on the circle r = A in both meshes
    x = body.dof_points[inner] + body.nodal_displacement(res.u)[inner]
    a = float(np.hypot(x[:, 0], x[:, 1]).mean())
    return res, _closed_form_pressure(a) / p - 1.0


@pytest.mark.parametrize(
    ("n_circumferential", "straight_bound", "curved_bound"),
    # measured P(a)/p - 1 = -5.38e-2 / -1.20e-2 straight, +1.05e-3 / +2.99e-4 curved
    # (2 / 4 cells per quarter, Q2/P1, κ/C1 = 1e4)
    [(2, 0.04, 0.002), (4, 0.008, 0.001)],
)
def test_curved_tube_inflation_closer_to_closed_form(
    n_circumferential, straight_bound, curved_bound
):
    rel = {}
    for curved in (False, True):
        res, rel[curved] = _inflate(n_circumferential, curved)
        assert res.converged
    print(f"n_circumferential={n_circumferential}: P(a)/p - 1 straight {rel[False]:+.2e}, "
          f"curved {rel[True]:+.2e}")  # fmt: skip
    assert abs(rel[False]) > straight_bound
    assert abs(rel[True]) < curved_bound


def test_curved_ventricle_nodes_on_ellipsoids():
    inner, outer, base = (7.0, 17.0), (10.0, 20.0), 5.0
    kw = dict(inner=inner, outer=outer, truncation=base, n_circumferential=8,
              n_longitudinal=4, n_transmural=1, segments=False)  # fmt: skip
    straight, curved = ventricle(**kw), ventricle(**kw, curved=True)
    assert isinstance(curved.mesh, skfem.MeshHex2)
    assert (straight.mesh.t == curved.mesh.t).all()
    np.testing.assert_array_equal(straight.mesh.p, curved.mesh.p[:, : straight.mesh.p.shape[1]])
    mesh = curved.mesh
    for name, (a, c) in (("endo", inner), ("epi", outer)):
        d = mesh.dofs.get_facet_dofs(curved.boundaries[name]).flatten()  # edge + face nodes
        d = np.concatenate([d, np.unique(mesh.facets[:, curved.boundaries[name]])])
        x = mesh.doflocs[:, d]
        level = (x[0] ** 2 + x[1] ** 2) / a**2 + x[2] ** 2 / c**2
        np.testing.assert_allclose(level, 1.0, atol=1e-10)
    d = mesh.dofs.get_facet_dofs(curved.boundaries["base"]).flatten()
    np.testing.assert_allclose(mesh.doflocs[2, d], base, atol=1e-10)
    # wall volume: closed form of the truncated ellipsoidal shells
    exact = VentricleGeometry(inner=inner, outer=outer, truncation=base).wall_volume()
    vol = {k: Body(s, MAT, element="hex20").cell_volume.sum() / exact - 1.0
           for k, s in (("straight", straight), ("curved", curved))}  # fmt: skip
    print(f"ventricle wall volume error: straight {vol['straight']:+.2e}, "
          f"curved {vol['curved']:+.2e}")  # fmt: skip
    # measured -11.8 % straight, -0.090 % curved (44 cells)
    assert vol["straight"] < -0.1
    assert abs(vol["curved"]) < 2e-3
    # the cavity volume through skfem's FacetBasis on the curved endocardium: measured
    # -11.9 % straight, -0.081 % curved
    geometry = VentricleGeometry(inner=inner, outer=outer, truncation=base)
    cav = {k: cavity_volume(Body(s, MAT, element="hex20")) / geometry.cavity_volume() - 1.0
           for k, s in (("straight", straight), ("curved", curved))}  # fmt: skip
    assert cav["straight"] < -0.1
    assert abs(cav["curved"]) < 2e-3


def test_curved_limits_are_clear_errors():
    spec = tube(1.0, 2.0, 0.2, n_radial=1, n_circumferential=4, angle=np.pi / 2, curved=True)
    with pytest.raises(ValueError, match="hex8"):
        Body(spec, MAT, element="hex8")
    body = Body(spec, MAT)
    with pytest.raises(NotImplementedError, match="curved"):
        body.displacement_at(np.zeros(body.ndof), [1.5, 0.1, 0.1])


def test_curved_hex_mesh_default_is_straight():
    spec = box((2.0, 1.0, 1.0), (2, 1, 1))
    curved = curved_hex_mesh(spec.mesh)
    a, b = Body(spec, MAT, element="hex20"), Body(curved, MAT)
    np.testing.assert_allclose(a.dof_points, b.dof_points, atol=1e-14)
    np.testing.assert_allclose(a.dV, b.dV, rtol=1e-12)
    with pytest.raises(ValueError, match="centre returned shape"):
        curved_hex_mesh(spec.mesh, lambda v: np.zeros((1, 3)))


def test_curved_to_meshio_writes_the_vertices():
    spec = tube(1.0, 2.0, 0.2, n_radial=1, n_circumferential=4, angle=np.pi / 2, curved=True)
    body = Body(spec, MAT)
    u = np.arange(body.ndof, dtype=np.float64)
    m = body.to_meshio(u)
    assert m.cells[0].type == "hexahedron" and m.points.shape == body.nodes.shape
    np.testing.assert_array_equal(m.point_data["displacement"], u.reshape(-1, 3)[: len(body.nodes)])
    back = Body.from_meshio(m, MAT)  # straight: the curved geometry is not written
    assert isinstance(back.mesh, skfem.MeshHex1) and not isinstance(back.mesh, skfem.MeshHex2)
    assert sorted(back.boundaries) == sorted(body.boundaries)
