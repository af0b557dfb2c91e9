"""Left-ventricle templates, tracked-like datasets and wall samples for the cardiac tests."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import xarray as xr

from harpx.anatomy.ventricle import VentricleGeometry
from harpx.anatomy.ventricle_fit import VentricleTemplate
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean

GEOMETRY = VentricleGeometry(inner=(25.0, 70.0), outer=(35.0, 78.0), truncation=10.0)
TEMPLATE = VentricleTemplate(GEOMETRY, centre=(2.0, -1.0, 3.0))
Motion = Callable[[np.ndarray], np.ndarray]


class WithAnterior:
    """A template that also carries an ``anterior`` angle (degrees), as a fitted one may."""

    def __init__(self, template: Any, anterior: float) -> None:
        self._template = template
        self.anterior = anterior

    def __getattr__(self, name: str) -> Any:
        return getattr(self._template, name)


def body_of(template: Any = TEMPLATE, n: tuple[int, int, int] = (16, 6, 2)) -> Body:
    """The template's hexahedral mesh as a body (coarse by default, so tests are fast)."""
    spec = template.mesh(n_circumferential=n[0], n_longitudinal=n[1], n_transmural=n[2])
    return Body(spec, NeoHookean(c1=1.0, kappa=10.0))


def fe_dataset(
    motion: Motion,
    body: Body | None = None,
    *,
    seen: tuple[float, float, float] | None = (1.0, 1.0, 1.0),
    rank: np.ndarray | None = None,
) -> xr.Dataset:
    """A tracked-like dataset of ``body`` under ``motion`` at frames 0 and 1 (100 ms).

    ``seen`` is every cell's ``observed_fraction`` of x, y, z (None: not recorded) and
    ``rank`` its ``observed_directions`` (default: the number of seen axes).
    """
    body = body_of() if body is None else body
    u = np.zeros(body.ndof)
    u[body.node_dofs] = motion(body.dof_points)
    disp = np.stack([np.zeros_like(body.dof_points), body.nodal_displacement(u)])
    strain = np.stack([body.green_strain(np.zeros(body.ndof)), body.green_strain(u)])
    ds = xr.Dataset(
        {
            "points": (("node", "axis"), body.dof_points),
            "cells": (("cell", "vertex"), body.cells, {"element": body.element}),
            "displacement": (("time", "node", "axis"), disp),
            "green_strain": (("time", "cell", "i", "j"), strain),
        },
        coords={"time": [0.0, 100.0], "axis": ["x", "y", "z"]},
    )
    if seen is not None:
        fraction = np.tile(np.asarray(seen, dtype=np.float64), (body.ncell, 1))
        ranks = np.full(body.ncell, int(np.count_nonzero(seen))) if rank is None else rank
        fraction[ranks == 0] = 0.0
        ds["observed_fraction"] = (("cell", "axis"), fraction)
        ds["observed_directions"] = ("cell", ranks)
    return ds


def wall_samples(template: Any = TEMPLATE, step: float = 1.0) -> np.ndarray:
    """Image points (n, 3) of a regular ``step`` mm grid (in template axes) inside the wall."""
    g = template.geometry
    a, c = g.outer
    r = np.arange(-a, a + step, step)
    z = np.arange(-c, g.truncation, step) + step / 2
    Z, Y, X = np.meshgrid(z, r, r, indexing="ij")
    q = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    return template.to_image(q[g.inside(q) > 0])


def centroid_z(template: Any, z1: float, z2: float) -> float:
    """Closed-form volume centroid (template z, mm) of the wall between planes z1 < z2.

    The wall's cross-section is the annulus ``A(z) = π (α - β z²)`` between the two
    ellipsoids, ``α = a_epi² - a_endo²``, ``β = a_epi²/c_epi² - a_endo²/c_endo²``
    (valid above the endocardial apex).
    """
    (ai, ci), (ao, co) = template.geometry.inner, template.geometry.outer
    alpha, beta = ao**2 - ai**2, ao**2 / co**2 - ai**2 / ci**2
    volume = alpha * (z2 - z1) - beta * (z2**3 - z1**3) / 3.0
    moment = alpha * (z2**2 - z1**2) / 2.0 - beta * (z2**4 - z1**4) / 4.0
    return moment / volume
