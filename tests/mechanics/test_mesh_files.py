"""Mesh files read into a Body or MeshSpec: named sets, curved quadratic cells, bad cells.

The truth is constructed: regions from the cell centroids, boundaries from the facets whose
nodes all lie on a plane, the edge offset of a curved tube from the circle's sagitta.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest
import skfem
from skfem.io.meshio import HEX_MAPPING

from harpx.errors import HarpxWarning
from harpx.io.mesh import read_body, read_body_mesh
from harpx.mechanics.body import Body
from harpx.mechanics.cells import warn_dropped_curvature
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box, tetrahedralize, tube

MAT = NeoHookean(c1=1.0, kappa=120.0)


def _facets_on_plane(mesh: skfem.Mesh, axis: int, value: float) -> np.ndarray:
    """Facet ids of ``mesh`` whose nodes all lie on the plane x[axis] = value (mm)."""
    on = np.isclose(mesh.p[axis, mesh.facets], value, atol=1e-12).all(axis=0)
    return np.flatnonzero(on)


def _tet_box() -> tuple[Body, np.ndarray, np.ndarray, np.ndarray]:
    """Unit box of 48 tetrahedra; cell ids below / above z = 0.5; the floor triangles."""
    body = Body(tetrahedralize(box((1.0, 1.0, 1.0), (2, 2, 2))), MAT)
    tets = body.to_meshio().cells_dict["tetra"]
    below = body.nodes[tets].mean(axis=1)[:, 2] < 0.5
    floor = body.mesh.facets.T[_facets_on_plane(body.mesh, 2, 0.0)]
    return body, tets, below, floor


# --- 1: harpx's own files keep their named regions and boundaries ----------------------


def test_read_body_mesh_keeps_the_regions_and_boundaries_body_to_meshio_writes(
    tmp_path: Path,
) -> None:
    spec = box((2.0, 1.0, 1.0), (4, 2, 2))
    x = spec.mesh.p[0, spec.mesh.t].mean(axis=0)
    regions = {"front_half": np.flatnonzero(x < 1.0), "back_half": np.flatnonzero(x >= 1.0)}
    body = Body(spec, MAT, regions=regions)
    path = tmp_path / "body.vtu"
    meshio.write(path, body.to_meshio())  # skfem:s:/skfem:b: cell data
    back = read_body_mesh(path)
    assert sorted(back.regions) == ["back_half", "front_half"]
    for name, cells in regions.items():
        np.testing.assert_array_equal(back.regions[name], cells)  # 8 cells each
    assert len(back.regions["front_half"]) == 8
    # boundary "left" (x = 0) is the 4 facets of the read mesh lying on that plane
    truth = _facets_on_plane(back.mesh, 0, 0.0)
    assert truth.size == 4
    np.testing.assert_array_equal(np.sort(back.boundaries["left"]), truth)
    np.testing.assert_array_equal(
        np.sort(back.boundaries["right"]), _facets_on_plane(back.mesh, 0, 2.0)
    )
    # the same names as read_body, and carried by the skfem mesh (Body picks them up)
    rebuilt = Body(back, MAT)
    assert sorted(rebuilt.boundaries) == sorted(read_body(path, MAT).boundaries)
    np.testing.assert_array_equal(np.sort(rebuilt.boundaries["left"]), truth)


# --- 2: gmsh physical groups and meshio cell sets ------------------------------------


def test_cell_sets_become_regions_and_boundaries() -> None:
    body, tets, below, floor = _tet_box()
    mesh = meshio.Mesh(
        body.nodes,
        [("triangle", floor), ("tetra", tets)],
        cell_sets={
            "lower": [np.array([], dtype=int), np.flatnonzero(below)],
            "upper": [np.array([], dtype=int), np.flatnonzero(~below)],
            "floor": [np.arange(len(floor)), np.array([], dtype=int)],
        },
    )
    back = Body.from_meshio(mesh, MAT)
    assert {k: len(v) for k, v in back.regions.items()} == {"lower": 24, "upper": 24}
    np.testing.assert_array_equal(back.regions["lower"], np.flatnonzero(below))
    truth = _facets_on_plane(back.mesh, 2, 0.0)
    assert truth.size == 8  # 4 squares of the floor, 2 triangles each
    np.testing.assert_array_equal(np.sort(back.boundaries["floor"]), truth)


def test_gmsh_physical_groups_named_by_field_data(tmp_path: Path) -> None:
    body, tets, below, floor = _tet_box()
    tag = np.where(below, 1, 2)
    mesh = meshio.Mesh(
        body.nodes,
        [("triangle", floor), ("tetra", tets)],
        cell_data={
            "gmsh:physical": [np.full(len(floor), 5), tag],
            "gmsh:geometrical": [np.ones(len(floor), dtype=int), tag],
        },
        field_data={
            "lower": np.array([1, 3]),
            "upper": np.array([2, 3]),
            "floor": np.array([5, 2]),
        },
    )
    path = tmp_path / "box.msh"
    meshio.write(path, mesh, file_format="gmsh22", binary=False)
    back = read_body(path, MAT)
    np.testing.assert_array_equal(back.regions["lower"], np.flatnonzero(below))
    np.testing.assert_array_equal(back.regions["upper"], np.flatnonzero(~below))
    np.testing.assert_array_equal(
        np.sort(back.boundaries["floor"]), _facets_on_plane(back.mesh, 2, 0.0)
    )


def test_names_that_cannot_be_mapped_are_named_in_a_warning() -> None:
    body, tets, below, floor = _tet_box()
    unnamed = meshio.Mesh(
        body.nodes, [("tetra", tets)], cell_data={"gmsh:physical": [np.where(below, 1, 2)]}
    )
    with pytest.warns(HarpxWarning, match=r"gmsh:physical tags \[1, 2\] with no name"):
        back = Body.from_meshio(unnamed, MAT)
    assert list(back.regions) == ["body"]
    labels = meshio.Mesh(body.nodes, [("tetra", tets)], cell_data={"medit:ref": [np.ones(48, int)]})
    with pytest.warns(HarpxWarning, match=r"integer cell data \['medit:ref'\]"):
        Body.from_meshio(labels, MAT)
    apex = meshio.Mesh(
        body.nodes,
        [("vertex", np.array([[0]])), ("tetra", tets)],
        cell_sets={"apex": [np.array([0]), np.array([], dtype=int)]},
    )
    with pytest.warns(HarpxWarning, match=r"cell set 'apex' on cells \{'vertex': 1\}"):
        Body.from_meshio(apex, MAT)


# --- 3: curved hexahedron20 files lose their curvature, with a warning --------------------


def test_curved_hexahedron20_warns_with_the_lost_sagitta(tmp_path: Path) -> None:
    spec = tube(20.0, 30.0, 10.0, n_radial=1, n_circumferential=8, n_axial=1, curved=True)
    curved = Body(spec, MAT, element="hex20")
    mesh = meshio.Mesh(curved.dof_points, [("hexahedron20", curved.cells)])
    # edge node on a 45-degree arc of the outer circle, r = 30 mm: off the chord midpoint by
    # the sagitta r (1 - cos 22.5°) = 2.2836 mm, a fraction (1 - cos 22.5°) / (2 sin 22.5°)
    # = 0.09946 of the chord
    half = np.pi / 8
    sagitta = 30.0 * (1 - np.cos(half))
    with pytest.warns(HarpxWarning, match=rf"8 'hexahedron20' cells .* up to {sagitta:.4g} mm"):
        ratio = warn_dropped_curvature(mesh.points, mesh.cells[0].data, "the tube")
    assert ratio == pytest.approx((1 - np.cos(half)) / (2 * np.sin(half)), rel=1e-6)
    with pytest.warns(HarpxWarning, match="curved geometry is lost"):
        straight = Body.from_meshio(mesh, MAT, element="hex20")
    # the documented reduction: straight cells, the annulus between inscribed octagons,
    # (n / 2) sin(2 pi / n) (R² - r²) h = 14142 mm³ (10% less than the tube's 15708 mm³)
    octagons = 8 / 2 * np.sin(2 * np.pi / 8) * (30.0**2 - 20.0**2) * 10.0
    assert straight.cell_volume.sum() == pytest.approx(octagons, rel=1e-12)
    path = tmp_path / "tube.vtu"
    meshio.write(path, mesh)
    with pytest.warns(HarpxWarning, match="curved geometry is lost"):
        read_body_mesh(path)


def test_straight_hexahedron20_reads_without_warning() -> None:
    body = Body(box((1.0, 1.0, 1.0), (2, 2, 2)), MAT, element="hex20")
    mesh = meshio.Mesh(body.dof_points, [("hexahedron20", body.cells)])
    assert warn_dropped_curvature(mesh.points, body.cells, "box") < 1e-12
    back = Body.from_meshio(mesh, MAT, element="hex20")  # warnings are errors here
    assert back.cell_volume.sum() == pytest.approx(1.0)


# --- 4: zero Jacobians are a named ValueError, not skfem's bare Exception -----------------

_CUBE = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
    dtype=np.float64,
)
_VTK = np.arange(8)[None, :]


def test_skfem_hexahedra_in_vtk_order_are_named() -> None:
    mesh = skfem.MeshHex1(_CUBE.T.copy(), _VTK.T.copy())
    with pytest.raises(ValueError, match=r"cells \[0\] .*scikit-fem's local vertex order"):
        Body(mesh, MAT)


def test_collapsed_skfem_hexahedron_is_named() -> None:
    # a wedge given as a hexahedron: VTK corners 2 and 6 are the nodes of corners 3 and 7
    vtk = np.array([[0, 1, 3, 3, 4, 5, 7, 7]])
    keep = np.unique(vtk)
    t = np.searchsorted(keep, vtk)[:, np.argsort(HEX_MAPPING[:8])].T.copy()  # skfem order
    with pytest.raises(ValueError, match=r"1 inverted or degenerate hexahedra: cells \[0\]"):
        Body(skfem.MeshHex1(_CUBE[keep].T.copy(), t), MAT)


def test_tetra10_in_gmsh_edge_order_is_named(tmp_path: Path) -> None:
    body = Body(tetrahedralize(box((1.0, 1.0, 1.0), (2, 2, 2))), MAT, element="tet10")
    gmsh = body.cells.copy()
    gmsh[:, [8, 9]] = body.cells[:, [9, 8]]  # gmsh lists edge 2-3 before edge 1-3
    path = tmp_path / "gmsh_order.vtu"
    meshio.write(path, meshio.Mesh(body.dof_points, [("tetra10", gmsh)]))
    with pytest.raises(ValueError, match=r"inverted or degenerate tetrahedra: cells \[0, .*gmsh"):
        read_body(path, MAT)
    # the same file in VTK order reads back as the same curved body
    meshio.write(path, meshio.Mesh(body.dof_points, [("tetra10", body.cells)]))
    assert read_body(path, MAT).cell_volume.sum() == pytest.approx(1.0)
