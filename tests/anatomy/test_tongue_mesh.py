"""Tongue mesh: cell count, muscle regions, fibres, boundaries and geometry."""

from __future__ import annotations

import numpy as np
import pytest
import skfem

from harpx.anatomy.tongue_mesh import (
    MUSCLES,
    muscle_atlas,
    tongue,
    tongue_inside,
    tongue_map,
    tongue_reference,
)
from harpx.mechanics.locate import locate


@pytest.fixture(scope="module")
def spec():
    return tongue()


def _det(mesh):
    basis = skfem.CellBasis(mesh, skfem.ElementHex1(), intorder=3)
    return mesh.mapping().detDF(basis.X), basis.dx.sum()


def test_paper_size_and_every_cell_in_exactly_one_muscle(spec):
    assert spec.mesh.nelements == 280  # the paper's 280 brick elements
    counts = np.zeros(spec.mesh.nelements, dtype=int)
    for ids in spec.regions.values():
        np.add.at(counts, ids, 1)
    np.testing.assert_array_equal(counts, 1)
    assert sorted(spec.regions) == sorted(MUSCLES)
    assert all(len(ids) > 0 for ids in spec.regions.values()), {
        k: len(v) for k, v in spec.regions.items()
    }


def test_fibres_are_unit_vectors_in_the_muscle_directions(spec):
    f = spec.fibers
    assert f.shape == (280, 3)
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), 1.0, rtol=0, atol=1e-12)  # round-off
    # dominant component of the mean direction: longitudinal x, transverse y, vertical z
    for name, axis in (("SL", 0), ("IL", 0), ("T", 1), ("V", 2)):
        mean = np.abs(f[spec.regions[name]]).mean(axis=0)
        assert np.argmax(mean) == axis, (name, mean)
        assert mean[axis] > 0.9, (name, mean)  # the map bends them by < 25 degrees


def test_genioglossus_fans_out_from_the_mandible_insertion(spec):
    ids = spec.regions["GG"]
    centres = spec.mesh.p[:, spec.mesh.t[:, ids]].mean(axis=1).T
    insertion = tongue_map(np.array([[0.8, 0.0, 0.0]]), 70.0, 50.0, 40.0)[0]
    radial = centres - insertion
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    # fibres point along the rays from the insertion (exact by construction, round-off)
    np.testing.assert_allclose(np.einsum("ij,ij->i", spec.fibers[ids], radial), 1.0, atol=1e-12)
    # a fan in the sagittal plane: from nearly horizontal (to the root) to steeply up (to the
    # dorsum), i.e. spread over more than 45 degrees, all pointing up and back
    angles = np.degrees(np.arctan2(spec.fibers[ids, 2], spec.fibers[ids, 0]))
    assert np.ptp(angles) > 45.0, np.ptp(angles)
    assert np.all(spec.fibers[ids, 2] > 0) and np.all(spec.fibers[ids, 0] < 0)


@pytest.mark.parametrize("divisions", [(10, 7, 4), (20, 14, 8), (3, 2, 2)])
def test_no_inverted_or_degenerate_cells(divisions):
    det, volume = _det(tongue(divisions=divisions).mesh)
    # one sign everywhere (skfem's reference orientation makes it negative) and bounded away
    # from 0: the map keeps det >= 8 % of its root value, cells differ in size by < 50x
    assert np.all(np.sign(det) == np.sign(det.flat[0])), divisions
    assert np.abs(det).min() > np.abs(det).max() / 50.0, divisions
    assert 75e3 < volume < 95e3  # a ~90 mL tongue (mm³)


def test_refinement_keeps_the_muscle_map_and_converges_in_volume():
    coarse, fine = tongue(), tongue(divisions=(20, 14, 8))
    # every fine cell sits in the coarse cell of the same muscle: compare via the atlas
    fine_centres = fine.mesh.p[:, fine.mesh.t].mean(axis=1).T
    cells, _ = locate(coarse.mesh, fine_centres)
    assert np.all(cells >= 0)
    label_coarse = np.empty(280, dtype="<U2")
    for name, ids in coarse.regions.items():
        label_coarse[ids] = name
    label_fine = np.empty(fine.mesh.nelements, dtype="<U2")
    for name, ids in fine.regions.items():
        label_fine[ids] = name
    agree = np.mean(label_fine == label_coarse[cells])
    # the coarse polygon differs from the fine one by the chord error: a few boundary cells'
    # centres fall into a neighbouring coarse cell of another muscle
    assert agree > 0.97, agree
    # volumes of the trilinear polyhedra converge to the smooth body (second order)
    v = [_det(m.mesh)[1] for m in (coarse, fine, tongue(divisions=(40, 28, 16)))]
    assert abs(v[2] - v[1]) < 0.3 * abs(v[1] - v[0]), v


def test_boundaries(spec):
    b = spec.boundaries
    for name in ("mandible", "base", "hyoid", "dorsum", "tip", "posterior", "lateral", "floor"):
        assert len(b[name]) > 0, name
    np.testing.assert_array_equal(b["base"], b["hyoid"])
    assert not np.intersect1d(b["mandible"], b["base"]).size
    assert not np.intersect1d(b["floor"], np.union1d(b["mandible"], b["base"])).size
    p = spec.mesh.p
    for name in ("mandible", "base", "floor"):
        np.testing.assert_allclose(p[2, spec.mesh.facets[:, b[name]]], 0.0, atol=1e-12)
    # the mandible insertion lies in front of the hyoid attachment (facet centroids)
    cx = {n: p[0, spec.mesh.facets[:, b[n]]].mean(axis=0) for n in ("mandible", "base")}
    assert cx["mandible"].min() > cx["base"].max()
    assert len(b["floor"]) + len(b["mandible"]) + len(b["base"]) == 70  # the whole floor


def test_reference_inverts_the_map_and_inside_matches_the_mesh(rng):
    ref = rng.uniform([0, -1, 0], [1, 1, 1], (2000, 3))
    x = tongue_map(ref, 70.0, 50.0, 40.0)
    # Newton on a smooth one-to-one map: round-off
    np.testing.assert_allclose(tongue_reference(x, 70.0, 50.0, 40.0), ref, atol=1e-10)
    pts = rng.uniform([-5, -30, -5], [75, 30, 45], (4000, 3))
    inside = tongue_inside(pts, 70.0, 50.0, 40.0)
    cells, _ = locate(tongue(divisions=(40, 28, 16)).mesh, pts)
    # the fine polyhedron and the smooth body differ only within the chord error (< 0.1 mm)
    assert np.mean(inside == (cells >= 0)) > 0.995
    assert 0.2 < inside.mean() < 0.6


def test_atlas_labels():
    labels = muscle_atlas(
        np.array(
            [[0.3, 0.0, 0.2], [0.3, 0.0, 0.95], [0.95, 0.9, 0.4], [0.2, 0.9, 0.1], [0.2, -0.9, 0.6]]
        )
    )
    assert labels.tolist() == ["GG", "SL", "T", "IL", "V"]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"divisions": (0, 7, 4)}, "divisions", id="divisions"),
        pytest.param({"divisions": "fine"}, "divisions", id="divisions-type"),
        pytest.param({"length": -1.0}, "length=-1.0", id="length"),
        pytest.param({"height": float("nan")}, "height=nan", id="height"),
    ],
)
def test_bad_sizes_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        tongue(**kwargs)
