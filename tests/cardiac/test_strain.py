"""LV-frame strain, AHA segments, twist and torsion on analytic motions; the bull's-eye."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.anatomy.ventricle import VentricleGeometry
from harpx.anatomy.ventricle_fit import VentricleTemplate
from harpx.cardiac.strain import aha_segments, cardiac_strain
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.plotting import bullseye

GEOMETRY = VentricleGeometry(inner=(25.0, 70.0), outer=(35.0, 78.0), truncation=10.0)
TEMPLATE = VentricleTemplate(GEOMETRY, centre=(2.0, -1.0, 3.0))
S = 0.1  # in-plane dilation
K = 0.2  # twist rate, degrees per mm along the long axis


def _dilation(p: np.ndarray) -> np.ndarray:
    u = np.zeros_like(p)
    u[:, :2] = S * (p[:, :2] - TEMPLATE.centre[:2])
    return u


def _twist(p: np.ndarray) -> np.ndarray:
    q = p - TEMPLATE.centre
    phi = np.deg2rad(K * q[:, 2])  # right-handed about the apex-to-base axis
    c, s = np.cos(phi), np.sin(phi)
    moved = np.stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1], q[:, 2]], axis=1)
    return moved - q


def _fe_dataset(motion) -> xr.Dataset:
    """A tracked-like dataset of the template mesh under ``motion`` at frames 0 and 1."""
    # coarse mesh so the test is fast
    spec = TEMPLATE.mesh(n_circumferential=16, n_longitudinal=6, n_transmural=2)
    body = Body(spec, NeoHookean(c1=1.0, kappa=10.0))
    u = np.zeros(body.ndof)
    u[body.node_dofs] = motion(body.dof_points)
    disp = np.stack([np.zeros_like(body.dof_points), body.nodal_displacement(u)])
    strain = np.stack([body.green_strain(np.zeros(body.ndof)), body.green_strain(u)])
    return xr.Dataset(
        {
            "points": (("node", "axis"), body.dof_points),
            "cells": (("cell", "vertex"), body.cells, {"element": "hex8"}),
            "displacement": (("time", "node", "axis"), disp),
            "green_strain": (("time", "cell", "i", "j"), strain),
        },
        coords={"time": [0.0, 100.0], "axis": ["x", "y", "z"]},
    )


def test_in_plane_dilation_gives_the_exact_circumferential_strain():
    out = cardiac_strain(_fe_dataset(_dilation), TEMPLATE)
    # a linear field is reproduced exactly by hex8 and e_c is horizontal, so every cell
    # has E_cc = ((1+s)^2 - 1)/2 and an engineering strain s (round-off only)
    ecc = out.strain_lv.sel(component="circumferential").isel(time=1)
    assert np.allclose(ecc, ((1 + S) ** 2 - 1) / 2, atol=1e-12)
    eng = out.peak_engineering_strain.sel(component="circumferential")
    assert np.allclose(eng, S, atol=1e-12)
    assert out.peak_time.sel(component="circumferential").values.tolist() == [100.0] * 17
    # radial motion does not rotate anything
    assert np.allclose(out.twist, 0.0, atol=1e-10)
    assert set(np.unique(out.aha_segment.values)) == set(range(1, 18))
    assert out.segment_strain.attrs["units"] == "1"


def test_linear_twist_gives_the_torsion_rate():
    out = cardiac_strain(_fe_dataset(_twist), TEMPLATE)
    # rotation by K degrees per mm about the axis: torsion is K, up to the cell centres'
    # angle being the radius-weighted mean of their nodes' angles (outer nodes of the
    # sloped apical wall lie lower): measured -1.4 % on this 2-cell-thick mesh
    assert float(out.torsion[1]) == pytest.approx(K, rel=0.02)
    # counter-clockwise seen from the apex is a negative rotation about the apex-to-base
    # axis: the apex level (z < 0 about the centre) turns positive, more than the base
    apex, base = (float(out.rotation.sel(level=k)[1]) for k in ("apex", "base"))
    assert apex > base and apex > 5.0
    distance = out.torsion.attrs["level_distance_mm"]
    assert float(out.twist[1]) == pytest.approx(float(out.torsion[1]) * distance, rel=1e-12)


def test_grid_displacement_gives_the_same_segment_strain():
    step = 2.0  # mm voxels, coarse grid so the test is fast
    x = np.arange(-40.0, 44.0, step)
    z = np.arange(-80.0, 14.0, step)
    Z, Y, X = np.meshgrid(z, x, x, indexing="ij")
    pts = np.stack([X, Y, Z], -1).reshape(-1, 3)
    inside = GEOMETRY.inside(TEMPLATE.to_local(pts)).reshape(Z.shape)
    u = _dilation(pts).reshape(*Z.shape, 3).transpose(3, 0, 1, 2)
    u = np.where(inside[None] > 0, u, np.nan)
    disp = np.stack([np.zeros_like(u), u])
    ds = xr.Dataset(
        {"displacement_true": (("time", "axis", "z", "y", "x"), disp),
         "body": (("z", "y", "x"), inside)},
        coords={"time": [0.0, 50.0], "axis": ["x", "y", "z"], "z": z, "y": x, "x": x},
    )  # fmt: skip
    out = cardiac_strain(ds, TEMPLATE)
    # central differences are exact for a linear field: every segment E_cc as on the mesh
    peak = out.peak_strain.sel(component="circumferential")
    assert np.allclose(peak, ((1 + S) ** 2 - 1) / 2, atol=1e-12)
    assert set(np.unique(out.aha_segment_grid.values)) == set(range(18))


def test_segments_follow_the_anterior_angle_and_the_thirds():
    # the cavity runs from z = -70 (endocardial apex) to 10 (base): thirds of 80/3 mm
    r = 30.0
    pts = TEMPLATE.to_image([[r, 0.1, 0.0], [r, 0.1, -30.0], [r, 0.1, -60.0], [0, 0, -74.0]])
    assert aha_segments(pts, TEMPLATE).tolist() == [1, 7, 13, 17]
    shifted = aha_segments(pts, TEMPLATE, anterior=10.0)  # 0.2° is now in the last sector
    assert shifted.tolist() == [6, 12, 13, 17]


def test_bullseye_draws_17_segments_and_rejects_others():
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    out = cardiac_strain(_fe_dataset(_dilation), TEMPLATE)
    ax = bullseye(out)
    assert len(ax.patches) == 17
    plt.close(ax.figure)
    with pytest.raises(ValueError, match="17 segment values"):
        bullseye(np.zeros(5))
    with pytest.raises(ValueError, match="select one frame"):
        bullseye(out.segment_strain)


def test_dataset_without_displacement_is_named():
    with pytest.raises(ValueError, match="needs a finite-element tracked/1 dataset"):
        cardiac_strain(xr.Dataset({"a": ("x", [1.0])}), TEMPLATE)


def test_segment_coordinates_survive_on_the_result():
    out = cardiac_strain(_fe_dataset(_dilation), TEMPLATE)
    assert str(out.segment_name.sel(segment=17).values) == "apex"
    assert out.component.values.tolist() == ["radial", "circumferential", "longitudinal"]
