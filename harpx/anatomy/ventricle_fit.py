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

:func:`ventricle_contours` extracts the points from a myocardium mask (a tissue fraction
such as a ``tagged/1`` dataset's ``body``, or a binary mask): the 0.5 iso-contour is found
between neighbouring voxel centres by linear interpolation along the two in-plane axes of
the short-axis slices; a crossing whose low side lies in the cavity (the holes of the mask
within each slice) is endocardial, otherwise epicardial; crossings along the slice axis
near the top of the wall give the base. Long-axis contours are simply more points for
:func:`fit_ventricle`.

Fit to a mask
-------------
:func:`fit_ventricle_to_mask` takes the stacks scans provide and refuses what it cannot
trust (:class:`VentricleFitError`, a ``ValueError``) or flags it (``fit.flags`` and a
:class:`VentricleFitWarning`), stating the numbers:

* **One piece with a cavity.** The myocardium (``myocardium=`` picks its label in a
  segmentation) must be one face-connected piece (specks under 1 % of it are dropped and
  flagged) and at least one short-axis slice must be a ring, i.e. enclose a cavity (a
  filled disc or cylinder is refused). Slices with tissue beyond the last ring form the
  apical cap; slices inside the stack without a closed cavity are left out (flagged).
* **Long axis.** For a short-axis stack (thick slices, or no apex in view) the long axis
  is the stack normal (a few slices cannot resolve its tilt; an ``axis=`` hint more than 15°
  off is refused). A 3-D segmentation that shows the apex, or long-axis slices, let the
  axis be fitted (flagged beyond 30° off the normal). Its sense (apex to base) comes from
  the apical cap, the user (``base_side``, an axis hint) or long-axis slices (the end
  where the wall crosses the axis is the apex); otherwise the fit is refused.
* **Base and apex levels.** The base plane comes from ``base_level``, long-axis slices or,
  with the apex in view, the top face of the mask; without any of these it is refused.
  An apex out of view is extrapolated by the ellipsoid (flagged with three standard errors
  of its position, refused when that exceeds a slice step and a tenth of the cavity) unless
  ``apex_level`` is given. A base plane more than 3 mm beyond the imaged tissue is
  flagged: a mesh of the mask has no base facets there.
* **Anterior.** An RV label (``rv=``) gives the septum as the LV voxels within two voxels
  of it in each ring slice; the septum spans from the anterior to the inferior insertion
  in the negative sense about the apex-to-base axis (counter-clockwise seen from the apex,
  the AHA order anterior, anteroseptal, inferoseptal, in a right-handed patient frame).
  The anterior wall, the centre of segments 1, 7 and 13 (``template.anterior``), lies 90°
  from the middle of the septum towards the lateral wall (the septum is segments 2-3 and
  8-9; Cerqueira et al. 2002), the convention of :mod:`harpx.cardiac.strain`.
  ``anterior=`` sets it directly.
* **Residual and segments.** rms residuals above one in-plane voxel are flagged. Every
  tissue voxel gets its AHA segment (the convention of
  :func:`harpx.cardiac.strain.aha_segments`): segments whose level lies beyond the imaged
  tissue are reported as ``out_of_view`` (empty, not invented); empty segments in view are
  flagged.

Units: mm, degrees for the fibre angles.

References
----------
.. [1] Cerqueira MD et al. Standardized myocardial segmentation and nomenclature for
   tomographic imaging of the heart. Circulation 105:539--542, 2002.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import scipy.ndimage as ndi
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from harpx._typing import FloatArray, IntArray
from harpx.anatomy.aha import segments_local
from harpx.anatomy.ventricle import VentricleGeometry, ventricle
from harpx.errors import HarpxError, HarpxWarning
from harpx.io.labels import read_labels
from harpx.mechanics.mesh import MeshSpec, hex_mesh, labelled_spec

__all__ = [
    "VentricleFit",
    "VentricleFitError",
    "VentricleFitWarning",
    "VentricleTemplate",
    "fit_ventricle",
    "fit_ventricle_to_mask",
    "ventricle_contours",
]

_AXES = ("x", "y", "z")


class VentricleFitError(HarpxError, ValueError):
    """A mask or contours the ventricle cannot be fitted to as asked.

    The message states what is wrong with the numbers (e.g. two separate blobs and their
    sizes, no cavity in any short-axis slice, an axis hint far off the slice normal) and
    what to pass instead.
    """


class VentricleFitWarning(HarpxWarning):
    """A fit that can be used but should be checked; the text is also in ``fit.flags``."""


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
        """Angle (degrees in [0, 360)) of image points about the long axis from template +x."""
        q = self.to_local(points)
        return np.asarray(np.mod(np.degrees(np.arctan2(q[:, 1], q[:, 0])), 360.0))

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
    flags : dict of str to str
        Problems found, by name, each with its numbers (empty for a clean fit); the same
        text was issued as a :class:`VentricleFitWarning` unless noted. Names:
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
        """Residual summary in mm: rms, mean absolute distance and 95th percentile per surface."""
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


def _crossings(
    f: FloatArray, coords: list[FloatArray], dim: int
) -> tuple[FloatArray, IntArray, Any]:
    """0.5 crossings of ``f`` along grid dimension ``dim`` (0 z, 1 y, 2 x).

    Returns the points (n, 3; x, y, z mm, linear interpolation between voxel centres), the
    (z, y, x) index of the voxel on the low-valued side, and whether that side comes first.
    """
    lo = [slice(None)] * 3
    hi = [slice(None)] * 3
    lo[dim], hi[dim] = slice(None, -1), slice(1, None)
    fa, fb = f[tuple(lo)], f[tuple(hi)]
    hit = (fa - 0.5) * (fb - 0.5) < 0
    idx = np.argwhere(hit)
    w = (0.5 - fa[hit]) / (fb[hit] - fa[hit])
    pos = np.stack([coords[k][idx[:, k]] for k in range(3)], axis=1)  # (z, y, x)
    step = np.diff(coords[dim])[idx[:, dim]]
    pos[:, dim] += w * step
    low_first = fa[hit] < fb[hit]
    low = idx.copy()
    low[:, dim] += np.where(low_first, 0, 1)
    return pos[:, ::-1], low, low_first


def _plane_structure(normal: int) -> Any:
    """4-connected in-plane structuring element of the slices normal to ``normal``."""
    structure = np.zeros((3, 3, 3), dtype=bool)
    plane = [slice(None)] * 3
    plane[normal] = slice(1, 2)
    structure[tuple(plane)] = ndi.generate_binary_structure(2, 1)
    return structure


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
        (outside the cavity). Voxels fill their extent: beyond the first and last slice
        the mask is taken as background, so the end faces lie half a slice step beyond
        the outer slice centres.
    """
    da = read_labels(mask, variable=variable)
    f, coords = _padded_along(np.asarray(da.values, dtype=np.float64), da, slice_axis)
    normal = ("z", "y", "x").index(slice_axis)
    inside = f >= 0.5
    cavity = ndi.binary_fill_holes(inside, structure=_plane_structure(normal)) & ~inside
    return _contours(f, coords, normal, cavity, axis, np.ones(f.shape[normal], dtype=bool))


def _padded_along(f: FloatArray, da: Any, slice_axis: str) -> tuple[FloatArray, list[FloatArray]]:
    """The volume with one background slice added at both ends of the slice axis."""
    normal = ("z", "y", "x").index(slice_axis)
    coords = [np.asarray(da[d].values, dtype=np.float64) for d in ("z", "y", "x")]
    c = coords[normal]
    step = c[1] - c[0] if c.size > 1 else 1.0
    coords[normal] = np.concatenate([[c[0] - step], c, [c[-1] + step]])
    pad = [(0, 0)] * 3
    pad[normal] = (1, 1)
    return np.pad(f, pad, mode="constant", constant_values=0.0), coords


def _contours(
    f: FloatArray,
    coords: list[FloatArray],
    normal: int,
    cavity: Any,
    axis: ArrayLike | None,
    use: Any,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Endo, epi and base points of ``f`` from the slices flagged in ``use``."""
    endo_pts, epi_pts = [], []
    for dim in range(3):  # the two in-plane axes
        if dim == normal:
            continue
        pts, low, _ = _crossings(f, coords, dim)
        keep = use[low[:, normal]]
        in_cavity = cavity[tuple(low.T)]
        endo_pts.append(pts[keep & in_cavity])
        epi_pts.append(pts[keep & ~in_cavity])
    endo_all, epi_all = np.concatenate(endo_pts), np.concatenate(epi_pts)
    pts, low, low_first = _crossings(f, coords, normal)
    # the base faces the base direction: tissue on the apical side, nothing on the basal
    # side (the cavity centroid lies basal of the epicardial one, which holds the apex)
    if axis is None:
        axis = endo_all.mean(axis=0) - epi_all.mean(axis=0)
    towards = float(np.asarray(axis, dtype=np.float64)[2 - normal])
    outward_up = ~low_first  # the tissue is at the lower index, nothing above
    top = outward_up if towards >= 0 else ~outward_up
    base_pts = pts[top & ~cavity[tuple(low.T)]]
    return endo_all, epi_all, base_pts


def _covers_axis(inside: Any, cavity: Any, normal: int, ring: int, towards: int) -> bool:
    """Whether the slice next to ring slice ``ring`` (in direction ``towards``) has tissue
    within two voxels of the centroid of that ring's cavity."""
    hole = np.argwhere(np.take(cavity, ring, axis=normal))
    tissue = np.argwhere(np.take(inside, ring + towards, axis=normal))
    if hole.size == 0 or tissue.size == 0:
        return False
    return bool(np.min(np.linalg.norm(tissue - hole.mean(axis=0), axis=1)) <= 2.0)


def _aha(template: VentricleTemplate, points: ArrayLike) -> IntArray:
    """AHA segment (1..17) of image points.

    The convention of :func:`harpx.cardiac.strain.aha_segments` with the template's
    ``anterior`` (0 when unknown): thirds of the cavity from the endocardial apex to the
    base plane; 60° (apical 90°) sectors, the first centred on ``anterior``, numbered
    counter-clockwise seen from the apex (clockwise about the template's z axis).
    """
    return segments_local(template.to_local(points), template.geometry, template.anterior or 0.0)


def _labels(values: Any, what: str, myocardium: Any, rv: Any) -> tuple[FloatArray, Any]:
    """Myocardium fraction and RV mask (or None) of a label volume."""
    if not np.all(np.isfinite(values)):
        raise VentricleFitError(f"{what} contains NaN or inf; fill it (e.g. mask.fillna(0))")
    integral = values.dtype == bool or bool(np.all(np.isclose(values, np.rint(values))))
    myo = None if myocardium is None else [int(v) for v in np.atleast_1d(myocardium)]
    rvl = None if rv is None else [int(v) for v in np.atleast_1d(rv)]
    if not integral:
        if values.min() < 0 or values.max() > 1:
            raise VentricleFitError(
                f"{what} is neither integer labels nor a fraction in [0, 1] (range "
                f"{values.min():.3g} .. {values.max():.3g}); pass a myocardium mask or labels"
            )
        if myo is not None or rvl is not None:
            raise VentricleFitError(
                f"{what} is a tissue fraction, not integer labels: myocardium= and rv= select "
                "labels of an integer segmentation"
            )
        return values.astype(np.float64), None
    ints = np.rint(values).astype(np.int64)
    present = [int(v) for v in np.unique(ints) if v != 0]
    if myo is None:
        myo = [v for v in present if v not in (rvl or [])]
        if len(myo) > 1:
            raise VentricleFitError(
                f"{what} holds labels {present[:10]!r}; say which is the left-ventricular "
                "myocardium with myocardium=<label> (and the right ventricle with rv=)"
            )
    missing = [v for v in (*myo, *(rvl or [])) if v not in present]
    if missing:
        raise VentricleFitError(
            f"labels {missing!r} are not in {what} (present: {present[:10]!r}); check "
            "myocardium= and rv="
        )
    rv_mask = None if rvl is None else np.isin(ints, rvl)
    return np.isin(ints, myo).astype(np.float64), rv_mask


def _warn(flags: dict[str, str], name: str, message: str, *, warn: bool = True) -> None:
    flags[name] = message
    if warn:
        warnings.warn(message, VentricleFitWarning, stacklevel=3)


def _read_lax(
    sources: Sequence[Any], variable: str | None, myocardium: Any
) -> list[tuple[FloatArray, list[FloatArray], FloatArray]]:
    """Long-axis masks: padded fraction, padded (z, y, x) coordinates, tissue points (x, y, z)."""
    out = []
    for k, source in enumerate(sources):  # a few long-axis slices
        da = read_labels(source, variable=variable)
        f, _ = _labels(np.asarray(da.values), f"long_axis_slices[{k}]", myocardium, None)
        f = np.pad(f, [(1, 1)] * 3, mode="constant", constant_values=0.0)
        coords = []
        for d in ("z", "y", "x"):
            c = np.asarray(da[d].values, dtype=np.float64)
            step = c[1] - c[0] if c.size > 1 else 1.0
            coords.append(np.concatenate([[c[0] - step], c, [c[-1] + step]]))
        tissue = np.argwhere(f >= 0.5)
        if len(tissue) < 10:
            raise VentricleFitError(
                f"long_axis_slices[{k}] holds {len(tissue)} myocardium voxels; pass the "
                "long-axis slice's myocardium mask"
            )
        xyz = np.stack([coords[2 - a][tissue[:, 2 - a]] for a in range(3)], axis=1)
        out.append((f, coords, xyz))
    return out


def _lax_sense(
    volumes: list[tuple[FloatArray, list[FloatArray], FloatArray]],
    centre: FloatArray,
    e_n: FloatArray,
    band: float,
) -> float | None:
    """+1 when long-axis slices put the apex at the low end of ``e_n``, -1 at the high end.

    At the apex the wall crosses the long axis (the line through ``centre`` along ``e_n``);
    at the base its two sides stay a cavity radius away. The end of the tissue (within
    ``band`` mm of its extreme) that comes closer to the axis is the apex; None when
    neither end does (closer than half the other's distance).
    """
    xyz = np.concatenate([v[2] for v in volumes])
    s = (xyz - centre) @ e_n
    r = np.linalg.norm((xyz - centre) - np.outer(s, e_n), axis=1)
    near_low = float(r[s < s.min() + band].min())
    near_high = float(r[s > s.max() - band].min())
    if near_low < 0.5 * near_high:
        return 1.0
    if near_high < 0.5 * near_low:
        return -1.0
    return None


def _lax_points(
    volumes: list[tuple[FloatArray, list[FloatArray], FloatArray]], template: VentricleTemplate
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Endo, epi and base points of long-axis label volumes, classified by ``template``.

    Each volume holds the myocardium of one long-axis slice on an axis-aligned grid (the
    slice's slab, background elsewhere). Iso-surface crossings whose mask gradient points
    out of the slice plane (the slab faces) are dropped; the others are endocardial where
    the tissue lies outward of the crossing along the template's layer normal, epicardial
    otherwise, and basal where the tissue lies apical of a crossing in the upper half of
    the slice's tissue.
    """
    endo, epi, base = [], [], []
    u = template.axis
    for f, coords, xyz in volumes:  # a few long-axis slices
        _, sv, vt = np.linalg.svd(xyz - xyz.mean(axis=0), full_matrices=False)
        plane_normal = vt[2] if sv[2] < 0.3 * sv[0] else None
        grad = np.gradient(f, *coords)  # d/dz, d/dy, d/dx
        s_tissue = xyz @ u
        s_mid = 0.5 * (s_tissue.min() + s_tissue.max())
        for dim in range(3):
            pts, low, low_first = _crossings(f, coords, dim)
            high = low.copy()
            high[:, dim] += np.where(low_first, 1, -1)
            g = np.stack(
                [0.5 * (grad[2 - a][tuple(low.T)] + grad[2 - a][tuple(high.T)]) for a in range(3)],
                axis=1,
            )
            g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
            if plane_normal is not None:
                in_plane = np.abs(g @ plane_normal) < 0.5
                pts, g = pts[in_plane], g[in_plane]
            e_r = template.local_basis(pts)[0]
            basal = (g @ u < -0.7) & (pts @ u > s_mid)
            outward = np.einsum("ni,ni->n", g, e_r) > 0
            endo.append(pts[~basal & outward])
            epi.append(pts[~basal & ~outward])
            base.append(pts[basal])
    return np.concatenate(endo), np.concatenate(epi), np.concatenate(base)


def _insertions(
    template: VentricleTemplate, points: FloatArray, slices: IntArray
) -> tuple[float, float, float, FloatArray]:
    """RV insertions and septum: anterior and inferior insertion and septal middle angles
    (degrees) and the septal arc width per slice.

    ``points`` are LV myocardium voxels next to the right ventricle and ``slices`` their
    slice index. In each slice the contact angles cover the septum; the largest angular gap
    between them is the free wall. The septum runs from the anterior insertion to the
    inferior one in the negative sense about the apex-to-base axis (counter-clockwise seen
    from the apex, the AHA order anterior, anteroseptal, inferoseptal), so the anterior
    insertion is the end of the contact arc in the positive sense. Slice values are
    combined by their circular mean.
    """
    angles = template.angle(points)
    ant, inf, middle, width = [], [], [], []
    for k in np.unique(slices):  # a few slices
        a = np.sort(angles[slices == k])
        if a.size < 3:
            continue
        gaps = np.diff(np.append(a, a[0] + 360.0))
        i = int(np.argmax(gaps))
        ant.append(a[i])
        inf.append(a[(i + 1) % a.size])
        width.append(360.0 - gaps[i])
        middle.append(a[i] - 0.5 * width[-1])

    def circular_mean(v: list[float]) -> float:
        r = np.deg2rad(np.asarray(v))
        return float(np.mod(np.degrees(np.arctan2(np.sin(r).mean(), np.cos(r).mean())), 360.0))

    if not ant:
        return float("nan"), float("nan"), float("nan"), np.empty(0)
    return circular_mean(ant), circular_mean(inf), circular_mean(middle), np.asarray(width)


def fit_ventricle_to_mask(
    mask: Any,
    *,
    slice_axis: Literal["x", "y", "z"] = "z",
    variable: str | None = None,
    myocardium: int | Sequence[int] | None = None,
    rv: int | Sequence[int] | None = None,
    anterior: float | ArrayLike | None = None,
    base_side: Literal["high", "low"] | None = None,
    base_level: float | None = None,
    apex_level: float | None = None,
    axis: Literal["auto", "slice", "fit"] | ArrayLike = "auto",
    long_axis_slices: Sequence[Any] = (),
    max_residual: float | None = None,
) -> VentricleFit:
    """Fit the ventricle to a myocardium mask or segmentation, refusing what it cannot trust.

    Works from what scans provide: a short-axis stack alone (a few slices, apex or base
    possibly out of view), a short-axis stack with long-axis slices, or a full 3-D
    segmentation. The steps and checks are in the module docstring ("Fit to a mask").

    Parameters
    ----------
    mask : xarray.Dataset, xarray.DataArray, str or os.PathLike
        Myocardium fraction, binary mask or integer segmentation on a ``(z, y, x)`` grid of
        voxel centres, mm (see :func:`~harpx.io.labels.read_labels`); coordinates in a
        right-handed patient frame (DICOM LPS, as :func:`~harpx.io.dicom.read_tagged` and
        ``read_labels`` give) for the RV insertions to be told apart.
    slice_axis : {"x", "y", "z"}, default "z"
        Grid axis normal to the short-axis slices.
    variable : str, optional
        Mask variable of a dataset.
    myocardium : int or sequence of int, optional
        Label(s) of the left-ventricular myocardium in an integer segmentation; required
        when it holds more than one label besides ``rv``.
    rv : int or sequence of int, optional
        Label(s) of the right ventricle (wall or blood pool) in the segmentation: its
        contact with the LV myocardium is the septum (segments 2-3); the anterior wall,
        ``template.anterior``, lies 90° from its middle towards the lateral wall.
    anterior : float or array_like of shape (3,), optional
        Instead of ``rv``: the direction of the anterior wall (the centre of segments 1, 7
        and 13) as an angle (degrees about the long axis, apex to base, from the
        template's +x axis: the image x axis projected onto the short-axis plane, or y for
        a long axis along x) or as an image point on it (mm).
    base_side : {"high", "low"}, optional
        Which end of the slice axis the base lies towards (increasing or decreasing
        coordinate). Needed when the mask does not show the apex (no apical cap: slices
        with tissue but no cavity beyond the last ring).
    base_level : float, optional
        Slice-axis coordinate (mm) of the base plane on the long axis. Default: from
        long-axis slices, else the top face of the mask when the apex is in view; required
        otherwise (the top of a partial stack need not be the base).
    apex_level : float, optional
        Slice-axis coordinate (mm) of the endocardial apex, for a short-axis stack that
        does not reach it; default: extrapolated by the fitted ellipsoid (flagged, refused
        when its uncertainty exceeds a slice step and a tenth of the cavity length).
    axis : {"auto", "slice", "fit"} or array_like of shape (3,), default "auto"
        The long axis: ``"slice"`` holds it at the slice normal; ``"fit"`` fits it;
        ``"auto"`` fits it for a 3-D segmentation that shows the apex (slice step at most
        1.5 times the in-plane step) or with long-axis slices, and holds it at the slice
        normal otherwise (a short-axis stack). A vector (apex to base) is a hint: held when
        the axis is held (refused more than 15° off the slice normal), the start of the fit
        otherwise (refused more than 45° off).
    long_axis_slices : sequence of masks, optional
        Long-axis myocardium masks (each a label volume on an axis-aligned grid, background
        outside its slice, e.g. resampled by ``read_tagged``): they add contour points along
        the long axis, show the apex and give the base.
    max_residual : float, optional
        rms residual (mm) above which the fit is flagged; default one in-plane voxel.

    Returns
    -------
    VentricleFit
        The template (with ``anterior`` when known), residuals, ``flags``, the voxel count
        of every AHA segment (``segment_voxels``), the segments out of view and the RV
        insertions.

    Raises
    ------
    VentricleFitError
        (a ``ValueError``) The mask is empty or not finite; it holds several labels and no
        ``myocardium``; the myocardium is in more than one piece (each at least 1 % of the
        largest); no short-axis slice encloses a cavity (a filled disc or cylinder); the
        base cannot be told from the apex; the base level is unknown; an axis hint
        contradicts the stack; the apex cannot be located; the RV label does not touch the
        myocardium; the base or apex level lies outside the fitted ventricle.

    Warns
    -----
    VentricleFitWarning
        For each warned entry of ``flags`` (residual, axis, apex extrapolated, base out of
        view, empty segments in view, open slices, implausible septal arc).
    """
    da = read_labels(mask, variable=variable)
    values = np.asarray(da.values)
    if slice_axis not in ("x", "y", "z"):
        raise VentricleFitError(f"slice_axis={slice_axis!r} must be 'x', 'y' or 'z'")
    if base_side not in (None, "high", "low"):
        raise VentricleFitError(f"base_side={base_side!r} must be 'high', 'low' or None")
    if rv is not None and anterior is not None:
        raise VentricleFitError("pass either rv= (a right-ventricle label) or anterior=, not both")
    f, rv_mask = _labels(values, "the mask", myocardium, rv)
    normal = ("z", "y", "x").index(slice_axis)
    other = tuple(d for d in range(3) if d != normal)
    e_n = np.zeros(3)
    e_n[2 - normal] = 1.0
    coords = [np.asarray(da[d].values, dtype=np.float64) for d in ("z", "y", "x")]
    steps = [float(np.abs(np.diff(c)).min()) if c.size > 1 else np.inf for c in coords]
    in_plane = min(steps[d] for d in other)
    step_n = steps[normal] if np.isfinite(steps[normal]) else in_plane
    flags: dict[str, str] = {}

    # the myocardium: one piece
    inside = f >= 0.5
    if not inside.any():
        raise VentricleFitError(
            f"the mask holds no myocardium (no voxel >= 0.5 among {values.size}); pass the "
            "segmentation of the left-ventricular wall"
        )
    pieces, count = ndi.label(inside)
    if count > 1:
        sizes = np.bincount(pieces.ravel())[1:]
        order = np.argsort(sizes)[::-1]
        if sizes[order[1]] >= 0.01 * sizes[order[0]]:
            centres = ndi.center_of_mass(inside, pieces, order[:3] + 1)
            where = [
                tuple(round(float(np.interp(c[k], np.arange(len(coords[k])), coords[k])), 1)
                      for k in (2, 1, 0))
                for c in centres
            ]  # fmt: skip
            raise VentricleFitError(
                f"the myocardium is in {count} separate pieces of {sizes[order[:5]].tolist()} "
                f"voxels (centres x, y, z mm: {where}); a ventricle is one piece: pass the "
                "left-ventricular wall only (e.g. mask.where(labels == ...)) or fix the gaps"
            )
        keep = pieces == 1 + order[0]
        f = np.where(ndi.binary_dilation(keep), f, 0.0)
        inside = f >= 0.5
        _warn(
            flags, "dropped_specks",
            f"{count - 1} specks of {int(sizes.sum() - sizes[order[0]])} voxels in all "
            f"(< 1 % of the {int(sizes[order[0]])}-voxel myocardium) were left out",
            warn=False,
        )  # fmt: skip

    # short-axis slices: rings (tissue around a cavity), the apical cap, open slices
    cavity = ndi.binary_fill_holes(inside, structure=_plane_structure(normal)) & ~inside
    tissue_n = inside.sum(axis=other)
    cavity_n = cavity.sum(axis=other)
    ring = cavity_n >= np.maximum(3, 0.02 * (tissue_n + cavity_n))
    tissue_k = np.nonzero(tissue_n)[0]
    ring_k = np.nonzero(ring)[0]
    if ring_k.size == 0:
        raise VentricleFitError(
            f"no short-axis slice (normal {slice_axis}) of the mask encloses a cavity: its "
            f"{tissue_k.size} slices with tissue are filled discs, as of a solid cylinder or "
            "of myocardium and blood pool together; pass the myocardium alone (or "
            "myocardium=<label>), or the right slice_axis"
        )
    open_k = tissue_k[(tissue_k > ring_k.min()) & (tissue_k < ring_k.max()) & ~ring[tissue_k]]
    # an apical cap: tissue beyond the last ring that covers the ring's axis (a disc); the
    # open arcs of an oblique base do not
    cap_low = tissue_k.min() < ring_k.min() and _covers_axis(
        inside, cavity, normal, ring_k.min(), -1
    )
    cap_high = tissue_k.max() > ring_k.max() and _covers_axis(
        inside, cavity, normal, ring_k.max(), 1
    )
    cap_k = tissue_k[(cap_low & (tissue_k < ring_k.min())) | (cap_high & (tissue_k > ring_k.max()))]
    slice_pos = coords[normal]
    if open_k.size:
        _warn(
            flags, "open_slices",
            f"{open_k.size} short-axis slices inside the stack have tissue but no closed "
            f"cavity ({slice_axis} = {np.round(slice_pos[open_k], 2).tolist()} mm) and were "
            "left out; close the ring in the segmentation to use them",
        )  # fmt: skip

    # the septum: myocardium of the ring slices within two voxels of the right ventricle
    touch = None
    if rv_mask is not None:
        near = ndi.binary_dilation(rv_mask, structure=_plane_structure(normal), iterations=2)
        in_rings = np.isin(np.arange(f.shape[normal]), ring_k)
        touch = np.argwhere(near & inside & np.expand_dims(in_rings, other))
        if len(touch) == 0:
            raise VentricleFitError(
                f"the right-ventricle label {rv!r} does not touch the left-ventricular "
                "myocardium in any ring slice (within 2 voxels); check rv= and myocardium="
            )

    # the sense of the long axis (apex to base)
    hint = None
    if isinstance(axis, str):
        if axis not in ("auto", "slice", "fit"):
            raise VentricleFitError(f"axis={axis!r} must be 'auto', 'slice', 'fit' or a vector")
    else:
        hint = np.asarray(axis, dtype=np.float64).reshape(3)
        if not (np.all(np.isfinite(hint)) and np.linalg.norm(hint) > 0):
            raise VentricleFitError(f"axis={axis!r} must be a finite non-zero vector")
        hint = hint / np.linalg.norm(hint)
    sense_user = None if base_side is None else (1.0 if base_side == "high" else -1.0)
    sense_hint = None if hint is None or hint @ e_n == 0 else float(np.sign(hint @ e_n))
    sense_cap = 1.0 if cap_low and not cap_high else -1.0 if cap_high and not cap_low else None
    if sense_user is not None and sense_hint is not None and sense_user != sense_hint:
        raise VentricleFitError(
            f"base_side={base_side!r} contradicts axis={axis!r} (apex to base); give one of them"
        )
    sense = sense_user if sense_user is not None else sense_hint
    lax = _read_lax(list(long_axis_slices), variable, myocardium)
    if lax and sense is None and sense_cap is None:
        grid_c = np.meshgrid(*coords, indexing="ij")
        ring_centre = np.array([float(grid_c[2 - a][cavity].mean()) for a in range(3)])
        sense = _lax_sense(lax, ring_centre, e_n, band=max(step_n, 3.0 * in_plane))
    if sense is not None and sense_cap is not None and sense != sense_cap:
        cap_at = slice_pos[tissue_k.min()] if cap_low else slice_pos[tissue_k.max()]
        raise VentricleFitError(
            f"the base is said to lie towards {'high' if sense > 0 else 'low'} {slice_axis}, "
            f"but the apical cap of the mask (tissue without cavity, {slice_axis} = "
            f"{cap_at:.4g} mm) lies at that end; check base_side / axis"
        )
    if sense is None:
        sense = sense_cap
    if sense is None:
        raise VentricleFitError(
            "cannot tell the base from the apex: the mask shows no apical cap (every end "
            f"slice along {slice_axis} is a ring{' or both ends are capped' if cap_low else ''}"
            "); pass base_side='high' or 'low' (the base lies towards increasing or "
            f"decreasing {slice_axis}) or long_axis_slices="
        )
    apex_in_view = bool(cap_low if sense > 0 else cap_high)
    thick = step_n > 1.5 * in_plane
    if axis == "slice":
        hold = True
    elif axis == "fit":
        hold = False
    else:
        hold = not ((apex_in_view and not thick) or bool(lax))
    u0 = sense * e_n
    if hint is not None:
        off = float(np.degrees(np.arccos(min(abs(float(hint @ e_n)), 1.0))))
        limit = 15.0 if hold else 45.0
        if off > limit:
            what = "a short-axis stack (axis held at its normal)" if hold else "the slices"
            raise VentricleFitError(
                f"axis={np.round(hint, 3).tolist()} is {off:.1f} degrees off the normal of "
                f"{what} ({slice_axis}, limit {limit:g}); short-axis slices are planned "
                "across the long axis: check axis and slice_axis, or resample the images"
            )
        u0 = hint * np.sign(hint @ e_n) * sense
    if apex_level is not None and not hold:
        raise VentricleFitError(
            "apex_level is for a short-axis stack that does not reach the apex (axis held at "
            "the slice normal); this mask is fitted in 3-D (apex in view or long-axis "
            "slices): drop apex_level or pass axis='slice'"
        )
    if hold and not apex_in_view and apex_level is None and not lax and ring_k.size < 3:
        raise VentricleFitError(
            f"the apex is not in view and {ring_k.size} ring slices cannot place it (the "
            "ellipsoid's centre, two long and two short radii need at least 3 levels); pass "
            "apex_level= or long_axis_slices="
        )

    # contour points (voxels fill their extent along the slice axis)
    fp, cp = _padded_along(f, da, slice_axis)
    cavity_p = np.pad(cavity, [(1, 1) if d == normal else (0, 0) for d in range(3)])
    # rings and the apical cap (all epicardium); not the open arcs beyond the base or the
    # open slices, whose inner side would pass for epicardium
    use = np.pad(np.isin(np.arange(f.shape[normal]), np.concatenate([ring_k, cap_k])), 1)
    endo, epi, base_pts = _contours(fp, cp, normal, cavity_p, u0, use)
    apex_point = None if apex_level is None else e_n * float(apex_level)
    try:
        first = fit_ventricle(endo, epi, axis=u0, hold_axis=hold, apex=apex_point)
    except ValueError as exc:
        raise VentricleFitError(f"the short-axis contours give no ventricle: {exc}") from exc
    lax_base = np.empty((0, 3))
    if lax:
        lax_endo, lax_epi, lax_base = _lax_points(lax, first.template)
        endo, epi = np.concatenate([endo, lax_endo]), np.concatenate([epi, lax_epi])
        first = fit_ventricle(endo, epi, axis=first.template.axis)
        apex_in_view = True
    t = first.template
    u = t.axis
    c = t.centre
    g = t.geometry

    # the base plane along the fitted axis
    if base_level is not None:
        truncation = (float(base_level) - c[2 - normal]) / u[2 - normal]
        base_used = np.empty((0, 3))
        source = f"base_level={base_level:g} mm"
    else:
        if len(lax_base) >= 3:
            candidates, source = lax_base, "the long-axis slices"
        elif apex_in_view:
            candidates, source = base_pts, "the top of the mask"
        else:
            top_k = tissue_k.max() if sense > 0 else tissue_k.min()
            raise VentricleFitError(
                f"the base level is unknown: the mask does not show the apex, so the top of "
                f"the stack ({slice_axis} = {slice_pos[top_k]:.4g} mm) need not be the base; "
                "pass base_level= (the slice-axis coordinate of the base plane, mm) or "
                "long_axis_slices="
            )
        if len(candidates) < 3:
            raise VentricleFitError(
                f"{source} gives {len(candidates)} base points; pass base_level="
            )
        qz = t.to_local(candidates)[:, 2]
        # the top face of the wall: its voxel staircase spans a step along the slice axis,
        # plus the rise of an oblique base plane across the ventricle
        slope = np.tan(np.arccos(min(abs(float(u @ e_n)), 1.0)))
        window = step_n + 2.0 * in_plane + g.outer[0] * slope
        t_b = g.transmural(t.to_local(candidates))
        base_used = candidates[(qz > qz.max() - window) & (t_b > -0.1) & (t_b < 1.1)]
        if len(base_used) < 3:
            raise VentricleFitError(
                f"{source} gives {len(base_used)} base points in the wall; pass base_level="
            )
        truncation = float(np.median(t.to_local(base_used)[:, 2]))
    uncertainty = first.apex_uncertainty
    if not apex_in_view and apex_level is None and uncertainty is not None:
        length = max(truncation + g.inner[1], 0.0)
        lowest = float(np.min(t.to_local(np.concatenate([endo, epi]))[:, 2]))
        allowed = max(step_n, 0.1 * length)
        apex_at = c[2 - normal] - g.inner[1] * u[2 - normal]
        if uncertainty > allowed:
            raise VentricleFitError(
                f"the apex is not in view and the slices do not locate it: the ellipsoid puts "
                f"it at {slice_axis} = {apex_at:.1f} ± {uncertainty:.1f} mm (more than "
                f"{allowed:.1f} mm), {lowest + g.inner[1]:.1f} mm beyond the lowest contour; "
                "pass apex_level= or long_axis_slices="
            )
        _warn(
            flags, "apex_extrapolated",
            f"the apex is not in view: the fitted ellipsoid places the endocardial apex at "
            f"{slice_axis} = {apex_at:.1f} ± {uncertainty:.1f} mm, {lowest + g.inner[1]:.1f} "
            "mm beyond the lowest contour; the AHA thirds depend on it (pass apex_level= if "
            "you know it)",
        )  # fmt: skip
    if not -g.inner[1] < truncation < g.inner[1]:
        raise VentricleFitError(
            f"the base plane from {source} lies {truncation:.1f} mm from the fitted centre "
            f"along the axis, outside the cavity (c_endo = {g.inner[1]:.1f} mm); check the "
            "base level and base_side"
        )
    if apex_level is not None and truncation <= -g.inner[1] + 1e-6:
        raise VentricleFitError("base_level lies at or below apex_level; check both")

    # the anterior direction
    geometry = VentricleGeometry(inner=g.inner, outer=g.outer, truncation=truncation)
    template = VentricleTemplate(geometry, c, t.rotation)
    insertions = None
    angle = None
    if anterior is not None:
        a = np.asarray(anterior, dtype=np.float64)
        angle = float(template.angle(a.reshape(1, 3))[0]) if a.size == 3 else float(a)
    elif touch is not None:
        pts = np.stack([coords[2 - a][touch[:, 2 - a]] for a in range(3)], axis=1)
        ant, inf, septum, width = _insertions(template, pts, touch[:, normal])
        if not np.isfinite(ant):
            raise VentricleFitError(
                f"the right-ventricle label {rv!r} touches the myocardium in too few voxels "
                f"({len(touch)}) to find the insertions; check rv="
            )
        # the anterior wall is 90 degrees from the middle of the septum, on the side of
        # the anterior insertion (positive about the apex-to-base axis)
        angle, insertions = float(np.mod(septum + 90.0, 360.0)), (ant, inf)
        w = float(np.median(width))
        if not 40.0 <= w <= 240.0:
            _warn(
                flags, "rv_contact",
                f"the right ventricle touches the LV myocardium over {w:.0f} degrees per "
                "slice (median; a septum spans about 120): check rv= (the RV wall or blood "
                "pool, not the LV blood pool)",
            )  # fmt: skip
    template = VentricleTemplate(geometry, c, t.rotation, anterior=angle)
    if angle is None:
        _warn(
            flags, "anterior_unknown",
            "no rv= or anterior=: the anterior wall (AHA segment 1) is unknown; segments are "
            "numbered from the template's +x axis",
            warn=False,
        )  # fmt: skip

    # residuals, checks and the segments
    qn, qp = template.to_local(endo), template.to_local(epi)
    endo_res = _distance(qn, *g.inner)
    epi_res = _distance(qp, *g.outer)
    base_res = template.to_local(base_used)[:, 2] - truncation if len(base_used) else np.empty(0)
    limit = in_plane if max_residual is None else float(max_residual)
    rms = float(np.sqrt(np.mean(np.concatenate([endo_res, epi_res]) ** 2)))
    if rms > limit:
        _warn(
            flags, "residual",
            f"the fit's rms residual is {rms:.2f} mm, above {limit:.2f} mm (one in-plane voxel "
            "by default): the mask is not well described by the truncated ellipsoid; check "
            "the segmentation",
        )  # fmt: skip
    tilt = float(np.degrees(np.arccos(np.clip(abs(float(template.axis @ e_n)), 0.0, 1.0))))
    if not hold and tilt > 30.0:
        _warn(
            flags, "axis",
            f"the fitted long axis {np.round(template.axis, 3).tolist()} is {tilt:.1f} degrees "
            f"off the slice normal ({slice_axis}); the rings of slices this oblique are "
            "elongated: resample the images across the long axis, or pass axis='slice'",
        )  # fmt: skip
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)[inside][:, ::-1]
    segment = _aha(template, grid)
    counts = np.bincount(segment, minlength=18)[1:]
    qz = template.to_local(grid)[:, 2]
    lo_view, hi_view = float(qz.min()), float(qz.max())  # tissue voxel centres
    bottom, top = -g.inner[1], truncation
    third = (top - bottom) / 3.0
    edges = {17: (-g.outer[1], bottom), 13: (bottom, bottom + third)}
    edges |= {7: (bottom + third, bottom + 2 * third), 1: (bottom + 2 * third, top)}
    ring_of = [17 if k == 17 else 13 if k >= 13 else 7 if k >= 7 else 1 for k in range(1, 18)]
    ranges = {k: edges[ring_of[k - 1]] for k in range(1, 18)}
    out_of_view = tuple(k for k, (a, b) in ranges.items() if b <= lo_view or a >= hi_view)
    empty = [k for k in range(1, 18) if counts[k - 1] == 0 and k not in out_of_view]
    if out_of_view:
        _warn(
            flags, "out_of_view",
            f"AHA segments {list(out_of_view)} lie outside the imaged tissue (voxel centres "
            f"at {lo_view:.1f} .. {hi_view:.1f} mm along the axis from the template centre) "
            "and are empty",
            warn=False,
        )  # fmt: skip
    if empty:
        _warn(
            flags, "empty_segments",
            f"AHA segments {empty} hold no tissue voxel although their level is in view: "
            "their strain will be missing (NaN); check the segmentation and the base level",
        )  # fmt: skip
    top_face = hi_view + 0.5 * step_n * abs(float(template.axis @ e_n))
    if truncation > top_face + 3.0:
        _warn(
            flags, "base_out_of_view",
            f"the base plane lies {truncation - top_face:.1f} mm beyond the imaged tissue: a "
            "mesh of this mask has no facets on it (an empty 'base' boundary); hold the top "
            "face of the mesh instead",
        )  # fmt: skip
    return VentricleFit(
        template,
        endo_res,
        epi_res,
        base_res,
        flags=flags,
        segment_voxels=counts,
        out_of_view=out_of_view,
        insertions=insertions,
        apex_uncertainty=uncertainty if not apex_in_view and apex_level is None else None,
    )
