r"""The analytic left ventricle fitted to endo- and epicardial contours or a myocardium mask.

Template
--------
A :class:`VentricleTemplate` places the truncated ellipsoidal ventricle of
:mod:`harpx.anatomy.ventricle` (built about the z axis with the apex towards −z) in the
image: a centre :math:`c` (the centre of both ellipsoids) and a rotation :math:`R` whose
columns are the template's x, y and z axes in image coordinates (z the long axis, pointing
from the apex to the base), so that an image point :math:`p` has template coordinates
:math:`q = R^T (p - c)`. The template's angular origin (its +x axis) is the image x axis
projected onto the short-axis plane. Its meshes (:meth:`VentricleTemplate.mesh`) and
helical fibres (:meth:`VentricleTemplate.fibers`) are those of
:func:`~harpx.anatomy.ventricle.ventricle`, moved rigidly into the image.

Fit
---
:func:`fit_ventricle` fits the centre, the long-axis direction (two angles) and the four
semi-axes by nonlinear least squares (``scipy.optimize.least_squares``, soft-L1 loss of
scale 1 mm) of the first-order distance of each contour point to its surface,

.. math::

    d(p) = \frac{\rho(q) - 1}{|\nabla_q \rho(q)|}, \qquad
    \rho(q) = \sqrt{\frac{q_x^2 + q_y^2}{a^2} + \frac{q_z^2}{c^2}},

(:math:`a, c` the endocardial semi-axes for endocardial points, the epicardial ones for
epicardial points), exact on the surface and accurate to second order in the distance
near it. The base plane is then the median template z of the base points, or the
highest contour point when there are none. The residual :math:`d` at the optimum, in mm,
is the fit's report (:class:`VentricleFit`).

:func:`ventricle_contours` extracts the points from a myocardium mask (a tissue fraction
such as a ``tagged/1`` dataset's ``body``, or a binary mask): the 0.5 iso-contour is found
between neighbouring voxel centres by linear interpolation along the two in-plane axes of
the short-axis slices; a crossing whose low side lies in the cavity (the holes of the mask
within each slice) is endocardial, otherwise epicardial; crossings along the slice axis
near the top of the wall give the base. Long-axis contours are simply more points for
:func:`fit_ventricle`.

Units: mm, degrees for the fibre angles.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import scipy.ndimage as ndi
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from harpx._typing import FloatArray
from harpx.anatomy.ventricle import VentricleGeometry, ventricle
from harpx.errors import HarpxWarning
from harpx.io.labels import read_labels
from harpx.mechanics.mesh import MeshSpec, hex_mesh, labelled_spec

__all__ = [
    "VentricleFit",
    "VentricleTemplate",
    "fit_ventricle",
    "fit_ventricle_to_mask",
    "ventricle_contours",
]

_AXES = ("x", "y", "z")


def _frame(axis: ArrayLike) -> FloatArray:
    """Rotation whose third column is the unit ``axis`` and first the projected image x."""
    u = np.asarray(axis, dtype=np.float64)
    u = u / np.linalg.norm(u)
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    ex = ref - (ref @ u) * u
    ex /= np.linalg.norm(ex)
    return np.column_stack([ex, np.cross(u, ex), u])


@dataclass(frozen=True)
class VentricleTemplate:
    """The analytic ventricle placed in the image by a centre and a rotation.

    Parameters
    ----------
    geometry : VentricleGeometry
        Semi-axes and base plane in template coordinates, mm.
    centre : array_like, shape (3,), default (0, 0, 0)
        Image position of the ellipsoids' centre, mm.
    rotation : array_like, shape (3, 3), default identity
        Columns: the template's x, y, z (long axis, apex to base) axes in image
        coordinates (orthonormal, right-handed).

    Examples
    --------
    >>> from harpx.anatomy.ventricle import VentricleGeometry
    >>> from harpx.anatomy.ventricle_fit import VentricleTemplate
    >>> g = VentricleGeometry(inner=(25.0, 70.0), outer=(35.0, 78.0), truncation=10.0)
    >>> VentricleTemplate(g, centre=(1.0, 2.0, 3.0)).apex.tolist()  # epicardial apex, mm
    [1.0, 2.0, -75.0]
    """

    geometry: VentricleGeometry
    centre: Any = field(default_factory=lambda: np.zeros(3))
    rotation: Any = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        c = np.asarray(self.centre, dtype=np.float64).reshape(3)
        r = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        if np.abs(r.T @ r - np.eye(3)).max() > 1e-8 or np.linalg.det(r) < 0:
            raise ValueError("rotation must be a proper orthonormal 3x3 matrix (det +1)")
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "rotation", r)

    @property
    def axis(self) -> FloatArray:
        """Unit long axis, apex to base, in image coordinates."""
        return np.asarray(self.rotation[:, 2])

    @property
    def apex(self) -> FloatArray:
        """Epicardial apex in image coordinates, mm."""
        return self.to_image(np.array([[0.0, 0.0, -self.geometry.outer[1]]]))[0]

    def to_local(self, points: ArrayLike) -> FloatArray:
        """Template coordinates ``R^T (p - c)`` of image points (n, 3), mm."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return np.asarray((p - self.centre) @ self.rotation)

    def to_image(self, points: ArrayLike) -> FloatArray:
        """Image coordinates ``c + R q`` of template points (n, 3), mm."""
        q = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return np.asarray(q @ self.rotation.T + self.centre)

    def transmural(self, points: ArrayLike) -> FloatArray:
        """Transmural fraction (0 endocardium, 1 epicardium) of image points."""
        return self.geometry.transmural(self.to_local(points))

    def local_basis(self, points: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Radial, circumferential and longitudinal unit vectors at image points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Image points, mm.

        Returns
        -------
        e_r, e_c, e_l : ndarray, shape (n, 3)
            In image coordinates: ``e_c`` counter-clockwise about the long axis, ``e_l``
            along the meridian of the layer through the point from apex to base, and
            ``e_r = e_c × e_l`` the outward layer normal.
        """
        e_c, e_l, _ = self.geometry.local_basis(self.to_local(points))
        e_r = np.cross(e_c, e_l)
        rot = self.rotation.T
        return e_r @ rot, e_c @ rot, e_l @ rot

    def fibers(
        self, points: ArrayLike, *, fiber_endo: float = 60.0, fiber_epi: float = -60.0
    ) -> FloatArray:
        """Unit helical fibres at image points (helix angles in degrees, endo to epi)."""
        f = self.geometry.fibers(self.to_local(points), fiber_endo=fiber_endo, fiber_epi=fiber_epi)
        return np.asarray(f @ self.rotation.T)

    def facet_predicates(self, *, base_tolerance: float = 3.0) -> dict[str, Any]:
        """Predicates naming ``"base"``, ``"endo"`` and ``"epi"`` facets of any wall mesh.

        For the ``boundaries`` argument of
        :func:`~harpx.anatomy.segmentation.mesh_from_labels`: a facet is basal when its
        centre lies within ``base_tolerance`` (mm) of the base plane and its outward normal
        is within 45° of the long axis; the other facets are endocardial where the
        transmural fraction of their centre is below 1/2, epicardial otherwise.

        Parameters
        ----------
        base_tolerance : float, default 3
            Distance from the base plane, mm (about half an element).

        Returns
        -------
        dict of str to callable
            ``predicate(centres, normals) -> bool array``.
        """
        zb = self.geometry.truncation

        def base(centres: FloatArray, normals: FloatArray) -> Any:
            near = np.abs(self.to_local(centres)[:, 2] - zb) < base_tolerance
            return near & (np.asarray(normals) @ self.axis > np.sqrt(0.5))

        def endo(centres: FloatArray, normals: FloatArray) -> Any:
            return ~base(centres, normals) & (self.transmural(centres) < 0.5)

        def epi(centres: FloatArray, normals: FloatArray) -> Any:
            return ~base(centres, normals) & (self.transmural(centres) >= 0.5)

        return {"base": base, "endo": endo, "epi": epi}

    def base_conditions(self) -> list[Any]:
        """Base held along z and four mid-wall base nodes pinned in-plane (rigid modes).

        Returns
        -------
        list
            ``[Fixed("base", (2,)), NodeFixed(...)]`` for ``dirichlet=``: the ``"base"``
            facets keep their z, and the nodes nearest the mid-wall base points on the
            template's ±x (±y) axes keep their y (x). Components are image components, so
            this matches the scene's conditions when the long axis is the image z axis; a
            :class:`~harpx.errors.HarpxWarning` flags a long axis more than 5° off z.
        """
        from harpx.mechanics.loads import Fixed
        from harpx.physiology.cut import NodeFixed

        tilt = float(np.degrees(np.arccos(np.clip(abs(self.axis[2]), 0.0, 1.0))))
        if tilt > 5.0:
            warnings.warn(
                f"the long axis is {tilt:.1f} degrees off the image z axis; base_conditions "
                "holds image components (z on the base, x/y pins), which no longer align "
                "with the ventricle; resample the images along the long axis or write your "
                "own conditions",
                HarpxWarning,
                stacklevel=2,
            )
        g = self.geometry
        a, c = (float(v) for v in g.semi_axes(0.5))
        zb = g.truncation
        r = a * np.sqrt(max(0.0, 1.0 - (zb / c) ** 2))
        local = [[r, 0.0, zb], [0.0, r, zb], [-r, 0.0, zb], [0.0, -r, zb]]
        return [Fixed("base", (2,)), NodeFixed(self.to_image(local), (1, 0, 1, 0))]

    def mesh(self, **options: Any) -> MeshSpec:
        """The template's hexahedral mesh in the image (see :func:`ventricle`).

        Parameters
        ----------
        **options
            Keywords of :func:`~harpx.anatomy.ventricle.ventricle` other than the
            geometry (``n_circumferential``, ``n_longitudinal``, ``n_transmural``,
            ``fiber_endo``, ``fiber_epi``, ``segments``).

        Returns
        -------
        MeshSpec
            Regions, boundaries ``endo``/``epi``/``base`` and helical fibres of the
            template mesh, moved rigidly into the image.
        """
        g = self.geometry
        spec = ventricle(inner=g.inner, outer=g.outer, truncation=g.truncation, **options)
        points = self.to_image(spec.mesh.p.T)
        moved = hex_mesh(points, _vtk_cells(spec.mesh))
        fibers = None if spec.fibers is None else spec.fibers @ self.rotation.T
        return labelled_spec(moved, spec.regions, spec.boundaries, fibers)


def _vtk_cells(mesh: Any) -> Any:
    from harpx.mechanics.mesh import _VTK_TO_SKFEM

    order = np.argsort(_VTK_TO_SKFEM)
    return mesh.t.T[:, order]


@dataclass(frozen=True)
class VentricleFit:
    """A fitted template and its residuals.

    Attributes
    ----------
    template : VentricleTemplate
        The fitted ventricle.
    endo_residual, epi_residual : ndarray
        Signed distance (mm, positive outside the surface) of each contour point to its
        fitted surface.
    base_residual : ndarray
        Signed distance (mm) of each base point to the fitted base plane (empty without
        base points).
    """

    template: VentricleTemplate
    endo_residual: FloatArray
    epi_residual: FloatArray
    base_residual: FloatArray

    @property
    def rms(self) -> float:
        """Root-mean-square distance of all endo- and epicardial points, mm."""
        d = np.concatenate([self.endo_residual, self.epi_residual])
        return float(np.sqrt(np.mean(d**2)))

    def report(self) -> dict[str, float]:
        """Residual summary in mm: rms, mean |d| and 95th percentile per surface."""
        out: dict[str, float] = {"rms": self.rms}
        for name, d in (
            ("endo", self.endo_residual),
            ("epi", self.epi_residual),
            ("base", self.base_residual),
        ):
            if d.size:
                out[f"{name}_rms"] = float(np.sqrt(np.mean(d**2)))
                out[f"{name}_p95"] = float(np.percentile(np.abs(d), 95))
        return out


def _distance(q: FloatArray, a: float | FloatArray, c: float | FloatArray) -> FloatArray:
    r2 = q[:, 0] ** 2 + q[:, 1] ** 2
    rho = np.sqrt(r2 / a**2 + q[:, 2] ** 2 / c**2)
    grad = np.sqrt(r2 / a**4 + q[:, 2] ** 2 / c**4) / np.maximum(rho, 1e-12)
    return (rho - 1.0) / np.maximum(grad, 1e-12)


def _axis_of(theta: float, phi: float) -> FloatArray:
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def fit_ventricle(
    endo: ArrayLike,
    epi: ArrayLike,
    *,
    base: ArrayLike | None = None,
    axis: ArrayLike | None = None,
) -> VentricleFit:
    """Fit the truncated ellipsoidal ventricle to endo- and epicardial contour points.

    Parameters
    ----------
    endo, epi : array_like, shape (n, 3)
        Image points (mm, columns x, y, z) on the endocardium and the epicardium, from
        short-axis and long-axis contours alike.
    base : array_like, shape (m, 3), optional
        Points on the base plane; default: the base passes through the highest contour
        point along the fitted axis.
    axis : array_like, shape (3,), optional
        Initial long-axis direction (apex to base); default: from the points (the
        endocardial centroid lies basal of the epicardial one, which includes the apex).

    Returns
    -------
    VentricleFit

    Raises
    ------
    ValueError
        If fewer than 10 points per surface are given or the fit is not a valid ventricle.
    """
    pn = np.asarray(endo, dtype=np.float64).reshape(-1, 3)
    pp = np.asarray(epi, dtype=np.float64).reshape(-1, 3)
    if len(pn) < 10 or len(pp) < 10:
        raise ValueError(
            f"fit_ventricle needs at least 10 points per surface, got {len(pn)} endo and "
            f"{len(pp)} epi; add contours"
        )
    if axis is None:
        both = np.concatenate([pn, pp])
        _, _, vt = np.linalg.svd(both - both.mean(axis=0), full_matrices=False)
        u = vt[0]
        if (pn.mean(axis=0) - pp.mean(axis=0)) @ u < 0:
            u = -u
    else:
        u = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    # start: centre on the axis at the top of the points, radii from the point spread
    mid = pp.mean(axis=0)
    s_all = (np.concatenate([pn, pp]) - mid) @ u
    centre0 = mid + s_all.max() * u

    def radial(p: FloatArray) -> FloatArray:
        d = p - centre0
        return np.linalg.norm(d - np.outer(d @ u, u), axis=1)

    a0, a1 = float(np.median(radial(pn))), float(np.median(radial(pp)))
    c0 = float(-((pn - centre0) @ u).min())
    c1 = float(-((pp - centre0) @ u).min())
    theta0, phi0 = float(np.arccos(np.clip(u[2], -1, 1))), float(np.arctan2(u[1], u[0]))
    x0 = np.array([*centre0, theta0, phi0, a0, c0, max(a1 - a0, 1.0), max(c1 - c0, 1.0)])

    def split(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        return x[:3], _frame(_axis_of(x[3], x[4]))

    def residual(x: FloatArray) -> FloatArray:
        c, rot = split(x)
        qn, qp = (pn - c) @ rot, (pp - c) @ rot
        return np.concatenate([_distance(qn, x[5], x[6]), _distance(qp, x[5] + x[7], x[6] + x[8])])

    lower = np.array([-np.inf] * 5 + [0.5, 0.5, 0.1, 0.1])
    upper = np.array([np.inf] * 9)
    x0[5:] = np.maximum(x0[5:], lower[5:] + 1e-3)
    sol = least_squares(residual, x0, bounds=(lower, upper), loss="soft_l1", f_scale=1.0)
    x = sol.x
    c, rot = split(x)
    # keep the angular origin at the projected image x (the frame is built from the axis)
    inner = (float(x[5]), float(x[6]))
    outer = (float(x[5] + x[7]), float(x[6] + x[8]))
    q_all = (np.concatenate([pn, pp]) - c) @ rot
    if base is not None:
        qb = (np.asarray(base, dtype=np.float64).reshape(-1, 3) - c) @ rot
        truncation = float(np.median(qb[:, 2]))
        base_res = qb[:, 2] - truncation
    else:
        truncation = float(q_all[:, 2].max())
        base_res = np.empty(0)
    truncation = float(np.clip(truncation, -0.999 * inner[1], 0.999 * inner[1]))
    try:
        geometry = VentricleGeometry(inner=inner, outer=outer, truncation=truncation)
    except ValueError as exc:
        raise ValueError(f"the fitted ventricle is not valid ({exc}); check the contours") from exc
    res = residual(x)
    return VentricleFit(
        VentricleTemplate(geometry, c, rot), res[: len(pn)], res[len(pn) :], base_res
    )


def ventricle_contours(
    mask: Any,
    *,
    slice_axis: Literal["x", "y", "z"] = "z",
    variable: str | None = None,
    axis: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Endocardial, epicardial and base points of a myocardium mask.

    Parameters
    ----------
    mask : xarray.Dataset, xarray.DataArray, str or os.PathLike
        Myocardium fraction or binary mask on a ``(z, y, x)`` grid (see
        :func:`~harpx.io.labels.read_labels`; a ``tagged/1`` dataset gives
        its ``body``).
    slice_axis : {"x", "y", "z"}, default "z"
        Grid axis normal to the short-axis slices (the closest one for oblique hearts).
    variable : str, optional
        Mask variable of a dataset.
    axis : array_like, shape (3,), optional
        Long-axis direction (apex to base) that tells the base from the apex; default the
        direction from the epicardial to the endocardial points' centroid.

    Returns
    -------
    endo, epi, base : ndarray, shape (n, 3)
        Image points (mm) of the 0.5 iso-contour: in-plane crossings split by the side of
        the cavity, and slice-axis crossings with tissue on their apical side only
        (outside the cavity).
    """
    da = read_labels(mask, variable=variable)
    f = np.asarray(da.values, dtype=np.float64)
    coords = [np.asarray(da[d].values, dtype=np.float64) for d in ("z", "y", "x")]
    inside = f >= 0.5
    normal = ("z", "y", "x").index(slice_axis)
    structure = np.zeros((3, 3, 3), dtype=bool)
    plane = [slice(None)] * 3
    plane[normal] = slice(1, 2)
    structure[tuple(plane)] = ndi.generate_binary_structure(2, 1)
    cavity = ndi.binary_fill_holes(inside, structure=structure) & ~inside

    def crossings(dim: int) -> tuple[FloatArray, Any, Any]:
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[dim], hi[dim] = slice(None, -1), slice(1, None)
        fa, fb = f[tuple(lo)], f[tuple(hi)]
        hit = (fa - 0.5) * (fb - 0.5) < 0
        idx = np.argwhere(hit)
        w = (0.5 - fa[hit]) / (fb[hit] - fa[hit])
        pos = np.stack([coords[k][idx[:, k]] for k in range(3)], axis=1)  # (z, y, x)
        step = coords[dim][1] - coords[dim][0]
        pos[:, dim] += w * step
        low_first = fa[hit] < fb[hit]
        low = idx.copy()
        low[:, dim] += np.where(low_first, 0, 1)
        return pos[:, ::-1], low, low_first

    endo_pts, epi_pts = [], []
    for dim in range(3):  # the two in-plane axes
        if dim == normal:
            continue
        pts, low, _ = crossings(dim)
        in_cavity = cavity[tuple(low.T)]
        endo_pts.append(pts[in_cavity])
        epi_pts.append(pts[~in_cavity])
    endo_all, epi_all = np.concatenate(endo_pts), np.concatenate(epi_pts)
    pts, low, low_first = crossings(normal)
    # the base faces the base direction: tissue on the apical side, nothing on the basal
    # side (the cavity centroid lies basal of the epicardial one, which holds the apex)
    if axis is None:
        axis = endo_all.mean(axis=0) - epi_all.mean(axis=0)
    towards = float(np.asarray(axis, dtype=np.float64)[2 - normal])
    outward_up = ~low_first  # the tissue is at the lower index, nothing above
    top = outward_up if towards >= 0 else ~outward_up
    base_pts = pts[top & ~cavity[tuple(low.T)]]
    return endo_all, epi_all, base_pts


def fit_ventricle_to_mask(
    mask: Any,
    *,
    slice_axis: Literal["x", "y", "z"] = "z",
    variable: str | None = None,
) -> VentricleFit:
    """Fit the ventricle to a myocardium mask (:func:`ventricle_contours` + :func:`fit_ventricle`).

    Parameters
    ----------
    mask : xarray.Dataset, xarray.DataArray, str or os.PathLike
        Myocardium fraction or mask on a ``(z, y, x)`` grid, mm.
    slice_axis : {"x", "y", "z"}, default "z"
        Grid axis normal to the short-axis slices.
    variable : str, optional
        Mask variable of a dataset.

    Returns
    -------
    VentricleFit
        The base plane is fitted to the slice-axis crossings at the top of the wall within
        one wall thickness of the highest contour point.
    """
    endo, epi, _ = ventricle_contours(mask, slice_axis=slice_axis, variable=variable)
    first = fit_ventricle(endo, epi)
    _, _, base = ventricle_contours(
        mask, slice_axis=slice_axis, variable=variable, axis=first.template.axis
    )
    t = first.template
    q = t.to_local(base)
    zb = t.geometry.truncation
    wall = t.geometry.outer[0] - t.geometry.inner[0]
    near = (np.abs(q[:, 2] - zb) < wall) & (t.geometry.transmural(q) > -0.1)
    near &= t.geometry.transmural(q) < 1.1
    if near.sum() < 3:
        return first
    return fit_ventricle(endo, epi, base=base[near], axis=t.axis)
