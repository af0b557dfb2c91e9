r"""The analytic left ventricle placed in the image and fitted to contour points.

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
:func:`~harpx.anatomy.ventricle.ventricle`, moved rigidly into the image. Its ``anterior``
angle (degrees about the long axis from the template's +x axis) is the direction of the
anterior wall, the centre of AHA segments 1, 7 and 13, as ``anterior`` of
:func:`harpx.cardiac.strain.aha_segments`.

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

:func:`~harpx.anatomy.contours.ventricle_contours` gives such points from a mask, and
:func:`~harpx.anatomy.mask_fit.fit_ventricle_to_mask` the whole fit to a mask.

Units: mm, degrees for the fibre angles.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from harpx._typing import FloatArray, IntArray
from harpx.anatomy.ventricle import VentricleGeometry
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.mechanics.cells import vtk_corners
from harpx.mechanics.mesh import MeshSpec, hex_mesh, labelled_spec

__all__ = ["VentricleFit", "VentricleTemplate", "fit_ventricle"]

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
    anterior : float, optional
        Direction of the anterior wall, the centre of AHA segments 1, 7 and 13 (Cerqueira
        et al. 2002): degrees about the long axis (right-handed about apex-to-base) from
        the template's +x axis, the ``anterior`` of :mod:`harpx.cardiac.strain` (which
        reads it from the template). Stored in [0, 360). None when unknown (no right
        ventricle in the segmentation and no angle given).

    Raises
    ------
    ValueError
        If ``rotation`` is not a proper rotation (orthonormal, det +1) or ``anterior`` is
        not a finite angle.

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
    anterior: float | None = None

    def __post_init__(self) -> None:
        c = np.asarray(self.centre, dtype=np.float64).reshape(3)
        r = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        if np.abs(r.T @ r - np.eye(3)).max() > 1e-8 or np.linalg.det(r) < 0:
            raise ValueError("rotation must be a proper orthonormal 3x3 matrix (det +1)")
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "rotation", r)
        if self.anterior is not None:
            a = float(self.anterior)
            if not np.isfinite(a):
                raise ValueError(f"anterior={self.anterior!r} must be a finite angle in degrees")
            object.__setattr__(self, "anterior", float(np.mod(a, 360.0)))

    @property
    def axis(self) -> FloatArray:
        """Unit long axis, apex to base, in image coordinates."""
        return np.asarray(self.rotation[:, 2])

    @property
    def apex(self) -> FloatArray:
        """Epicardial apex in image coordinates, mm."""
        return self.to_image(np.array([[0.0, 0.0, -self.geometry.outer[1]]]))[0]

    def angle(self, points: ArrayLike) -> FloatArray:
        """Angle (degrees in [0, 360)) of image points about the long axis from template +x.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Image points, mm.

        Returns
        -------
        ndarray, shape (n,)
            Angle about the long axis (right-handed about apex-to-base) from the
            template's +x axis, degrees in [0, 360).
        """
        q = self.to_local(points)
        return np.asarray(np.mod(np.degrees(np.arctan2(q[:, 1], q[:, 0])), 360.0))

    def to_local(self, points: ArrayLike) -> FloatArray:
        """Template coordinates ``R^T (p - c)`` of image points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Image points, mm.

        Returns
        -------
        ndarray, shape (n, 3)
            Template coordinates, mm (long axis along z, the ellipsoids' centre at 0).
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return np.asarray((p - self.centre) @ self.rotation)

    def to_image(self, points: ArrayLike) -> FloatArray:
        """Image coordinates ``c + R q`` of template points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Template coordinates, mm.

        Returns
        -------
        ndarray, shape (n, 3)
            Image coordinates, mm.
        """
        q = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return np.asarray(q @ self.rotation.T + self.centre)

    def transmural(self, points: ArrayLike) -> FloatArray:
        """Transmural fraction (0 endocardium, 1 epicardium) of image points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Image points, mm.

        Returns
        -------
        ndarray, shape (n,)
            ``t`` (dimensionless), as in :meth:`VentricleGeometry.transmural
            <harpx.anatomy.ventricle.VentricleGeometry.transmural>`: < 0 inside the cavity,
            > 1 outside the wall.
        """
        return self.geometry.transmural(self.to_local(points))

    def surface_distance(self, points: ArrayLike, surface: str) -> FloatArray:
        """Signed distance of image points from the endo- or epicardial ellipsoid.

        The level-set value over its gradient (first order in the distance, exact on the
        surface), the measure :func:`fit_ventricle` minimises: the residual of the fit.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Image points, mm.
        surface : {"endo", "epi"}
            The endocardial or the epicardial ellipsoid.

        Returns
        -------
        ndarray, shape (n,)
            Signed distance, mm, positive outside the ellipsoid.

        Raises
        ------
        ValueError
            If ``surface`` is neither ``"endo"`` nor ``"epi"``.
        """
        if surface not in ("endo", "epi"):
            raise ValueError(f"surface={surface!r} must be 'endo' or 'epi'")
        a, c = self.geometry.inner if surface == "endo" else self.geometry.outer
        return _distance(self.to_local(points), a, c)

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
        """Unit helical fibres at image points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Image points, mm (in or near the wall).
        fiber_endo, fiber_epi : float, default 60, -60
            Helix angles at the endocardium and epicardium, degrees, as in
            :meth:`VentricleGeometry.fibers <harpx.anatomy.ventricle.VentricleGeometry.fibers>`.

        Returns
        -------
        ndarray, shape (n, 3)
            Unit fibre directions in image coordinates.
        """
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
                stacklevel=user_stacklevel(),
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
            template mesh, moved rigidly into the image and turned about the long axis by
            ``anterior`` (0 when unknown): its ``aha_XX`` regions are the segments
            :func:`harpx.cardiac.strain.aha_segments` gives this template, and with
            ``n_circumferential`` a multiple of 24 (the default 48 is) every sector border
            is a cell border, so no segment mean takes part of a cell.
        """
        spec = self.geometry.mesh(**options)
        a = np.deg2rad(self.anterior or 0.0)
        turn = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0, 0, 1]])
        points = self.to_image(spec.mesh.p.T @ turn.T)
        moved = hex_mesh(points, vtk_corners(spec.mesh))
        fibers = None if spec.fibers is None else spec.fibers @ (self.rotation @ turn).T
        return labelled_spec(moved, spec.regions, spec.boundaries, fibers)


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
    flags : dict of str to str
        Problems found, by name, each with its numbers (empty for a clean fit); the same
        text was issued as a :class:`~harpx.anatomy.mask_slices.VentricleFitWarning` unless
        noted. Names:
        ``"residual"`` (rms above the limit), ``"axis"`` (fitted axis far off the slice
        normal), ``"apex_extrapolated"`` (apex out of view, placed by the ellipsoid),
        ``"base_out_of_view"`` (the base plane beyond the imaged tissue: a mesh of the mask
        has no base facets), ``"empty_segments"`` (AHA segments in view without tissue),
        ``"open_slices"`` (slices inside the stack without a closed cavity, left out),
        ``"rv_contact"`` (an implausible septal arc), and, without a warning,
        ``"out_of_view"`` (segments beyond the imaged slab, empty by design),
        ``"anterior_unknown"`` and ``"dropped_specks"``.
    segment_voxels : ndarray of int, shape (17,), optional
        Tissue voxels of the mask in each AHA segment 1..17 (mask fits only), with the
        template's ``anterior`` (0 when unknown).
    out_of_view : tuple of int
        AHA segments whose longitudinal level lies entirely outside the imaged tissue (e.g.
        the apical ring of a mid-ventricular stack): empty because not imaged.
    insertions : tuple of 2 float, optional
        Angles (degrees, measured as ``template.anterior``) of the anterior and inferior
        right-ventricular insertions found from an RV label (circular means over the
        ring slices).
    apex_uncertainty : float, optional
        For an apex out of view: three standard errors (mm) of the apex position along
        the axis from the fit's Jacobian.
    """

    template: VentricleTemplate
    endo_residual: FloatArray
    epi_residual: FloatArray
    base_residual: FloatArray
    flags: dict[str, str] = field(default_factory=dict)
    segment_voxels: IntArray | None = None
    out_of_view: tuple[int, ...] = ()
    insertions: tuple[float, float] | None = None
    apex_uncertainty: float | None = None

    @property
    def rms(self) -> float:
        """Root-mean-square distance of all endo- and epicardial points, mm."""
        d = np.concatenate([self.endo_residual, self.epi_residual])
        return float(np.sqrt(np.mean(d**2)))

    def report(self) -> dict[str, float]:
        """Residual summary in mm: rms overall, rms and 95th percentile per surface.

        Returns
        -------
        dict of str to float
            ``"rms"`` (:attr:`rms`) and, for each of ``"endo"``, ``"epi"`` and ``"base"``
            that has points, ``"<surface>_rms"`` and ``"<surface>_p95"`` (95th percentile
            of the absolute distance), mm.
        """
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


def _initial_axis(pn: FloatArray, pp: FloatArray) -> FloatArray:
    """Principal direction of the points, apex to base (the cavity lies basal of the wall)."""
    both = np.concatenate([pn, pp])
    _, _, vt = np.linalg.svd(both - both.mean(axis=0), full_matrices=False)
    u = vt[0]
    return -u if (pn.mean(axis=0) - pp.mean(axis=0)) @ u < 0 else u


def _fit_free(pn: FloatArray, pp: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Centre, axis angles and semi-axes by least squares; returns (x, residual at x)."""
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

    def residual(x: FloatArray) -> FloatArray:
        c, rot = x[:3], _frame(_axis_of(x[3], x[4]))
        qn, qp = (pn - c) @ rot, (pp - c) @ rot
        return np.concatenate([_distance(qn, x[5], x[6]), _distance(qp, x[5] + x[7], x[6] + x[8])])

    lower = np.array([-np.inf] * 5 + [0.5, 0.5, 0.1, 0.1])
    upper = np.array([np.inf] * 9)
    x0[5:] = np.maximum(x0[5:], lower[5:] + 1e-3)
    sol = least_squares(residual, x0, bounds=(lower, upper), loss="soft_l1", f_scale=1.0)
    return sol.x, residual(sol.x)


def _fit_held(
    pn: FloatArray, pp: FloatArray, u: FloatArray, apex: FloatArray | None
) -> tuple[FloatArray, FloatArray, float | None]:
    """Least squares with the long axis held at ``u``.

    Returns the full parameter vector (centre, axis angles, semi-axes as in
    :func:`_fit_free`), the residual and, for a free apex, three standard errors (mm) of
    the endocardial apex position along the axis (Gauss-Newton covariance, the residual
    variance floored at the quantisation of a 1 mm grid).
    """
    rot = _frame(u)
    qn, qp = pn @ rot, pp @ rot  # template-oriented coordinates about the image origin
    c_xy = qp[:, :2].mean(axis=0)
    radial_n = np.linalg.norm(qn[:, :2] - c_xy, axis=1)
    radial_p = np.linalg.norm(qp[:, :2] - c_xy, axis=1)
    a0 = float(np.median(radial_n))
    da = max(float(np.median(radial_p)) - a0, 1.0)
    s_top, s_bottom = float(qp[:, 2].max()), float(qp[:, 2].min())
    s_apex = None if apex is None else float(np.asarray(apex, dtype=np.float64) @ u)
    # an ellipsoid elongated like a left ventricle (c about 2.5 a), centred mid-stack
    c0 = 2.5 * a0 if s_apex is None else max(0.5 * (s_top + s_bottom) - s_apex, 1.0)
    s0 = 0.5 * (s_top + s_bottom) if s_apex is None else s_apex + c0

    def unpack(y: FloatArray) -> tuple[FloatArray, float, float, float, float]:
        if s_apex is None:
            centre = np.array([y[0], y[1], y[2]])
            return centre, y[3], y[4], y[5], y[6]
        centre = np.array([y[0], y[1], s_apex + y[3]])
        return centre, y[2], y[3], y[4], y[5]

    def residual(y: FloatArray) -> FloatArray:
        centre, a_n, c_n, d_a, d_c = unpack(y)
        return np.concatenate(
            [_distance(qn - centre, a_n, c_n), _distance(qp - centre, a_n + d_a, c_n + d_c)]
        )

    if s_apex is None:
        y0 = np.array([*c_xy, s0, a0, c0, da, 8.0])
        lower = np.array([-np.inf] * 3 + [0.5, 0.5, 0.1, 0.1])
    else:
        y0 = np.array([*c_xy, a0, c0, da, 8.0])
        lower = np.array([-np.inf] * 2 + [0.5, 0.5, 0.1, 0.1])
    y0 = np.maximum(y0, lower + 1e-3)
    sol = least_squares(
        residual, y0, bounds=(lower, np.full(len(y0), np.inf)), loss="soft_l1", f_scale=1.0,
        x_scale="jac",
    )  # fmt: skip
    centre_q, a_n, c_n, d_a, d_c = unpack(sol.x)
    r = residual(sol.x)
    uncertainty = None
    if s_apex is None:
        jac = np.asarray(sol.jac)
        dof = max(len(r) - len(sol.x), 1)
        variance = max(float(np.sum(r**2)) / dof, 1.0 / 12.0)
        cov = variance * np.linalg.pinv(jac.T @ jac)
        g = np.zeros(len(sol.x))
        g[2], g[4] = 1.0, -1.0  # apex = centre - c_endo along the axis
        uncertainty = 3.0 * float(np.sqrt(max(float(g @ cov @ g), 0.0)))
    centre = rot @ centre_q
    theta, phi = float(np.arccos(np.clip(u[2], -1, 1))), float(np.arctan2(u[1], u[0]))
    x = np.array([*centre, theta, phi, a_n, c_n, d_a, d_c])
    return x, r, uncertainty


def fit_ventricle(
    endo: ArrayLike,
    epi: ArrayLike,
    *,
    base: ArrayLike | None = None,
    axis: ArrayLike | None = None,
    hold_axis: bool = False,
    apex: ArrayLike | None = None,
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
    hold_axis : bool, default False
        Keep the long axis at ``axis`` (e.g. the normal of a short-axis stack whose few
        slices cannot resolve its tilt); only the centre and the semi-axes are fitted.
    apex : array_like, shape (3,), optional
        With ``hold_axis``: an image point at the level of the endocardial apex (only its
        position along the axis counts), for contours that do not reach the apex.

    Returns
    -------
    VentricleFit
        With ``hold_axis`` and no ``apex``, ``apex_uncertainty`` is three standard errors
        (mm) of the apex position along the axis.

    Raises
    ------
    ValueError
        If fewer than 10 points per surface are given, ``hold_axis`` lacks ``axis``,
        ``apex`` lacks ``hold_axis``, or the fit is not a valid ventricle.
    """
    pn = np.asarray(endo, dtype=np.float64).reshape(-1, 3)
    pp = np.asarray(epi, dtype=np.float64).reshape(-1, 3)
    if len(pn) < 10 or len(pp) < 10:
        raise ValueError(
            f"fit_ventricle needs at least 10 points per surface, got {len(pn)} endo and "
            f"{len(pp)} epi; add contours"
        )
    if hold_axis and axis is None:
        raise ValueError("hold_axis=True needs axis= (the long-axis direction, apex to base)")
    if apex is not None and not hold_axis:
        raise ValueError("apex= is used with hold_axis=True (a held axis); pass both")
    u = _initial_axis(pn, pp) if axis is None else np.asarray(axis, dtype=np.float64)
    u = u / np.linalg.norm(u)
    uncertainty = None
    if hold_axis:
        apex_point = None if apex is None else np.asarray(apex, dtype=np.float64).reshape(3)
        x, res, uncertainty = _fit_held(pn, pp, u, apex_point)
    else:
        x, res = _fit_free(pn, pp, u)
    c, rot = x[:3], _frame(_axis_of(x[3], x[4]))
    if hold_axis:
        rot = _frame(u)
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
    return VentricleFit(
        VentricleTemplate(geometry, c, rot),
        res[: len(pn)],
        res[len(pn) :],
        base_res,
        apex_uncertainty=uncertainty,
    )
