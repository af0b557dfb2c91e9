r"""A tongue-like hexahedral body with five labelled intrinsic/extrinsic muscles and fibres.

Geometry
--------
A structured grid of reference coordinates :math:`(\xi, \eta, \zeta) \in [0, 1] \times
[-1, 1] \times [0, 1]` (posterior → anterior, right → left, inferior → superior) is mapped
onto a rounded, tapering block with a flat floor:

.. math::

    x &= L\,\big[\xi - \xi^2 (0.06\,\eta^2 + 0.03\,\zeta^2)\big], \\
    y &= \tfrac{W}{2}\,\eta\,(1 - 0.35\,\xi^2)(1 - 0.15\,\zeta^2), \\
    z &= H\,\zeta\,(1 - 0.5\,\xi^2)(1 - 0.15\,\eta^2),

so the body is ``length`` L long (x, the root at x = 0, the tip at x ≈ L), ``width`` W wide
at the root (y, centred on the mid-sagittal plane y = 0) and ``height`` H high at the root
(z, the floor at z = 0). The dorsum (upper surface) falls towards the tip and the sides,
the body narrows towards the tip and the dorsum, and the tip is rounded in plan view. The
Jacobian determinant of the map stays above 8 % of its value at the root everywhere, so the
map is one-to-one and no cell is inverted for any divisions (checked in the tests).

Muscles (an anatomical simplification)
--------------------------------------
Fibre directionality and muscle definitions follow the tongue literature the paper relies on
(its reference [7]; the classic morphology is Takemoto 2001). The five muscles are laid out
on a 10 × 7 × 4 *atlas* of the reference box (ξ, η, ζ bins); a cell belongs to the muscle of
the atlas bin that contains its centre, so any refinement of the default divisions (e.g.
``(20, 14, 8)``) carries exactly the same muscle map:

=====  =========================  ======================================  ==================
name   muscle                     atlas bins (i: ξ, j: η, k: ζ)           fibre direction
=====  =========================  ======================================  ==================
SL     superior longitudinal      top layer k = 3 (under the dorsum)      antero-posterior
                                                                          (∂x/∂ξ)
GG     genioglossus               mid-sagittal columns j = 2..4,          fan from the
                                  k = 0..2, posterior body i ≤ 6          mandible insertion
IL     inferior longitudinal      lateral columns j ∈ {0,1,5,6}, k = 0,   antero-posterior
                                  i ≤ 6                                   (∂x/∂ξ)
V      verticalis                 lateral columns, k = 1..2, i ≤ 6        superior-inferior
                                                                          (∂x/∂ζ)
T      transverse                 anterior body i ≥ 7, k = 0..2, all j    left-right (∂x/∂η)
=====  =========================  ======================================  ==================

Simplifications: the interdigitated transverse and vertical laminae of the real tongue core
are represented as two separate blocks — the verticalis in the lateral core of the body
beside the genioglossus, the transverse across the whole width of the anterior third —
rather than alternating sheets (thin alternating T/V layers have opposite strains that no
tagged acquisition resolves);
the genioglossus is one fan (its anterior, middle and posterior bundles are not separated);
extrinsic muscles other than the genioglossus (styloglossus, hyoglossus, palatoglossus) are
not modelled; the genioglossus fan radiates from a single insertion point on the mandible
(mental spine) at the front of the floor, ``M = map(0.8, 0, 0)``.

Boundaries
----------
``"mandible"``: floor facets around the genioglossus insertion (0.6 ≤ ξ ≤ 0.9,
abs(η) ≤ 3/7); ``"base"`` (alias ``"hyoid"``): the posterior floor strip under the
genioglossus (ξ ≤ 0.6, abs(η) ≤ 3/7), attached to the hyoid; ``"floor"``: the rest of the floor
(free, so the inferior longitudinal muscles can shorten); ``"dorsum"``:
upper surface (ζ = 1, free); ``"tip"`` (ξ = 1), ``"posterior"`` (ξ = 0) and ``"lateral"``
(η = ±1), all free. Units: mm.

References
----------
.. [1] Takemoto H. Morphological analyses of the human tongue musculature for
   three-dimensional modeling. J Speech Lang Hear Res 44:95--107, 2001.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from harpx._typing import FloatArray
from harpx.mechanics.mesh import MeshSpec, facets_where, hex_mesh, labelled_spec

__all__ = [
    "ATLAS_DIVISIONS",
    "MUSCLES",
    "muscle_atlas",
    "tongue",
    "tongue_map",
    "tongue_inside",
    "tongue_reference",
]

#: region name -> muscle name
MUSCLES: dict[str, str] = {
    "GG": "genioglossus",
    "IL": "inferior longitudinal",
    "SL": "superior longitudinal",
    "T": "transverse",
    "V": "verticalis",
}

#: bins of the muscle atlas along (ξ, η, ζ)
ATLAS_DIVISIONS: tuple[int, int, int] = (10, 7, 4)

# shape coefficients of the map (module docstring): tip rounding in plan view (y) and
# elevation (z), narrowing towards the tip and the dorsum, lowering towards the tip and sides.
# They keep det(d map) >= 0.085 det at the root everywhere in the reference box.
_RY, _RZ, _TW, _TWZ, _TH, _THY = 0.06, 0.03, 0.35, 0.15, 0.5, 0.15

#: reference coordinates (ξ, η, ζ) of the genioglossus insertion on the mandible
_MANDIBLE_POINT = (0.8, 0.0, 0.0)


def tongue_map(ref: NDArray[np.float64], length: float, width: float, height: float) -> FloatArray:
    """Map reference coordinates (ξ, η, ζ) to physical positions (x, y, z) in mm.

    Parameters
    ----------
    ref : ndarray, shape (n, 3)
        Reference coordinates: ξ in [0, 1] (posterior → anterior), η in [-1, 1]
        (right → left), ζ in [0, 1] (inferior → superior); dimensionless.
    length, width, height : float
        Body length (x), root width (y) and root height (z), mm.

    Returns
    -------
    ndarray, shape (n, 3)
        Positions in mm (see the module docstring for the formula).

    Examples
    --------
    >>> from harpx.anatomy.tongue_mesh import tongue_map
    >>> tongue_map(np.array([[0.0, 1.0, 1.0]]), 70.0, 50.0, 40.0).round(3).tolist()
    [[0.0, 21.25, 34.0]]
    """
    ref = np.asarray(ref, dtype=np.float64)
    xi, eta, zeta = ref[:, 0], ref[:, 1], ref[:, 2]
    x = length * (xi - xi**2 * (_RY * eta**2 + _RZ * zeta**2))
    y = 0.5 * width * eta * (1.0 - _TW * xi**2) * (1.0 - _TWZ * zeta**2)
    z = height * zeta * (1.0 - _TH * xi**2) * (1.0 - _THY * eta**2)
    return np.column_stack([x, y, z])


def _map_jacobian(ref: FloatArray, length: float, width: float, height: float) -> FloatArray:
    """Columns ∂x/∂ξ, ∂x/∂η, ∂x/∂ζ of the map at ``ref`` (n, 3); shape (n, 3, 3), mm."""
    xi, eta, zeta = ref[:, 0], ref[:, 1], ref[:, 2]
    a = _RY * eta**2 + _RZ * zeta**2
    wx = 1.0 - _TW * xi**2
    wz = 1.0 - _TWZ * zeta**2
    hx = 1.0 - _TH * xi**2
    he = 1.0 - _THY * eta**2
    d_xi = np.column_stack(
        [
            length * (1.0 - 2.0 * xi * a),
            0.5 * width * eta * (-2.0 * _TW * xi) * wz,
            height * zeta * (-2.0 * _TH * xi) * he,
        ]
    )
    d_eta = np.column_stack(
        [
            length * (-(xi**2) * 2.0 * _RY * eta),
            0.5 * width * wx * wz,
            height * zeta * hx * (-2.0 * _THY * eta),
        ]
    )
    d_zeta = np.column_stack(
        [
            length * (-(xi**2) * 2.0 * _RZ * zeta),
            0.5 * width * eta * wx * (-2.0 * _TWZ * zeta),
            height * hx * he,
        ]
    )
    return np.stack([d_xi, d_eta, d_zeta], axis=-1)


def tongue_reference(
    points: NDArray[np.float64],
    length: float,
    width: float,
    height: float,
    *,
    iterations: int = 12,
) -> FloatArray:
    """Invert :func:`tongue_map`: reference coordinates (ξ, η, ζ) of physical points.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Physical positions (x, y, z) in mm.
    length, width, height : float
        Body sizes in mm, as given to :func:`tongue`.
    iterations : int, default 12
        Newton iterations at most (vectorised over the points), after a few fixed-point
        sweeps.

    Returns
    -------
    ndarray, shape (n, 3)
        (ξ, η, ζ); a point is inside the smooth tongue iff ξ, ζ in [0, 1] and η in
        [-1, 1]. Points far outside may not converge and then lie outside those ranges.

    Examples
    --------
    >>> from harpx.anatomy.tongue_mesh import tongue_map, tongue_reference
    >>> ref = np.array([[0.3, -0.5, 0.7], [0.95, 0.9, 0.1]])
    >>> bool(np.allclose(tongue_reference(tongue_map(ref, 70, 50, 40), 70, 50, 40), ref))
    True
    """
    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    L, hw, H = float(length), 0.5 * float(width), float(height)
    px, py, pz = x[:, 0] / L, x[:, 1] / hw, x[:, 2] / H
    xi, eta, zeta = px.copy(), np.zeros_like(px), np.zeros_like(px)
    for _ in range(6):  # a few sweeps of the (weakly coupled) fixed point as a start
        eta = np.clip(py / ((1 - _TW * xi**2) * (1 - _TWZ * zeta**2)), -2.0, 2.0)
        zeta = np.clip(pz / ((1 - _TH * xi**2) * (1 - _THY * eta**2)), -1.0, 2.0)
        xi = np.clip(px + xi**2 * (_RY * eta**2 + _RZ * zeta**2), -1.0, 1.3)
    for _ in range(int(iterations)):  # Newton with the analytic Jacobian, Cramer's rule
        a = _RY * eta**2 + _RZ * zeta**2
        wx, wz = 1.0 - _TW * xi**2, 1.0 - _TWZ * zeta**2
        hx, he = 1.0 - _TH * xi**2, 1.0 - _THY * eta**2
        r0, r1, r2 = xi - xi**2 * a - px, eta * wx * wz - py, zeta * hx * he - pz
        # Jacobian d(r0, r1, r2)/d(xi, eta, zeta) of the normalised map
        j00, j01, j02 = 1.0 - 2.0 * xi * a, -2.0 * _RY * xi**2 * eta, -2.0 * _RZ * xi**2 * zeta
        j10, j11, j12 = -2.0 * _TW * xi * eta * wz, wx * wz, -2.0 * _TWZ * zeta * eta * wx
        j20, j21, j22 = -2.0 * _TH * xi * zeta * he, -2.0 * _THY * eta * zeta * hx, hx * he
        c00, c01, c02 = j11 * j22 - j12 * j21, j12 * j20 - j10 * j22, j10 * j21 - j11 * j20
        det = j00 * c00 + j01 * c01 + j02 * c02
        det = np.where(np.abs(det) > 1e-12, det, np.inf)
        d0 = (c00 * r0 + (j02 * j21 - j01 * j22) * r1 + (j01 * j12 - j02 * j11) * r2) / det
        d1 = (c01 * r0 + (j00 * j22 - j02 * j20) * r1 + (j02 * j10 - j00 * j12) * r2) / det
        d2 = (c02 * r0 + (j01 * j20 - j00 * j21) * r1 + (j00 * j11 - j01 * j10) * r2) / det
        xi = np.clip(xi - d0, -1.0, 2.0)
        eta = np.clip(eta - d1, -2.0, 2.0)
        zeta = np.clip(zeta - d2, -1.0, 2.0)
        if (
            max(
                np.abs(d0).max(initial=0.0),
                np.abs(d1).max(initial=0.0),
                np.abs(d2).max(initial=0.0),
            )
            < 1e-13
        ):
            break
    return np.column_stack([xi, eta, zeta])


def tongue_inside(
    points: NDArray[np.float64], length: float, width: float, height: float
) -> NDArray[np.bool_]:
    """Whether physical points lie inside the smooth tongue of :func:`tongue_map`.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Positions (x, y, z) in mm.
    length, width, height : float
        Body sizes in mm.

    Returns
    -------
    ndarray of bool, shape (n,)
        True inside the body (boundary included): the point's reference coordinates
        (:func:`tongue_reference`) lie in [0, 1] × [-1, 1] × [0, 1] and map back onto it
        to within ``1e-6 * length``.

    Examples
    --------
    >>> from harpx.anatomy.tongue_mesh import tongue_inside
    >>> tongue_inside(np.array([[30.0, 0.0, 10.0], [30.0, 0.0, -1.0]]), 70, 50, 40).tolist()
    [True, False]
    """
    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tol = 1e-9
    out = np.zeros(x.shape[0], dtype=bool)
    # the body lies in its bounding box [0, L] x [-W/2, W/2] x [0, H]: only those need Newton
    near = np.nonzero(
        (x[:, 0] >= -tol * length)
        & (x[:, 0] <= length * (1 + tol))
        & (np.abs(x[:, 1]) <= 0.5 * width * (1 + tol))
        & (x[:, 2] >= -tol * height)
        & (x[:, 2] <= height * (1 + tol))
    )[0]
    ref = tongue_reference(x[near], length, width, height)
    in_box = (
        (ref[:, 0] >= -tol)
        & (ref[:, 0] <= 1 + tol)
        & (np.abs(ref[:, 1]) <= 1 + tol)
        & (ref[:, 2] >= -tol)
        & (ref[:, 2] <= 1 + tol)
    )
    residual = np.linalg.norm(tongue_map(ref, length, width, height) - x[near], axis=1)
    out[near] = in_box & (residual < 1e-6 * length)
    return out


def muscle_atlas(ref: NDArray[np.float64]) -> NDArray[np.str_]:
    """Muscle label of reference points (ξ, η, ζ) from the 10 × 7 × 4 atlas.

    Parameters
    ----------
    ref : ndarray, shape (n, 3)
        Reference coordinates (dimensionless), usually cell centres.

    Returns
    -------
    ndarray of str, shape (n,)
        One of ``"GG"``, ``"IL"``, ``"SL"``, ``"T"``, ``"V"`` per point (see the module
        docstring for the layout).

    Examples
    --------
    >>> from harpx.anatomy.tongue_mesh import muscle_atlas
    >>> muscle_atlas(np.array([[0.3, 0.0, 0.2], [0.3, 0.0, 0.95], [0.95, 0.0, 0.2]])).tolist()
    ['GG', 'SL', 'T']
    """
    ref = np.asarray(ref, dtype=np.float64)
    ni, nj, nk = ATLAS_DIVISIONS
    i = np.clip(np.floor(ref[:, 0] * ni), 0, ni - 1).astype(int)
    j = np.clip(np.floor(0.5 * (ref[:, 1] + 1.0) * nj), 0, nj - 1).astype(int)
    k = np.clip(np.floor(ref[:, 2] * nk), 0, nk - 1).astype(int)
    mid = (j >= 2) & (j <= 4)
    anterior = i >= 7
    label = np.full(ref.shape[0], "T", dtype="<U2")  # anterior body: transverse
    label[~anterior & mid] = "GG"
    label[~anterior & ~mid & (k == 0)] = "IL"
    label[~anterior & ~mid & (k >= 1)] = "V"
    label[k == 3] = "SL"
    return label


def _fibers(
    label: NDArray[np.str_],
    centres: FloatArray,
    ref_centres: FloatArray,
    length: float,
    width: float,
    height: float,
) -> FloatArray:
    jac = _map_jacobian(ref_centres, length, width, height)
    fibers = jac[:, :, 0].copy()  # longitudinal (SL, IL): along ξ
    t = label == "T"
    fibers[t] = jac[t, :, 1]  # transverse: along η
    v = label == "V"
    fibers[v] = jac[v, :, 2]  # vertical: along ζ
    g = label == "GG"
    insertion = tongue_map(np.array([_MANDIBLE_POINT]), length, width, height)[0]
    fibers[g] = centres[g] - insertion  # fan from the mandible insertion
    return fibers / np.linalg.norm(fibers, axis=1, keepdims=True)


def tongue(
    *,
    length: float = 70.0,
    width: float = 50.0,
    height: float = 40.0,
    divisions: tuple[int, int, int] = (10, 7, 4),
) -> MeshSpec:
    """A tongue-like body with five muscle regions, per-cell fibres and named boundaries.

    Parameters
    ----------
    length : float, default 70
        Antero-posterior length (x, root at x = 0, tip towards +x), mm.
    width : float, default 50
        Left-right width at the root (y, centred on y = 0), mm.
    height : float, default 40
        Height of the root (z, floor at z = 0), mm.
    divisions : tuple of 3 int, default (10, 7, 4)
        Cells along (ξ, η, ζ): antero-posterior, left-right, inferior-superior. The default
        gives the paper's 280 cells; ``(20, 14, 8)`` refines it 2× with the same muscles.

    Returns
    -------
    MeshSpec
        Regions ``"GG"``, ``"IL"``, ``"SL"``, ``"T"``, ``"V"`` (cell ids; together they
        cover every cell exactly once), unit ``fibers`` (ncell, 3) and boundaries
        ``"mandible"``, ``"base"`` (= ``"hyoid"``), ``"floor"``, ``"dorsum"``, ``"tip"``,
        ``"posterior"``, ``"lateral"``. Anatomy and its simplifications: module docstring.

    Raises
    ------
    ValueError
        If a size is not positive or ``divisions`` are not three integers >= 1.

    Examples
    --------
    >>> from harpx.anatomy.tongue_mesh import tongue
    >>> spec = tongue()
    >>> spec.mesh.nelements, {k: len(v) for k, v in spec.regions.items()}
    (280, {'GG': 63, 'IL': 28, 'SL': 70, 'T': 63, 'V': 56})
    """
    for name, value in (("length", length), ("width", width), ("height", height)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name}={value!r} must be a positive length in mm")
    try:
        nx, ny, nz = (int(d) for d in divisions)
    except (TypeError, ValueError):
        raise ValueError(f"divisions={divisions!r} must be three integers >= 1") from None
    if min(nx, ny, nz) < 1:
        raise ValueError(f"divisions={divisions!r} must be three integers >= 1")
    xi = np.linspace(0.0, 1.0, nx + 1)
    eta = np.linspace(-1.0, 1.0, ny + 1)
    zeta = np.linspace(0.0, 1.0, nz + 1)
    # points ordered with ξ fastest, then η, then ζ
    Z, E, X = np.meshgrid(zeta, eta, xi, indexing="ij")
    ref = np.column_stack([X.ravel(), E.ravel(), Z.ravel()])
    points = tongue_map(ref, length, width, height)
    idx = np.arange(ref.shape[0]).reshape(nz + 1, ny + 1, nx + 1)
    # VTK order: bottom quad counter-clockwise seen from +ζ (ξ right, η up), then the top
    c = idx[:-1, :-1, :-1], idx[:-1, :-1, 1:], idx[:-1, 1:, 1:], idx[:-1, 1:, :-1]
    u = idx[1:, :-1, :-1], idx[1:, :-1, 1:], idx[1:, 1:, 1:], idx[1:, 1:, :-1]
    cells = np.column_stack([a.ravel() for a in (*c, *u)])
    ref_centres = ref[cells].mean(axis=1)
    centres = points[cells].mean(axis=1)
    label = muscle_atlas(ref_centres)
    regions = {name: np.nonzero(label == name)[0].astype(np.int64) for name in MUSCLES}
    regions = {k: v for k, v in regions.items() if v.size}
    fibers = _fibers(label, centres, ref_centres, length, width, height)

    mesh = hex_mesh(points, cells)
    tol = 1e-9

    def where(mask: NDArray[np.bool_]) -> Callable[[FloatArray], NDArray[np.bool_]]:
        return lambda p: mask  # the mesh keeps the point order of ``ref``

    xi_, eta_, zeta_ = ref[:, 0], ref[:, 1], ref[:, 2]
    bottom = zeta_ < tol
    base = bottom & (xi_ <= 0.6 + tol) & (np.abs(eta_) <= 3.0 / 7.0 + tol)
    mandible = bottom & (xi_ >= 0.6 - tol) & (xi_ <= 0.9 + tol) & (np.abs(eta_) <= 3.0 / 7.0 + tol)
    boundaries = {
        "mandible": facets_where(mesh, where(mandible)),
        "base": facets_where(mesh, where(base)),
        "dorsum": facets_where(mesh, where(zeta_ > 1.0 - tol)),
        "tip": facets_where(mesh, where(xi_ > 1.0 - tol)),
        "posterior": facets_where(mesh, where(xi_ < tol)),
        "lateral": np.union1d(
            facets_where(mesh, where(eta_ < -1.0 + tol)),
            facets_where(mesh, where(eta_ > 1.0 - tol)),
        ).astype(np.int64),
    }
    boundaries["hyoid"] = boundaries["base"]
    all_floor = facets_where(mesh, where(bottom))
    boundaries["floor"] = np.setdiff1d(
        all_floor, np.union1d(boundaries["mandible"], boundaries["base"])
    ).astype(np.int64)
    return labelled_spec(mesh, regions, boundaries, fibers)
