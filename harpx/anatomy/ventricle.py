r"""A thick-walled, truncated ellipsoidal left ventricle as a structured hexahedral mesh.

Geometry
--------
The wall lies between two confocal-free ellipsoids of revolution about the z axis, both
centred at the origin, apex towards negative z:

.. math::

    \frac{x^2 + y^2}{a(t)^2} + \frac{z^2}{c(t)^2} = 1, \qquad
    a(t) = a_{endo} + t (a_{epi} - a_{endo}),\quad c(t) = c_{endo} + t (c_{epi} - c_{endo}),

with the transmural coordinate :math:`t \in [0, 1]` (0 endocardium, 1 epicardium), cut by
the base plane :math:`z = z_b` (``truncation``). On the surface of layer :math:`t` a point is
:math:`(a \sin\nu \cos\theta,\ a \sin\nu \sin\theta,\ -c \cos\nu)`, with the circumferential
angle :math:`\theta` and the polar angle :math:`\nu` from the apex. The longitudinal mesh
coordinate is the *arc-length fraction* :math:`\sigma \in [0, 1]` of the mid-wall meridian
from the apex (:math:`\sigma = 0`) to the base (:math:`\sigma = 1`), so cells have even
lengths from a flat apex to a steep equator; the other layers' nodes lie on the mid-wall
normals (transmural lines cross the wall at right angles), slid near the base so that the
base row lies on the base plane (:meth:`VentricleGeometry.surface_points`).

Apex
----
The polar parametrisation is singular at the apex, where a structured (θ, σ) grid would
collapse its first ring of cells into wedges. The apical cap :math:`\sigma \le \sigma_{cap}`
is therefore meshed as an O-grid in the disc coordinates :math:`(\xi, \eta) =
(\sigma/\sigma_{cap}) (\cos\theta, \sin\theta)`: a square core of
(``n_circumferential/4``)² cells, rounded towards a circle, surrounded by rings that blend the
square into the circle :math:`\sigma = \sigma_{cap}`, whose nodes are the first row of the
structured (θ, σ) grid. The map from the disc to the surface is smooth through the pole,
so every cell is a proper hexahedron (positive Jacobian at every Gauss point, no hole). The
cap radius is chosen so that the core cells are about 3/4 of the longitudinal cell length.

Fibres
------
Helical fibres lie in the tangent plane of the layer surface through the point,

.. math::

    f = \cos\alpha\, e_c + \sin\alpha\, e_l, \qquad
    \alpha(t) = \alpha_{endo} + t (\alpha_{epi} - \alpha_{endo}),

with :math:`e_c = (-\sin\theta, \cos\theta, 0)` (counter-clockwise seen from the base, i.e.
about +z) and :math:`e_l` the unit meridian tangent pointing from the apex to the base. The
default helix angle turns linearly from +60° at the endocardium to −60° at the epicardium
(Streeter et al. 1969). The mesh carries one fibre per cell, evaluated at the cell's centre
(:meth:`VentricleGeometry.fibers` evaluates the field at any point).

Units: mm, degrees for the public fibre angles.

References
----------
.. [1] Streeter DD, Spotnitz HM, Patel DP, Ross J, Sonnenblick EH. Fiber orientation in the
   canine left ventricle during diastole and systole. Circ Res 24:339--347, 1969.
.. [2] Guccione JM, McCulloch AD, Waldman LK. Passive material properties of intact
   ventricular myocardium determined from a cylindrical model. J Biomech Eng 113:42--55,
   1991.
.. [3] Cerqueira MD et al. Standardized myocardial segmentation and nomenclature for
   tomographic imaging of the heart (AHA 17-segment model). Circulation 105:539--542, 2002.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import skfem
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray
from harpx.anatomy.aha import segments_local
from harpx.mechanics.mesh import (
    MeshSpec,
    curved_hex_mesh,
    facets_where,
    hex_mesh,
    labelled_spec,
)

if TYPE_CHECKING:
    from harpx.mechanics.body import Body

__all__ = ["VentricleGeometry", "cavity_volume", "ventricle"]

# samples of the meridian used to tabulate the arc length of each layer
_ARC_SAMPLES = 4097
# (a, c) weights of the 8 trilinear corners, VTK order, for the orientation check
_CORNERS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
    dtype=np.float64,
)


@dataclass(frozen=True)
class VentricleGeometry:
    """Truncated thick-walled ellipsoid of revolution (left-ventricle model), mm.

    Parameters
    ----------
    inner : tuple of 2 float
        Endocardial semi-axes ``(a_endo, c_endo)``: short (x, y) and long (z) radius, mm.
    outer : tuple of 2 float
        Epicardial semi-axes ``(a_epi, c_epi)``, mm; each larger than its inner value.
    truncation : float
        z of the base plane, mm, with ``-c_endo < truncation < c_endo``.

    Raises
    ------
    ValueError
        If the semi-axes are not positive and nested, or the base plane misses the cavity.

    Examples
    --------
    >>> from harpx.anatomy.ventricle import VentricleGeometry
    >>> g = VentricleGeometry(inner=(20.0, 50.0), outer=(30.0, 60.0), truncation=0.0)
    >>> round(g.wall_volume() / 1000.0, 3)  # 2/3 π (a_epi² c_epi - a_endo² c_endo), mL
    71.209
    """

    inner: tuple[float, float]
    outer: tuple[float, float]
    truncation: float

    def __post_init__(self) -> None:
        a0, c0 = (float(v) for v in self.inner)
        a1, c1 = (float(v) for v in self.outer)
        if not (0 < a0 < a1 and 0 < c0 < c1):
            raise ValueError(
                f"semi-axes inner={self.inner!r}, outer={self.outer!r} must be positive with "
                "inner < outer for both (a, c), in mm"
            )
        if not -c0 < float(self.truncation) < c0:
            raise ValueError(
                f"truncation={self.truncation!r} mm must cut the cavity: -c_endo < z_base < "
                f"c_endo = {c0!r}"
            )
        object.__setattr__(self, "inner", (a0, c0))
        object.__setattr__(self, "outer", (a1, c1))
        object.__setattr__(self, "truncation", float(self.truncation))

    # ------------------------------------------------------------------ layers
    def semi_axes(self, t: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Semi-axes ``a(t), c(t)`` (mm) of the layer at transmural fraction ``t``.

        Parameters
        ----------
        t : array_like
            Transmural fraction (dimensionless): 0 endocardium, 1 epicardium; values
            outside [0, 1] extrapolate linearly.

        Returns
        -------
        a, c : ndarray, shape of ``t``
            Short (x, y) and long (z) semi-axis of the layer, mm.
        """
        t = np.asarray(t, dtype=np.float64)
        a = self.inner[0] + t * (self.outer[0] - self.inner[0])
        c = self.inner[1] + t * (self.outer[1] - self.inner[1])
        return a, c

    def _meridian_table(self, t: float) -> tuple[FloatArray, FloatArray, float]:
        """Polar angle ν in [0, π], arc length from the apex (mm) and the base arc length."""
        a, c = (float(v) for v in self.semi_axes(t))
        nu = np.linspace(0.0, np.pi, _ARC_SAMPLES)
        speed = np.sqrt((a * np.cos(nu)) ** 2 + (c * np.sin(nu)) ** 2)
        arc = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(nu))])
        nu_base = float(np.arccos(np.clip(-self.truncation / c, -1.0, 1.0)))
        return nu, arc, float(np.interp(nu_base, nu, arc))

    def _project(self, sigma: FloatArray, t: float) -> FloatArray:
        """Arc position (mm) on layer ``t`` of the mid-wall normal through arc fraction σ."""
        nu_m, arc_m, length_m = self._meridian_table(0.5)
        a_m, c_m = (float(v) for v in self.semi_axes(0.5))
        num = np.interp(sigma * length_m, arc_m, nu_m)
        r0, z0 = a_m * np.sin(num), -c_m * np.cos(num)
        nr, nz = r0 / a_m**2, z0 / c_m**2
        norm = np.hypot(nr, nz)
        nr, nz = nr / norm, nz / norm
        a, c = (float(v) for v in self.semi_axes(t))
        A = nr**2 / a**2 + nz**2 / c**2
        B = 2.0 * (r0 * nr / a**2 + z0 * nz / c**2)
        C = r0**2 / a**2 + z0**2 / c**2 - 1.0
        lam = -2.0 * C / (B + np.sqrt(np.maximum(B * B - 4.0 * A * C, 0.0)))
        r, z = r0 + lam * nr, z0 + lam * nz
        nu_t, arc_t, _ = self._meridian_table(t)
        return np.interp(np.arctan2(r / a, -z / c), nu_t, arc_t)

    def surface_points(self, theta: ArrayLike, sigma: ArrayLike, t: float) -> FloatArray:
        r"""Points of layer ``t`` at angles ``theta`` (rad) and mid-wall arc fractions ``sigma``.

        The longitudinal coordinate σ is the arc-length fraction of the mid-wall meridian
        (``t = 1/2``) from the apex (0) to the base (1). The point of layer ``t`` lies on the
        normal to the mid-wall through that mid-wall point, so transmural mesh lines cross
        the wall at right angles; near the base it is slid along its meridian by
        :math:`\sigma^4` times the mismatch at σ = 1, which puts the base row exactly on the
        base plane while leaving the rest of the wall (practically) normal.

        Parameters
        ----------
        theta, sigma : array_like
            Circumferential angle (rad) and mid-wall arc fraction in [0, 1], broadcast
            together.
        t : float
            Transmural fraction (0 endocardium, 1 epicardium).

        Returns
        -------
        ndarray, shape (..., 3)
            Points in mm.
        """
        theta, sigma = np.broadcast_arrays(
            np.asarray(theta, dtype=np.float64), np.asarray(sigma, dtype=np.float64)
        )
        nu_t, arc_t, length_t = self._meridian_table(t)
        arc = self._project(sigma, t)
        arc = arc + sigma**4 * (length_t - self._project(np.array(1.0), t))
        nu = np.interp(arc, arc_t, nu_t)
        a, c = (float(v) for v in self.semi_axes(t))
        r = a * np.sin(nu)
        return np.stack([r * np.cos(theta), r * np.sin(theta), -c * np.cos(nu)], axis=-1)

    # ------------------------------------------------------------------ coordinates
    def transmural(self, points: ArrayLike, *, iterations: int = 60) -> FloatArray:
        """Transmural fraction ``t`` of points: the layer whose ellipsoid passes through each.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Points in mm.
        iterations : int, default 60
            Bisection steps (each halves the bracket; 60 reach round-off).

        Returns
        -------
        ndarray, shape (n,)
            ``t`` (dimensionless): 0 on the endocardium, 1 on the epicardium, < 0 inside
            the cavity and > 1 outside the wall (bracketed to [-1, 2]).
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        r2 = p[:, 0] ** 2 + p[:, 1] ** 2
        z2 = p[:, 2] ** 2
        # a(t), c(t) stay positive on the bracket [t_lo, 2]
        t_lo = max(
            -1.0,
            0.99
            * max(
                -self.inner[0] / (self.outer[0] - self.inner[0]),
                -self.inner[1] / (self.outer[1] - self.inner[1]),
            ),
        )
        lo = np.full(len(p), t_lo)
        hi = np.full(len(p), 2.0)
        for _ in range(int(iterations)):  # vectorised bisection over all points
            mid = 0.5 * (lo + hi)
            a, c = self.semi_axes(mid)
            outside = r2 / a**2 + z2 / c**2 > 1.0  # point lies outside layer `mid`
            lo = np.where(outside, mid, lo)
            hi = np.where(outside, hi, mid)
        return 0.5 * (lo + hi)

    def local_basis(self, points: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Circumferential and longitudinal unit vectors and ``t`` at points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Points in mm.

        Returns
        -------
        e_c : ndarray, shape (n, 3)
            ``(-sin θ, cos θ, 0)``, counter-clockwise about +z.
        e_l : ndarray, shape (n, 3)
            Unit meridian tangent of the layer through the point, from apex to base.
        t : ndarray, shape (n,)
            Transmural fraction.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        t = self.transmural(p)
        a, c = self.semi_axes(t)
        theta = np.arctan2(p[:, 1], p[:, 0])
        r = np.hypot(p[:, 0], p[:, 1])
        e_r = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], axis=1)
        e_c = np.stack([-np.sin(theta), np.cos(theta), np.zeros_like(theta)], axis=1)
        # tangent of the ellipse (r/a)² + (z/c)² = 1 in the (r, z) half-plane: (-z/c², r/a²)
        tr = -p[:, 2] / c**2
        tz = r / a**2
        norm = np.hypot(tr, tz)
        e_l = (tr / norm)[:, None] * e_r + (tz / norm)[:, None] * np.array([0.0, 0.0, 1.0])
        return e_c, e_l, t

    def helix_angle(self, t: ArrayLike, fiber_endo: float, fiber_epi: float) -> FloatArray:
        """Helix angle (degrees) at transmural fraction ``t``, linear from endo to epi.

        Parameters
        ----------
        t : array_like
            Transmural fraction (dimensionless), clipped to [0, 1].
        fiber_endo, fiber_epi : float
            Helix angles at the endocardium and epicardium, degrees.

        Returns
        -------
        ndarray, shape of ``t``
            Helix angle, degrees.
        """
        t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
        return fiber_endo + t * (fiber_epi - fiber_endo)

    def fibers(
        self, points: ArrayLike, *, fiber_endo: float = 60.0, fiber_epi: float = -60.0
    ) -> FloatArray:
        """Unit helical fibre directions at points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Points in mm (in or near the wall).
        fiber_endo, fiber_epi : float, default 60, -60
            Helix angles at the endocardium and epicardium in degrees, measured from the
            circumferential direction towards the base.

        Returns
        -------
        ndarray, shape (n, 3)
            Unit fibres ``cos α e_c + sin α e_l`` (α clipped to the wall's range).
        """
        e_c, e_l, t = self.local_basis(points)
        alpha = np.deg2rad(self.helix_angle(t, fiber_endo, fiber_epi))
        f = np.cos(alpha)[:, None] * e_c + np.sin(alpha)[:, None] * e_l
        return f / np.linalg.norm(f, axis=1, keepdims=True)

    def inside(self, points: ArrayLike) -> FloatArray:
        """Indicator of points inside the wall.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Points in mm.

        Returns
        -------
        ndarray of float, shape (n,)
            1.0 where ``0 <= t <= 1`` (:meth:`transmural`) and ``z <= truncation``,
            else 0.0.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        t = self.transmural(p)
        return ((t >= 0.0) & (t <= 1.0) & (p[:, 2] <= self.truncation)).astype(np.float64)

    # ------------------------------------------------------------------ volumes
    @staticmethod
    def _truncated_volume(a: float, c: float, zb: float) -> float:
        # π a² ∫_{-c}^{zb} (1 - z²/c²) dz
        return float(np.pi * a**2 * ((zb + c) - (zb**3 + c**3) / (3.0 * c**2)))

    def cavity_volume(self) -> float:
        """Analytic cavity volume below the base plane, mm³.

        Returns
        -------
        float
            Volume inside the endocardial ellipsoid below ``z = truncation``, mm³.
        """
        return self._truncated_volume(*self.inner, self.truncation)

    def wall_volume(self) -> float:
        """Analytic wall volume below the base plane, mm³.

        Returns
        -------
        float
            Volume between the endo- and epicardial ellipsoids below ``z = truncation``,
            mm³.
        """
        return self._truncated_volume(*self.outer, self.truncation) - self.cavity_volume()

    def mesh(self, **options: Any) -> MeshSpec:
        """This geometry meshed by :func:`ventricle`.

        Parameters
        ----------
        **options
            Keywords of :func:`ventricle` other than the geometry (``n_circumferential``,
            ``n_longitudinal``, ``n_transmural``, ``fiber_endo``, ``fiber_epi``,
            ``segments``, ``curved``).

        Returns
        -------
        MeshSpec
            The mesh of :func:`ventricle` (regions, fibres, boundaries ``"endo"``,
            ``"epi"`` and ``"base"``) with this geometry's semi-axes and base plane.
        """
        return ventricle(inner=self.inner, outer=self.outer, truncation=self.truncation, **options)


# ------------------------------------------------------------------------------ mesh


def _disc_ogrid(
    n_circumferential: int, n_rings: int, core: float = 0.5, rounding: float = 0.5
) -> tuple[FloatArray, IntArray, IntArray]:
    """O-grid of the unit disc: points, counter-clockwise quads and the boundary loop.

    The boundary loop has ``n_circumferential`` nodes at angles ``-π/4 + 2πk/n``.
    """
    m = n_circumferential // 4
    s = np.linspace(-core, core, m + 1)
    SX, SY = np.meshgrid(s, s, indexing="xy")
    sq = np.stack([SX.ravel(), SY.ravel()], axis=1)
    # round the square core towards a circle of the same half-width
    linf = np.abs(sq).max(axis=1)
    l2 = np.linalg.norm(sq, axis=1)
    factor = np.where(l2 > 0, (1.0 - rounding) + rounding * linf / np.where(l2 > 0, l2, 1.0), 1.0)
    core_pts = sq * factor[:, None]
    cidx = np.arange((m + 1) ** 2).reshape(m + 1, m + 1)
    quads = [
        np.column_stack(
            [
                cidx[:-1, :-1].ravel(),
                cidx[:-1, 1:].ravel(),
                cidx[1:, 1:].ravel(),
                cidx[1:, :-1].ravel(),
            ]
        )
    ]
    # counter-clockwise loop over the core boundary starting at the corner (+, -)
    loop = np.concatenate(
        [cidx[:, m][:-1], cidx[m, ::-1][:-1], cidx[::-1, 0][:-1], cidx[0, :][:-1]]
    )
    nc = 4 * m
    angle = -0.25 * np.pi + 2.0 * np.pi * np.arange(nc) / nc
    circle = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    pts = [core_pts]
    rings = [loop]
    nxt = len(core_pts)
    for k in range(1, n_rings + 1):  # a few rings
        f = k / n_rings
        pts.append((1.0 - f) * core_pts[loop] + f * circle)
        rings.append(nxt + np.arange(nc))
        nxt += nc
    j = np.arange(nc)
    for k in range(1, len(rings)):
        inner, outer = rings[k - 1], rings[k]
        quads.append(
            np.column_stack([inner[j], outer[j], outer[(j + 1) % nc], inner[(j + 1) % nc]])
        )
    return np.concatenate(pts), np.concatenate(quads), rings[-1]


def _orient(points: FloatArray, cells: IntArray) -> IntArray:
    """Reorder hexahedra (VTK order) whose trilinear Jacobian at the centre is negative."""
    x = points[cells]  # (n, 8, 3)
    # derivatives of the trilinear map at the cell centre
    sgn = 2.0 * _CORNERS - 1.0  # ±1 per corner and direction
    d = np.einsum("nai,aj->nij", x, sgn) / 4.0  # columns d/dξ_j
    det = np.linalg.det(d)
    flip = det < 0
    out = cells.copy()
    out[flip] = cells[flip][:, [0, 3, 2, 1, 4, 7, 6, 5]]
    return out


def _aha_segments(centres: FloatArray, geometry: VentricleGeometry) -> dict[str, IntArray]:
    """The 17 AHA segments of cells by their centres (anterior wall at +x), as named sets."""
    labels = segments_local(centres, geometry, 0.0)
    return {f"aha_{k:02d}": np.nonzero(labels == k)[0] for k in range(1, 18)}


def ventricle(
    *,
    inner: tuple[float, float] = (25.0, 70.0),
    outer: tuple[float, float] = (35.0, 78.0),
    truncation: float = 10.0,
    n_circumferential: int = 48,
    n_longitudinal: int = 27,
    n_transmural: int = 4,
    fiber_endo: float = 60.0,
    fiber_epi: float = -60.0,
    segments: bool = True,
    curved: bool = False,
) -> MeshSpec:
    """Structured hexahedral mesh of a truncated ellipsoidal left ventricle with fibres.

    Parameters
    ----------
    inner : tuple of 2 float, default (25, 70)
        Endocardial semi-axes ``(a_endo, c_endo)`` in mm (short radius, long radius).
    outer : tuple of 2 float, default (35, 78)
        Epicardial semi-axes ``(a_epi, c_epi)`` in mm.
    truncation : float, default 10
        z of the base plane in mm (the apex is at ``z = -c``).
    n_circumferential : int, default 48
        Cells around the circumference; a multiple of 4, at least 8 (the apical O-grid
        core has ``n_circumferential/4`` cells per side). The apex (on the axis) is a mesh
        vertex only for a multiple of 8 (an even number of core cells per side); otherwise
        it is the centre of the middle core cell (e.g. 12 or 20) -- evaluate fields there
        with :meth:`Body.displacement_at` instead of reading a node.
    n_longitudinal : int, default 27
        Cells along the meridian between the apical cap and the base.
    n_transmural : int, default 4
        Cells across the wall.
    fiber_endo, fiber_epi : float, default 60, -60
        Helix angles in degrees at the endocardium and epicardium (linear in between).
    segments : bool, default True
        Also name the AHA segments ``"aha_01"`` ... ``"aha_17"``: each cell in the segment
        of its centre (:func:`harpx.anatomy.aha.segments_local` with the anterior wall at
        +x, the segments :func:`harpx.cardiac.strain.aha_segments` reads: the cavity's
        length in basal, mid and apical thirds, six 60° sectors in the basal and mid rings
        and four 90° sectors in the apical one, numbered counter-clockwise seen from the
        apex with segments 1, 7 and 13 centred on +x; the apex cap below the cavity). With
        ``n_circumferential`` a multiple of 24 every sector border is a cell border.
        :meth:`~harpx.anatomy.ventricle_fit.VentricleTemplate.mesh` turns the mesh to the
        template's ``anterior``.
    curved : bool, default False
        Return curved hexahedra (a :class:`skfem.MeshHex2`, 27-node triquadratic
        geometry; :func:`~harpx.mechanics.mesh.curved_hex_mesh`) for an isoparametric
        hex20 :class:`~harpx.mechanics.body.Body` (the default element on it). Each edge,
        face and cell node is the image of the parametric midpoint of its vertices: the
        mean transmural fraction t, and the mean (θ, σ) on the (θ, σ) grid or the mean
        position in the apical O-grid disc, mapped through
        :meth:`VentricleGeometry.surface_points`. So the nodes of the endocardial and
        epicardial faces lie on the ellipsoids and those of the base on its plane, and
        the cells do not cut the curved walls with flat faces. The vertices are those
        of the straight mesh. Point location and tracking do not take curved cells (they
        raise ``NotImplementedError``).

    Returns
    -------
    MeshSpec
        Region ``"myocardium"`` (all cells) and the segments; per-cell unit fibres;
        boundaries ``"endo"``, ``"epi"`` and ``"base"`` (the plane ``z = truncation``).
        With the defaults: 4 × (48·27 + 144 + 48·4) = 6528 cells.

    Raises
    ------
    ValueError
        If a count is out of range or the geometry is inconsistent.

    Notes
    -----
    See the module docstring for the parametrisation, the apical O-grid cap (no degenerate
    cells and no hole) and the fibre field. The apical cap spans the arc fraction
    ``σ_cap = κ m / (n_longitudinal + κ m)`` (``m = n_circumferential/4``, κ = 3/4) so that
    its core cells are about 3/4 of a longitudinal cell; its rings are as long as the
    longitudinal cells.

    Examples
    --------
    >>> from harpx.anatomy.ventricle import ventricle
    >>> spec = ventricle(n_circumferential=8, n_longitudinal=3, n_transmural=1)
    >>> spec.mesh.nelements, sorted(spec.boundaries)
    (36, ['base', 'endo', 'epi'])
    """
    nc, nl, nt = int(n_circumferential), int(n_longitudinal), int(n_transmural)
    if nc < 8 or nc % 4:
        raise ValueError(f"n_circumferential={n_circumferential!r} must be a multiple of 4, >= 8")
    if nl < 1 or nt < 1:
        raise ValueError(
            f"n_longitudinal={n_longitudinal!r} and n_transmural={n_transmural!r} must be >= 1"
        )
    (a_in, c_in), (a_out, c_out) = inner, outer
    geom = VentricleGeometry(inner=(a_in, c_in), outer=(a_out, c_out), truncation=truncation)
    m = nc // 4
    kappa = 0.75
    sigma_cap = kappa * m / (nl + kappa * m)
    d_sigma = (1.0 - sigma_cap) / nl
    core = 0.5
    n_rings = max(1, int(round((1.0 - core) * sigma_cap / d_sigma)))
    disc, cap_quads, circle = _disc_ogrid(nc, n_rings, core=core)
    # per-layer node set: the cap nodes except its boundary circle, then the (σ, θ) grid
    cap_only = np.setdiff1d(np.arange(len(disc)), circle)
    n_cap = len(cap_only)
    theta_grid = -0.25 * np.pi + 2.0 * np.pi * np.arange(nc) / nc
    sigma_grid = sigma_cap + d_sigma * np.arange(nl + 1)
    rho = np.linalg.norm(disc[cap_only], axis=1)
    cap_theta = np.arctan2(disc[cap_only, 1], disc[cap_only, 0])
    TH, SG = np.meshgrid(theta_grid, sigma_grid, indexing="xy")  # (nl+1, nc)
    theta_nodes = np.concatenate([cap_theta, TH.ravel()])
    sigma_nodes = np.concatenate([sigma_cap * rho, SG.ravel()])
    per_layer = len(theta_nodes)
    layers_t = np.arange(nt + 1) / nt
    points = np.concatenate(
        [geom.surface_points(theta_nodes, sigma_nodes, float(t)) for t in layers_t]  # nt+1 layers
    )
    # local ids within a layer: disc node -> layer id (the circle is row 0 of the grid)
    disc_to_layer = np.empty(len(disc), dtype=np.int64)
    disc_to_layer[cap_only] = np.arange(n_cap)
    disc_to_layer[circle] = n_cap + np.arange(nc)
    grid = n_cap + np.arange((nl + 1) * nc).reshape(nl + 1, nc)
    j = np.arange(nc)
    I_, J_ = np.meshgrid(np.arange(nl), j, indexing="ij")
    JN = (J_ + 1) % nc
    grid_quads = np.column_stack(
        [
            grid[I_, J_].ravel(),
            grid[I_, JN].ravel(),
            grid[I_ + 1, JN].ravel(),
            grid[I_ + 1, J_].ravel(),
        ]
    )
    quads = np.concatenate([disc_to_layer[cap_quads], grid_quads])
    offsets = per_layer * np.arange(nt)[:, None, None]
    cells = np.concatenate([quads[None] + offsets, quads[None] + offsets + per_layer], axis=2)
    cells = _orient(points, cells.reshape(-1, 8))

    layer_of_node = np.repeat(np.arange(nt + 1), per_layer)
    local = np.tile(np.arange(per_layer), nt + 1)
    on_base = np.isin(local, grid[nl])
    mesh = hex_mesh(points, cells)
    boundaries = {
        "endo": facets_where(mesh, lambda p: layer_of_node == 0),
        "epi": facets_where(mesh, lambda p: layer_of_node == nt),
        "base": facets_where(mesh, lambda p: on_base),
    }

    centres = points[cells].mean(axis=1)
    fibers = geom.fibers(centres, fiber_endo=fiber_endo, fiber_epi=fiber_epi)
    regions: dict[str, IntArray] = {"myocardium": np.arange(len(cells), dtype=np.int64)}
    if segments:
        regions |= _aha_segments(centres, geom)
    spec = labelled_spec(mesh, regions, boundaries, fibers)
    if not curved:
        return spec
    # parametric coordinates of every layer node: (θ, σ) and, for the cap and its
    # boundary circle, the position in the O-grid disc
    disc_xy = np.full((per_layer, 2), np.nan)
    disc_xy[:n_cap] = disc[cap_only]
    disc_xy[n_cap : n_cap + nc] = disc[circle]

    def centre(vertices: IntArray) -> FloatArray:
        local, layer = vertices % per_layer, vertices // per_layer
        t = layers_t[layer].mean(axis=1)
        on_grid = np.all(local >= n_cap, axis=1)  # else in the apical cap
        th0 = theta_nodes[local[:, :1]]
        th = (th0 + np.mod(theta_nodes[local] - th0 + np.pi, 2.0 * np.pi) - np.pi).mean(axis=1)
        sg = sigma_nodes[local].mean(axis=1)
        d = disc_xy[local[~on_grid]].mean(axis=1)
        th[~on_grid] = np.arctan2(d[:, 1], d[:, 0])
        sg[~on_grid] = sigma_cap * np.hypot(d[:, 0], d[:, 1])
        out = np.empty((len(t), 3))
        key = np.round(t * 2 * nt).astype(np.int64)  # t is a multiple of 1/(2 nt)
        for k in np.unique(key):
            sel = key == k
            out[sel] = geom.surface_points(th[sel], sg[sel], float(t[sel][0]))
        return out

    return dataclasses.replace(spec, mesh=curved_hex_mesh(spec.mesh, centre))


def cavity_volume(body: Body, u: ArrayLike | None = None, *, base: float | None = None) -> float:
    """Volume enclosed by the (deformed) endocardium and the base plane, mm³.

    Parameters
    ----------
    body : Body
        A body built on a :func:`ventricle` mesh (boundary ``"endo"``).
    u : array_like, shape (ndof,), optional
        Displacement in mm; the reference configuration if omitted.
    base : float, optional
        z of the closing plane in mm; default the mean reference z of the ``"base"``
        boundary nodes (exact when the base is held in z).

    Returns
    -------
    float
        ``V = -∫_endo (z - z_b) n_z da`` (divergence theorem with the field
        ``(0, 0, z - z_b)``, which has no flux through the base plane; ``n`` is the
        body's outward normal, pointing into the cavity), evaluated on the current
        surface with Nanson's formula ``n da = cof F N dA``.
    """
    from harpx.mechanics.kinematics import cofactor

    facets = body.facets("endo")
    mesh = body.mesh
    element = body.scalar_element
    fb = skfem.FacetBasis(mesh, element, facets=facets.astype(np.int32), intorder=4)
    nb = len(fb.basis)
    if u is None:
        u = np.zeros(body.ndof)
    u = np.asarray(u, dtype=np.float64)
    ue = u[3 * fb.element_dofs.T[:, :, None] + np.arange(3)]  # (nf, nb, 3)
    phi = np.stack([np.asarray(fb.basis[a][0]) for a in range(nb)], axis=-1)  # (nf, nq, nb)
    grad = np.stack([fb.basis[a][0].grad for a in range(nb)]).transpose(2, 3, 0, 1)
    F = np.einsum("fai,fqaJ->fqiJ", ue, grad) + np.eye(3)
    nda = np.einsum("fqiJ,fqJ->fqi", cofactor(F), np.asarray(fb.normals).transpose(1, 2, 0))
    x = np.asarray(fb.global_coordinates()).transpose(1, 2, 0) + np.einsum("fqa,fai->fqi", phi, ue)
    if base is None:
        base_facets = body.facets("base")
        base = float(mesh.p[2, np.unique(mesh.facets[:, base_facets])].mean())
    return float(-np.sum((x[..., 2] - base) * nda[..., 2] * np.asarray(fb.dx)))
