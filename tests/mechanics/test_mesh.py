"""Mesh builders: element counts, volumes, named facets, orientation, O-grid quality."""

from __future__ import annotations

import numpy as np
import pytest
import skfem

from harpx.mechanics.mesh import box, cylinder, facets_where, tube


def _volumes_and_det(mesh):
    basis = skfem.CellBasis(mesh, skfem.ElementHex1(), intorder=3)
    det = mesh.mapping().detDF(basis.X)
    return basis.dx.sum(axis=1), det


def test_box_counts_volume_and_facets():
    spec = box((2.0, 3.0, 1.0), (2, 3, 4), origin=(1.0, -1.0, 0.5))
    mesh = spec.mesh
    assert mesh.nelements == 24
    vol, det = _volumes_and_det(mesh)
    # trilinear map of a box is exact: volume identity to round-off
    np.testing.assert_allclose(vol.sum(), 6.0, rtol=1e-12)
    # skfem's own tensor meshes have detDF < 0 with its reference ordering; same sign everywhere
    assert np.all(np.sign(det) == np.sign(det.flat[0]))
    counts = {k: len(v) for k, v in spec.boundaries.items()}
    assert counts == {"left": 12, "right": 12, "front": 8, "back": 8, "bottom": 6, "top": 6}
    centers = mesh.p[:, mesh.facets[:, spec.boundaries["top"]]].mean(axis=1)
    np.testing.assert_allclose(centers[2], 1.5, rtol=0, atol=1e-12)
    assert sorted(mesh.boundaries) == sorted(spec.boundaries)


def test_meshspec_unpacks():
    mesh, regions, fibers, boundaries = box()
    assert fibers is None and list(regions) == ["body"] and "left" in boundaries
    assert mesh.nelements == 8


def test_box_rejects_bad_sizes():
    with pytest.raises(ValueError, match="divisions"):
        box(divisions=(0, 1, 1))
    with pytest.raises(ValueError, match="lengths"):
        box(lengths=(1.0, -1.0, 1.0))


def test_cylinder_ogrid_volume_and_quality():
    n_c = 16
    spec = cylinder(2.0, 3.0, n_radial=3, n_circumferential=n_c, n_axial=2)
    vol, det = _volumes_and_det(spec.mesh)
    # polygon with n_c straight chords: area = n_c/2 r² sin(2π/n_c), exact for trilinear cells
    expected = 0.5 * n_c * 4.0 * np.sin(2 * np.pi / n_c) * 3.0
    np.testing.assert_allclose(vol.sum(), expected, rtol=1e-12)
    # no degenerate or inverted cells: Jacobian has one sign and is bounded away from 0
    jac = np.abs(det)
    assert np.all(np.sign(det) == np.sign(det.flat[0]))
    assert jac.min() > 0.2 * jac.max() / 8  # coarse bound: cells within a factor 40 in size
    assert len(spec.boundaries["outer"]) == n_c * 2
    nbot = len(spec.boundaries["bottom"])
    assert nbot == len(spec.boundaries["top"]) == spec.mesh.nelements // 2
    assert set(spec.regions) == {"tissue"}


def test_cylinder_with_wall():
    spec = cylinder(
        2.0, 1.0, n_radial=2, n_circumferential=8, n_axial=1, wall_thickness=0.5, n_wall=2
    )
    assert set(spec.regions) == {"tissue", "wall"}
    assert len(spec.regions["wall"]) == 16
    assert len(spec.boundaries["wall_outer"]) == 8
    # "outer" is the interior interface between tissue and wall
    assert len(spec.boundaries["outer"]) == 8
    assert not np.isin(spec.boundaries["outer"], spec.mesh.boundary_facets()).any()
    p = spec.mesh.p
    r = np.hypot(*p[:2, spec.mesh.facets[:, spec.boundaries["wall_outer"]]].reshape(2, -1))
    np.testing.assert_allclose(r, 2.5, rtol=1e-12)


def test_cylinder_rejects_bad_circumference():
    with pytest.raises(ValueError, match="multiple of 4"):
        cylinder(1.0, 1.0, n_circumferential=6)


def test_tube_sector_facets():
    spec = tube(1.0, 2.0, 0.5, n_radial=2, n_circumferential=4, n_axial=1, angle=np.pi / 2)
    b = spec.boundaries
    assert {k: len(v) for k, v in b.items()} == {
        "inner": 4, "outer": 4, "bottom": 8, "top": 8, "start": 2, "end": 2
    }  # fmt: skip
    p = spec.mesh.p
    np.testing.assert_allclose(p[1, spec.mesh.facets[:, b["start"]]], 0.0, atol=1e-12)
    np.testing.assert_allclose(p[0, spec.mesh.facets[:, b["end"]]], 0.0, atol=1e-12)
    closed = tube(1.0, 2.0, 0.5, n_circumferential=8)
    assert "start" not in closed.boundaries and closed.mesh.nelements == 16


def test_facets_where_interior():
    spec = box((2.0, 1.0, 1.0), (2, 1, 1))
    mid = facets_where(spec.mesh, lambda p: np.abs(p[:, 0] - 1.0) < 1e-12, boundary_only=False)
    assert len(mid) == 1
