"""The ventricle template fitted to contours: exact recovery, masks, fibres, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.anatomy.ventricle import VentricleGeometry
from harpx.anatomy.ventricle_fit import (
    VentricleTemplate,
    fit_ventricle,
    fit_ventricle_to_mask,
)
from harpx.errors import HarpxWarning

GEOMETRY = VentricleGeometry(inner=(22.0, 60.0), outer=(31.0, 68.0), truncation=8.0)


def _rotation(degrees_x: float, degrees_y: float) -> np.ndarray:
    a, b = np.deg2rad(degrees_x), np.deg2rad(degrees_y)
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    return ry @ rx


def _surface(template: VentricleTemplate, t: float, n: int, rng) -> np.ndarray:
    a, c = template.geometry.semi_axes(t)
    theta = rng.uniform(0, 2 * np.pi, n)
    z = rng.uniform(-0.95 * c, template.geometry.truncation, n)
    r = a * np.sqrt(1 - (z / c) ** 2)
    local = np.stack([r * np.cos(theta), r * np.sin(theta), z], axis=1)
    return template.to_image(local)


def test_exact_contours_recover_the_template(rng):
    truth = VentricleTemplate(GEOMETRY, centre=(4.0, -3.0, 12.0), rotation=_rotation(20, -10))
    endo, epi = _surface(truth, 0.0, 400, rng), _surface(truth, 1.0, 400, rng)
    base_local = np.column_stack(
        [rng.uniform(-20, 20, 50), rng.uniform(-20, 20, 50), np.full(50, 8.0)]
    )
    fit = fit_ventricle(endo, epi, base=truth.to_image(base_local))
    g = fit.template.geometry
    # points on the surfaces: the distance is exact there, so the optimum is the truth up
    # to the solver's tolerance
    assert np.allclose([*g.inner, *g.outer, g.truncation], [22, 60, 31, 68, 8], atol=1e-5)
    assert np.allclose(fit.template.centre, truth.centre, atol=1e-5)
    assert fit.template.axis @ truth.axis == pytest.approx(1.0, abs=1e-10)
    assert fit.rms < 1e-6


def test_fit_to_a_binary_mask_is_within_half_a_voxel():
    truth = VentricleTemplate(GEOMETRY, centre=(3.0, -2.0, 0.0))
    step = 1.5  # mm, coarse grid so the test is fast
    x = np.arange(-40.0, 40.0, step)
    z = np.arange(-75.0, 15.0, step)
    Z, Y, X = np.meshgrid(z, x, x, indexing="ij")
    inside = truth.geometry.inside(truth.to_local(np.stack([X, Y, Z], -1).reshape(-1, 3)))
    mask = xr.DataArray(inside.reshape(Z.shape), dims=("z", "y", "x"),
                        coords={"z": z, "y": x, "x": x})  # fmt: skip
    fit = fit_ventricle_to_mask(mask)
    g = fit.template.geometry
    # a binary mask places its 0.5 contour midway between voxel centres: every surface
    # point is within half a voxel (0.75 mm) of the truth, the rms is about step/sqrt(12)
    # = 0.43 mm, and the fitted parameters are within half a voxel
    half = 0.5 * step
    assert np.allclose(g.inner, GEOMETRY.inner, atol=half)
    assert np.allclose(g.outer, GEOMETRY.outer, atol=half)
    assert np.allclose(fit.template.to_image([[0, 0, g.truncation]])[0, 2], 8.0, atol=half)
    assert np.allclose(fit.template.centre[:2], [3.0, -2.0], atol=0.1 * step)
    assert fit.rms < 0.5 and fit.report()["base_rms"] < step


def test_template_mesh_and_fibres_move_with_the_template():
    rot = _rotation(30, 15)
    template = VentricleTemplate(GEOMETRY, centre=(1.0, 2.0, 3.0), rotation=rot)
    spec = template.mesh(n_circumferential=8, n_longitudinal=3, n_transmural=1)
    upright = VentricleTemplate(GEOMETRY).mesh(n_circumferential=8, n_longitudinal=3,
                                                n_transmural=1)  # fmt: skip
    # rigid motion: points and fibres rotate, names stay (exact up to round-off)
    assert np.allclose(spec.mesh.p.T, upright.mesh.p.T @ rot.T + [1.0, 2.0, 3.0], atol=1e-12)
    assert np.allclose(spec.fibers, upright.fibers @ rot.T, atol=1e-12)
    assert sorted(spec.boundaries) == ["base", "endo", "epi"]
    e_r, e_c, e_l = template.local_basis(spec.mesh.p.T)
    frame = np.stack([e_r, e_c, e_l], axis=-1)
    assert np.allclose(np.einsum("nij,nik->njk", frame, frame), np.eye(3), atol=1e-12)
    # the mid-wall fibre at the helix angle 0 is circumferential
    mid = template.to_image([[GEOMETRY.semi_axes(0.5)[0] * np.sqrt(1 - (4 / 64) ** 2), 0, -4]])
    f = template.fibers(mid, fiber_endo=60.0, fiber_epi=-60.0)
    assert abs(f[0] @ template.local_basis(mid)[1][0]) == pytest.approx(1.0, abs=1e-3)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="at least 10 points per surface"):
        fit_ventricle(np.zeros((3, 3)), np.zeros((30, 3)))
    with pytest.raises(ValueError, match="orthonormal"):
        VentricleTemplate(GEOMETRY, rotation=2 * np.eye(3))


def test_facet_predicates_and_base_conditions():
    template = VentricleTemplate(GEOMETRY, centre=(1.0, 0.0, -2.0))
    names = template.facet_predicates()
    normals = np.array([template.axis, [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    # a point on the base plane facing up; endocardial and epicardial points at z = -30
    a0 = GEOMETRY.inner[0] * np.sqrt(1 - (30 / 60) ** 2)
    a1 = GEOMETRY.outer[0] * np.sqrt(1 - (30 / 68) ** 2)
    pts = template.to_image([[26.0, 0, 8.0], [a0 + 0.1, 0, -30.0], [a1 - 0.1, 0, -30.0]])
    assert names["base"](pts, normals).tolist() == [True, False, False]
    assert names["endo"](pts, normals).tolist() == [False, True, False]
    assert names["epi"](pts, normals).tolist() == [False, False, True]
    fixed, pins = template.base_conditions()
    assert fixed.facet == "base" and pins.components == (1, 0, 1, 0)
    assert np.allclose(template.to_local(pins.points)[:, 2], GEOMETRY.truncation)
    tilted = VentricleTemplate(GEOMETRY, rotation=_rotation(10, 0))
    with pytest.warns(HarpxWarning, match="10.0 degrees off the image z axis"):
        tilted.base_conditions()


def test_surface_distance_is_exact_on_the_equator_and_the_axis(rng):
    template = VentricleTemplate(GEOMETRY, centre=(3.0, -2.0, 5.0), rotation=_rotation(20, -10))
    # points on each surface are at distance 0 (to rounding)
    for surface, t in (("endo", 0.0), ("epi", 1.0)):
        on = _surface(template, t, 200, rng)
        assert np.abs(template.surface_distance(on, surface)).max() < 1e-9
    # along the equator (z = 0) and the long axis the level set's first-order distance is
    # exact: r - a and |z| - c
    local = np.array([[24.0, 0.0, 0.0], [0.0, 19.0, 0.0], [0.0, 0.0, -63.0], [0.0, 0.0, -50.0]])
    points = template.to_image(local)
    np.testing.assert_allclose(
        template.surface_distance(points, "endo"), [2.0, -3.0, 3.0, -10.0], atol=1e-9
    )
    np.testing.assert_allclose(
        template.surface_distance(points, "epi"), [-7.0, -12.0, -5.0, -18.0], atol=1e-9
    )
    with pytest.raises(ValueError, match="surface='mid' must be 'endo' or 'epi'"):
        template.surface_distance(points, "mid")
