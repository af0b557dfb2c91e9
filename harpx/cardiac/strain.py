r"""Strain in the ventricle's local frame, AHA 17 segments, twist and torsion.

Local frame
-----------
At every point of the wall the fitted template (:class:`~harpx.anatomy.ventricle_fit.
VentricleTemplate`) gives the circumferential direction :math:`e_c` (counter-clockwise
about the long axis, which points from the apex to the base), the longitudinal direction
:math:`e_l` (the meridian of the ellipsoidal layer through the point, apex to base) and the
radial direction :math:`e_r = e_c \times e_l` (the outward layer normal). The normal
Green–Lagrange strains are :math:`E_{aa} = e_a \cdot E\, e_a` with
:math:`E = \tfrac12 (F^T F - I)`, and the engineering (stretch) strains
:math:`\varepsilon_{aa} = \sqrt{1 + 2 E_{aa}} - 1` (the relative change of length of a
reference line element along :math:`e_a`), both dimensionless.

AHA 17 segments
---------------
Cerqueira et al. (2002): the cavity, from the endocardial apex :math:`z = -c_{endo}` to the
base plane (template coordinates), is cut into basal, mid and apical thirds of equal length;
the myocardium below the endocardial apex is segment 17 (apex). Basal (1–6) and mid (7–12)
rings have six 60° sectors and the apical ring (13–16) four 90° sectors. Segments 1, 7 and
13 are centred on the anterior direction, the angle ``anterior`` (degrees about the long
axis, right-handed about the apex-to-base axis, from the template's +x axis), and the
numbers run counter-clockwise *seen from the apex*, as in the standard short-axis view and
bull's-eye (anterior at the top, septum on the left): anterior, anteroseptal, inferoseptal,
inferior, inferolateral, anterolateral. In the template's right-handed frame that is
clockwise about its z axis: basal and mid sector k is centred on ``anterior - 60° (k-1)``,
apical sector k on ``anterior - 90° (k-1)``, so the septum lies at ``anterior - 90°`` and the
lateral wall at ``anterior + 90°``. The template has no right ventricle: ``anterior`` comes
from the caller or from the template's ``anterior`` attribute when it has one (the
direction of the anterior wall, e.g. midway between the right-ventricular insertions
rotated by 90° towards the lateral wall). Segment values are volume integrals over the
segment's points with image data, divided by their volume: for trilinear (hex8) cells the
2 × 2 × 2 Gauss points of every cell, each with the strain and volume it carries there, so
that a cell across a segment border adds to both segments in proportion; for other
elements one point per cell (its centre, with the cell's mean strain); for a grid result
the voxels. What that leaves out, and which components the tags observed, is described in
:mod:`harpx.cardiac.quality`.

Rotation, twist, torsion
------------------------
The rotation of a material point is the angle, in the short-axis plane, between its
reference and current position vectors from the long axis; its sign follows the cardiac
convention: positive counter-clockwise *seen from the apex* (that is, a negative rotation
about the apex-to-base axis). Level rotations are volume-weighted means over the basal
(1–6) and apical (13–16) segments with data; twist is apical minus basal rotation (degrees)
and torsion the twist divided by the reference distance between the two levels' centroids
along the axis (degrees/mm). A level whose segments with data fill less than
``min_coverage`` of its template volume (the segments' rule) has no rotation, and then
twist and torsion are NaN (:mod:`harpx.cardiac.twist`).

References
----------
.. [1] Cerqueira MD et al. Standardized myocardial segmentation and nomenclature for
   tomographic imaging of the heart. Circulation 105:539--542, 2002.
.. [2] Russel IK et al. Left ventricular torsion: an expanding role in the analysis of
   myocardial dysfunction. JACC Cardiovasc Imaging 2:648--655, 2009.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx._typing import BoolArray, FloatArray, IntArray
from harpx.anatomy.aha import segments_local
from harpx.cardiac.anterior import _anterior
from harpx.cardiac.quality import (
    HEART_SIZE_MM,
    check_body,
    check_template,
    flag_result,
    source_labels,
    strain_seen_fraction,
    template_segment_volume,
)
from harpx.cardiac.twist import _level_rotation, _levels, _warn_levels
from harpx.cardiac.wall_points import _cell_weights, _grid_strain, _hex8_gauss_points, _observation
from harpx.conventions import ELEMENT_CORNERS
from harpx.errors import HarpxWarning, user_stacklevel

__all__ = [
    "AHA_NAMES",
    "COMPONENTS",
    "MIN_COVERAGE",
    "aha_segments",
    "cardiac_strain",
    "lv_measures",
]

#: names of the 17 AHA segments, index k-1 for segment k
AHA_NAMES = (
    "basal anterior", "basal anteroseptal", "basal inferoseptal", "basal inferior",
    "basal inferolateral", "basal anterolateral", "mid anterior", "mid anteroseptal",
    "mid inferoseptal", "mid inferior", "mid inferolateral", "mid anterolateral",
    "apical anterior", "apical septal", "apical inferior", "apical lateral", "apex",
)  # fmt: skip
#: the normal strain components in the local frame
COMPONENTS = ("radial", "circumferential", "longitudinal")
#: least coverage (fraction of its template volume with data) for a segment to get a value
MIN_COVERAGE = 0.1


def aha_segments(points: ArrayLike, template: Any, *, anterior: float | None = None) -> IntArray:
    """AHA segment (1–17) of wall points.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Image points in mm (in the wall).
    template : VentricleTemplate
        The fitted ventricle.
    anterior : float, optional
        Direction of the anterior wall (centre of segments 1, 7, 13), degrees about the
        long axis (right-handed about the apex-to-base axis) from the template's +x axis.
        Default: the template's ``anterior``; without one, 0 and a warning.

    Returns
    -------
    ndarray of int, shape (n,)
        Segment numbers 1..17, counter-clockwise seen from the apex (points above the base
        plane count as basal).

    Raises
    ------
    TypeError
        If ``anterior`` is not a single number (e.g. a vector or an image point).
    ValueError
        If ``anterior`` is not finite.

    Warns
    -----
    HarpxWarning
        Neither ``anterior`` nor the template gives the anterior direction: the names are
        then counted from the template's +x axis, not anatomical.

    Examples
    --------
    >>> from harpx.anatomy.ventricle import VentricleGeometry
    >>> from harpx.anatomy.ventricle_fit import VentricleTemplate
    >>> from harpx.cardiac.strain import aha_segments
    >>> t = VentricleTemplate(VentricleGeometry((25.0, 70.0), (35.0, 78.0), 10.0))
    >>> # anterior +x; the septum at -y, the lateral wall at +y; the apex
    >>> points = [[30.0, 1.0, 0.0], [-1.0, -30.0, -40.0], [0.0, 0.0, -74.0]]
    >>> aha_segments(points, t, anterior=0.0).tolist()
    [1, 9, 17]
    """
    angle, _ = _anterior(anterior, template)
    q = template.to_local(points)
    return segments_local(q, template.geometry, angle)


def _local_strain(E: FloatArray, basis: tuple[FloatArray, ...]) -> FloatArray:
    """Normal components (..., n, 3) of strains E (..., n, 3, 3) along (e_r, e_c, e_l)."""
    frame = np.stack(basis, axis=-1)  # (n, 3 axis, 3 component)
    return np.einsum("nia,...nij,nja->...na", frame, E, frame)


def _ranges(numbers: ArrayLike) -> str:
    """``"1-4, 7"`` for [1, 2, 3, 4, 7]."""
    k = [int(v) for v in np.asarray(numbers).ravel()]
    parts, start = [], 0
    for i in range(1, len(k) + 1):  # at most 17 segments
        if i == len(k) or k[i] != k[i - 1] + 1:
            parts.append(str(k[start]) if i - 1 == start else f"{k[start]}-{k[i - 1]}")
            start = i
    return ", ".join(parts)


def _peak(values: FloatArray, times: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Signed value of largest magnitude over time (axis 0) and its time; NaN without data."""
    finite = np.isfinite(values)
    k = np.argmax(np.where(finite, np.abs(values), -1.0), axis=0)
    any_ = finite.any(axis=0)
    peak = np.where(any_, np.take_along_axis(values, k[None], axis=0)[0], np.nan)
    return peak, np.where(any_, times[k], np.nan)


def _warn_quality(coverage: FloatArray, has: BoolArray, source: Any, twist: str,
                  min_coverage: float) -> str:  # fmt: skip
    """Warn about segments without data and components the tags did not see; the summary."""
    empty = np.flatnonzero(~has) + 1
    if empty.size:
        named = ", ".join(f"{k} {AHA_NAMES[k - 1]} ({coverage[k - 1]:.2f})" for k in empty)
        warnings.warn(
            f"no image data in AHA segment(s) {_ranges(empty)}: {named} (coverage, the "
            f"fraction of the segment's template volume with data, below {min_coverage:g}); "
            "their values are NaN (listed in attrs['segments_without_data'])",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    unseen = []
    for c, name in enumerate(COMPONENTS):  # three components
        for label in ("inferred", "partly inferred"):
            segs = np.flatnonzero(source[:, c] == label) + 1
            if segs.size:
                unseen.append(f"{name} strain {label} in segment(s) {_ranges(segs)}")
    if twist in ("inferred", "partly inferred"):
        unseen.append(f"rotation, twist and torsion {twist}")
    summary = "; ".join(unseen)
    if unseen:
        warnings.warn(
            f"the tags did not observe every component: {summary}. There the values come "
            "from the mechanical model, not from the images (see 'strain_source' and the "
            "'source' attribute of rotation, twist and torsion); add tags along the unseen "
            "direction (e.g. long-axis slices with a through-plane tag) to measure them",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return summary


def lv_measures(
    points: ArrayLike,
    green_strain: ArrayLike,
    current: ArrayLike,
    weights: ArrayLike,
    template: Any,
    *,
    time: ArrayLike,
    anterior: float | None = None,
    observed: ArrayLike | None = None,
    has_data: ArrayLike | None = None,
    min_coverage: float = MIN_COVERAGE,
    heart_size: tuple[float, float] = HEART_SIZE_MM,
) -> xr.Dataset:
    """Segment strains, peaks, rotations, twist and torsion from strains at wall points.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Reference positions (Gauss points, cell centres or voxel centres), mm.
    green_strain : array_like, shape (ntime, n, 3, 3)
        Green–Lagrange strain at the points (dimensionless); NaN points are left out.
    current : array_like, shape (ntime, n, 3)
        Current positions of the points, mm.
    weights : array_like, shape (n,)
        Volume of each point, mm³.
    template : VentricleTemplate
        The fitted ventricle (local frame and segments).
    time : array_like, shape (ntime,)
        Frame times, ms.
    anterior : float, optional
        Direction of the anterior wall, degrees (see :func:`aha_segments`); default the
        template's ``anterior`` attribute, else 0 with a :class:`~harpx.errors.HarpxWarning`.
    observed : array_like, shape (n, 3), optional
        Fraction of the image axes x, y, z that the tags see at each point (the tracker's
        ``observed_fraction``); default not recorded.
    has_data : array_like of bool, shape (n,), optional
        Points with image data (default all); the others are left out of every mean.
    min_coverage : float, default :data:`MIN_COVERAGE`
        Segments whose points with data fill less than this fraction of their template
        volume get NaN.
    heart_size : tuple of 2 float, default (20, 150)
        Plausible extent of the ventricle, mm (see
        :func:`~harpx.cardiac.quality.check_template`).

    Returns
    -------
    xarray.Dataset
        ``segment_strain`` and ``segment_engineering_strain`` (time, segment, component);
        ``peak_strain`` and ``peak_engineering_strain`` (segment, component): the signed
        value of largest magnitude over the frames, with ``peak_time`` (ms);
        ``segment_volume`` (segment, mm³, of the points with data) and
        ``segment_template_volume`` (mm³); ``strain_observed_fraction`` (segment,
        component): mean observed fraction of the component (its direction's, for the
        radial one at most that of the better-seen in-wall direction:
        :func:`~harpx.cardiac.quality.strain_seen_fraction`; NaN: not recorded);
        ``rotation`` (time, level) in degrees for the ``"base"`` and ``"apex"``
        levels, ``twist`` (time, degrees) and ``torsion`` (time, degrees/mm), each with
        attributes ``source`` (``"no data"`` where a level lacks coverage) and
        ``observed_fraction``; coordinates ``level_coverage`` (level, 0..1: the fraction of
        the level's template volume in its segments with data; below ``min_coverage`` the
        level's rotation is NaN, and twist and torsion), ``segment`` (1..17),
        ``segment_name``, ``segment_coverage`` (0..1), ``strain_source`` (segment,
        component: ``"observed"``, ``"partly inferred"``, ``"inferred"``, ``"not
        recorded"`` or ``"no data"``), ``component`` (radial, circumferential,
        longitudinal); attributes ``anterior_deg``, ``anterior_source``,
        ``segments_without_data`` (int array), ``levels_without_data`` (level names,
        space-separated, empty when none) and ``strain_inferred`` (summary, empty when
        the tags saw everything). Segments without data are NaN throughout.

    Raises
    ------
    TypeError
        If ``template`` is not a ventricle template, or ``anterior`` is not a single number.
    ValueError
        If ``anterior`` is not finite.
    SchemaError
        If the template's size is not a heart's in mm (metres, µm).
    VentricleShapeError
        If the points do not lie in the template's wall.

    Warns
    -----
    HarpxWarning
        When the anterior direction is unknown, when segments have no data (named), when a
        level lacks coverage (twist and torsion NaN), and when the tags did not observe a
        component (named with its segments).
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    E = np.asarray(green_strain, dtype=np.float64)
    x = np.asarray(current, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    times = np.asarray(time, dtype=np.float64)
    check_template(template, heart_size)
    anterior_deg, anterior_source = _anterior(anterior, template)
    q0 = template.to_local(p)
    segment = segments_local(q0, template.geometry, anterior_deg)
    basis = template.local_basis(p)
    local = _local_strain(E, basis)  # (time, n, 3)
    engineering = np.sqrt(np.maximum(1.0 + 2.0 * local, 0.0)) - 1.0
    valid = np.all(np.isfinite(local), axis=(0, 2)) & np.all(np.isfinite(x), axis=(0, 2))
    check_body(p[valid], w[valid], template)
    data = valid if has_data is None else valid & np.asarray(has_data, dtype=bool).reshape(-1)
    seen = (np.full((len(p), 3), np.nan) if observed is None
            else strain_seen_fraction(basis, observed))  # fmt: skip
    segments = _Segments.of(segment, data, w, template, min_coverage)
    seg = segments.mean(local)
    seg_eng = segments.mean(engineering)
    seg_seen = segments.mean(seen)
    coverage, has = segments.coverage, segments.has
    source = source_labels(seg_seen, has[:, None])
    peak_e, peak_t = _peak(seg, times)
    peak_eng, _ = _peak(seg_eng, times)
    # the levels on their segments with data, and only with enough of it (as a segment)
    levels, level_cov, level_ok = _levels(
        segment, data, has, segments.volume, segments.template_volume, min_coverage
    )
    level_rot, distance, level_seen = _level_rotation(q0, x, template, levels, w, seen)
    twist = level_rot[:, 1] - level_rot[:, 0]
    both = level_ok & level_ok.all()  # twist and torsion need both levels
    seen_at = [float(np.min(level_seen[k])) if observed is not None and k.any() else np.nan
               for k in (level_ok, both)]  # fmt: skip
    rot_source, twist_source = (
        str(source_labels(f)) if k.any() else "no data"
        for f, k in zip(seen_at, (level_ok, both), strict=True)
    )
    summary = _warn_quality(coverage, has, source, twist_source, min_coverage)
    levels_without_data = _warn_levels(level_cov, level_ok, min_coverage)

    seg_coords = {
        "segment": ("segment", np.arange(1, 18), {"long_name": "AHA segment", "units": "1"}),
        "segment_name": ("segment", np.array(AHA_NAMES, dtype=str), {"long_name": "AHA name"}),
        "segment_coverage": ("segment", coverage, {
            "units": "1", "long_name": "fraction of the segment's template volume with data"}),
        "component": ("component", np.array(COMPONENTS, dtype=str), {"long_name": "direction"}),
        "strain_source": (("segment", "component"), source, {
            "long_name": "observed by the tags or inferred by the model"}),
        "level": ("level", np.array(list(levels), dtype=str), {"long_name": "short-axis level"}),
        "level_coverage": ("level", level_cov, {"units": "1", "long_name":
                           "fraction of the level's template volume in its segments with data"}),
        "time": ("time", times, {"units": "ms", "long_name": "time"}),
    }  # fmt: skip
    out = xr.Dataset(coords=seg_coords)
    dims3 = ("time", "segment", "component")

    def var(data: Any, dims: tuple[str, ...], units: str, long_name: str) -> xr.DataArray:
        return xr.DataArray(data, dims=dims, attrs={"units": units, "long_name": long_name})

    out["segment_strain"] = var(seg, dims3, "1", "segment mean Green-Lagrange strain")
    out["segment_engineering_strain"] = var(
        seg_eng, dims3, "1", "segment mean engineering strain (stretch - 1)"
    )
    out["peak_strain"] = var(
        peak_e, ("segment", "component"), "1", "peak segment Green-Lagrange strain"
    )
    out["peak_engineering_strain"] = var(
        peak_eng, ("segment", "component"), "1", "peak segment engineering strain"
    )
    out["peak_time"] = var(peak_t, ("segment", "component"), "ms", "time of peak strain")
    out["segment_volume"] = var(
        segments.volume, ("segment",), "mm3", "volume of the segment with data"
    )
    out["segment_template_volume"] = var(
        segments.template_volume, ("segment",), "mm3", "volume of the segment in the template"
    )
    out["strain_observed_fraction"] = var(
        seg_seen, ("segment", "component"), "1", "mean fraction of the direction the tags see"
    )
    out["rotation"] = var(
        level_rot, ("time", "level"), "degree", "rotation, counter-clockwise seen from apex"
    )
    out["twist"] = var(twist, ("time",), "degree", "apical minus basal rotation")
    out["torsion"] = var(
        twist / distance if np.isfinite(distance) and distance > 0 else twist * np.nan,
        ("time",),
        "degree/mm",
        "twist per base-apex distance",
    )
    out["torsion"].attrs["level_distance_mm"] = distance
    for name, k in (("rotation", 0), ("twist", 1), ("torsion", 1)):
        out[name].attrs.update(source=(rot_source, twist_source)[k], observed_fraction=seen_at[k])
    out.attrs.update(
        anterior_deg=anterior_deg,
        anterior_source=anterior_source,
        segments_without_data=np.flatnonzero(~has).astype(np.int64) + 1,
        levels_without_data=levels_without_data,
        strain_inferred=summary,
    )
    return out


@dataclass(frozen=True)
class _Segments:
    """The wall points' AHA segments as volume weights (:func:`lv_measures`)."""

    weights: FloatArray  # (n, 17): each point's volume in its segment, 0 elsewhere or no data
    data: BoolArray  # (n,): points with data
    volume: FloatArray  # (17,): volume with data per segment, mm³
    template_volume: FloatArray  # (17,): the segment's volume in the template, mm³
    coverage: FloatArray  # (17,): volume / template volume, at most 1
    has: BoolArray  # (17,): coverage at least ``min_coverage`` (and some volume)

    @classmethod
    def of(
        cls, segment: IntArray, data: BoolArray, w: FloatArray, template: Any, min_coverage: float
    ) -> _Segments:
        onehot = (segment[:, None] == np.arange(1, 18)[None, :]) & data[:, None]  # (n, 17)
        weights = onehot * w[:, None]
        volume = weights.sum(axis=0)
        template_volume = template_segment_volume(template)
        coverage = np.minimum(volume / template_volume, 1.0)
        has = (coverage >= min_coverage) & (volume > 0)
        return cls(weights, data, volume, template_volume, coverage, has)

    def mean(self, values: FloatArray) -> FloatArray:
        """Volume-weighted segment means of (..., n, c) values -> (..., 17, c); NaN for a
        segment without enough data."""
        norm = np.where(self.has, self.volume, np.nan)
        filled = np.where(self.data[:, None], values, 0.0)
        means: FloatArray = np.einsum("...nc,ns->...sc", filled, self.weights) / norm[:, None]
        return means


def _aligned_body(body: xr.DataArray, u: xr.DataArray) -> xr.DataArray:
    """``body`` in the voxel order of the displacement ``u`` (z, y, x): a coordinate stored
    in the opposite order is reversed; a different grid is refused."""
    b = body.transpose("z", "y", "x")
    for d in (d for d in ("z", "y", "x") if d in b.coords):
        have, want = (np.asarray(a[d].values, dtype=np.float64) for a in (b, u))
        if have.shape == want.shape and np.allclose(have[::-1], want) and have.size > 1:
            b = b.isel({d: slice(None, None, -1)})
        elif have.shape != want.shape or not np.allclose(have, want):
            raise ValueError(
                f"body's {d} coordinate ({have.size} values, {have.min():.4g} .. "
                f"{have.max():.4g} mm) is not the displacement's ({want.size} values, "
                f"{want.min():.4g} .. {want.max():.4g} mm); pass a body on the same grid"
            )
    return b


def _warn_not_recorded(what: str) -> None:
    warnings.warn(
        f"{what} does not record which directions its tags observed (no 'observed_fraction'): "
        "strain_source is 'not recorded', and a component no tag saw (e.g. longitudinal "
        "strain and twist with short-axis x/y tags only) would look measured. Track with "
        "harpx.tracking.track, which records it per cell",
        HarpxWarning,
        stacklevel=user_stacklevel(),
    )


def cardiac_strain(
    tracked: xr.Dataset,
    template: Any,
    *,
    anterior: float | None = None,
    body: xr.DataArray | None = None,
    min_coverage: float = MIN_COVERAGE,
    heart_size: tuple[float, float] = HEART_SIZE_MM,
) -> xr.Dataset:
    """Local-frame strain, AHA segment curves and peaks, twist and torsion of a result.

    Parameters
    ----------
    tracked : xarray.Dataset
        A finite-element ``tracked/1`` dataset (``points``, ``cells``, ``displacement``,
        ``green_strain``; ``observed_fraction`` and ``observed_directions`` say what the
        tags saw in each cell), or any dataset with a displacement on the image grid
        (``displacement_grid`` of conventional HARP, or the ``displacement_true`` of a
        synthetic ``tagged/1`` dataset, taken as fully known), whose strain is then taken
        by central differences between voxel centres.
    template : VentricleTemplate
        The fitted ventricle: local frame, segments and long axis (e.g.
        ``fit_ventricle_to_mask(tagged).template``), in mm.
    anterior : float, optional
        Direction of the anterior wall in degrees about the long axis from the template's
        +x axis (see :func:`aha_segments`); default the template's ``anterior`` attribute.
    body : xarray.DataArray, optional
        For grid displacements: the voxels to use (``body >= 0.5``), default the
        ``body`` variable of the dataset when present, else every finite voxel.
    min_coverage : float, default :data:`MIN_COVERAGE`
        Segments whose cells (voxels) with data fill less than this fraction of their
        template volume are NaN.
    heart_size : tuple of 2 float, default (20, 150)
        Plausible extent of the ventricle in mm; pass smaller bounds for small animals.

    Returns
    -------
    xarray.Dataset
        ``tracked`` with the variables of :func:`lv_measures` added, plus, for a
        finite-element result, ``strain_lv`` and ``engineering_strain_lv`` (time, cell,
        component), ``strain_lv_observed`` (cell, component: observed fraction of each
        component in the cell, as ``strain_observed_fraction``, when recorded) and
        ``aha_segment`` (cell); for a grid result
        ``aha_segment_grid`` (z, y, x, 0 outside the voxels used). Finite-element cells
        without tag data (``observed_directions`` 0) count as cells without data.
        Attribute ``frames_missing_target`` (ms): the frames whose tracking missed its
        target or did not converge (``target_reached``, ``converged``); where there are
        any, ``peak_at_missed_frame`` (segment, component) marks the peaks taken there.

    Raises
    ------
    ValueError
        If the dataset holds neither a finite-element result nor a grid displacement, if
        ``body`` is not on the displacement's grid (a coordinate stored in the opposite
        order is reversed to match), or if ``anterior`` is not finite.
    TypeError
        If ``anterior`` is not a single number (an angle in degrees; for a point on the
        anterior wall pass ``template.angle([point])[0]``).
    SchemaError
        If the template is not a heart's size in mm (coordinates in metres or µm).
    VentricleShapeError
        If the body is not the template's wall (e.g. a cylinder, or another ventricle).

    Warns
    -----
    HarpxWarning
        Segments without data (NaN), a short-axis level without enough data (twist and
        torsion NaN), components the tags did not observe, an unknown
        anterior direction, a dataset that does not record what its tags observed, or
        settings that under-report radial strain (conventional HARP; a band-pass radius
        or blur-correction passes below what removes the blur across the wall:
        :func:`~harpx.cardiac.quality.radial_strain_caution`, kept in
        ``attrs["radial_strain_caution"]``, empty when none), or frames whose tracking
        missed its target.

    Examples
    --------
    A synthetic displacement on a 4 mm grid: the wall shrinks by 10 % in the short-axis
    plane and turns about the long axis by 0.1° per mm of height, so every segment has a
    circumferential Green–Lagrange strain of (0.9² - 1) / 2 and the torsion is 0.1°/mm:

    >>> from harpx.anatomy.ventricle import VentricleGeometry
    >>> from harpx.anatomy.ventricle_fit import VentricleTemplate
    >>> t = VentricleTemplate(VentricleGeometry((25.0, 70.0), (35.0, 78.0), 10.0), anterior=0.0)
    >>> x = y = np.arange(-36.0, 37.0, 4.0)
    >>> z = np.arange(-78.0, 11.0, 4.0)
    >>> Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    >>> a = np.deg2rad(0.1) * Z  # turn about the long axis (z), rad
    >>> u = np.stack([0.9 * (np.cos(a) * X - np.sin(a) * Y) - X,
    ...               0.9 * (np.sin(a) * X + np.cos(a) * Y) - Y, 0.0 * Z])
    >>> wall = t.transmural(np.stack([X, Y, Z], axis=-1).reshape(-1, 3)).reshape(X.shape)
    >>> ds = xr.Dataset(
    ...     {"displacement_true": (("time", "axis", "z", "y", "x"), np.stack([0.0 * u, u])),
    ...      "body": (("z", "y", "x"), (wall >= 0.0) & (wall <= 1.0) & (Z <= 10.0))},
    ...     coords={"time": [0.0, 100.0], "axis": ["x", "y", "z"], "z": z, "y": y, "x": x})
    >>> out = cardiac_strain(ds, t)
    >>> np.unique(out.peak_strain.sel(component="circumferential").round(3)).tolist()
    [-0.095]
    >>> round(float(out.torsion.sel(time=100.0)), 3)  # degrees/mm
    0.1
    """
    if "time" not in tracked.coords:
        raise ValueError(
            "cardiac_strain needs a finite-element tracked/1 dataset or a grid displacement "
            "with a 'time' coordinate (ms); this dataset has none"
        )
    times = np.asarray(tracked["time"].values, dtype=np.float64)
    options: dict[str, Any] = {
        "time": times, "anterior": anterior, "min_coverage": min_coverage,
        "heart_size": heart_size,
    }  # fmt: skip
    fe = (
        {"points", "cells", "displacement", "green_strain"} <= set(tracked.variables)
        and tracked["cells"].attrs.get("element", "hex8") != "points"
        and tracked.sizes.get("cell", 0) > 0
    )
    if fe:
        pts = np.asarray(tracked["points"].values, dtype=np.float64)
        cells = np.asarray(tracked["cells"].values, dtype=np.int64)
        disp = np.asarray(tracked["displacement"].transpose("time", "node", "axis").values)
        element = str(tracked["cells"].attrs.get("element", "hex8"))
        corners = cells[:, : ELEMENT_CORNERS.get(element, 8)]
        centres = pts[corners].mean(axis=1)
        E = np.asarray(tracked["green_strain"].transpose("time", "cell", "i", "j").values)
        observed, has_data = _observation(tracked)
        if observed is None:
            _warn_not_recorded("this finite-element dataset")
        if element == "hex8":
            # the segment means as volume integrals on each cell's Gauss points: a cell
            # across a segment border adds to both sides, not wholly to its centre's
            X, E_points, current, weights = _hex8_gauss_points(pts, cells, disp)
            measures = lv_measures(
                X, E_points, current, weights, template,
                observed=None if observed is None else np.repeat(observed, 8, axis=0),
                has_data=None if has_data is None else np.repeat(has_data, 8), **options,
            )  # fmt: skip
        else:  # other elements: one point per cell, its centre, with the cell-mean strain
            current = (pts[None] + disp)[:, corners].mean(axis=2)
            measures = lv_measures(
                centres, E, current, _cell_weights(pts, cells, element), template,
                observed=observed, has_data=has_data, **options,
            )  # fmt: skip
        basis = template.local_basis(centres)
        local = _local_strain(E, basis)
        dims = ("time", "cell", "component")
        out = tracked.assign_coords(measures.coords).assign(measures.data_vars)
        out.attrs.update(measures.attrs)
        out["strain_lv"] = xr.DataArray(
            local, dims=dims,
            attrs={"units": "1", "long_name": "Green-Lagrange strain in the LV frame"},
        )  # fmt: skip
        out["engineering_strain_lv"] = xr.DataArray(
            np.sqrt(np.maximum(1.0 + 2.0 * local, 0.0)) - 1.0, dims=dims,
            attrs={"units": "1", "long_name": "engineering strain in the LV frame"},
        )  # fmt: skip
        if observed is not None:
            out["strain_lv_observed"] = xr.DataArray(
                strain_seen_fraction(basis, observed), dims=("cell", "component"),
                attrs={"units": "1", "long_name": "observed fraction of the strain component"},
            )  # fmt: skip
        out["aha_segment"] = xr.DataArray(
            aha_segments(centres, template, anterior=measures.attrs["anterior_deg"]),
            dims="cell", attrs={"units": "1", "long_name": "AHA segment"},
        )  # fmt: skip
        return flag_result(out)
    name = next((n for n in ("displacement_grid", "displacement_true") if n in tracked), None)
    if name is None:
        raise ValueError(
            "cardiac_strain needs a finite-element tracked/1 dataset (points, cells, "
            "displacement, green_strain) or a grid displacement ('displacement_grid' or "
            f"'displacement_true'); got variables {sorted(map(str, tracked.data_vars))!r}"
        )
    u = tracked[name]
    pts, E, current = _grid_strain(u)
    if body is None and "body" in tracked:
        body = tracked["body"]
    use = np.ones(len(pts), dtype=bool)
    if body is not None:
        use = np.asarray(_aligned_body(body, u).values >= 0.5).ravel()
    finite = use & np.all(np.isfinite(E), axis=(0, 2, 3))
    n = int(finite.sum())
    if name == "displacement_grid":
        _warn_not_recorded(f"'{name}' (method {tracked.attrs.get('method', 'unknown')!r})")
    # voxel volume from the absolute steps: a coordinate stored descending (e.g. after
    # ds.isel(z=slice(None, None, -1))) is the same grid, not a negative volume
    spacing = [float(np.abs(np.diff(u[d].values)).mean()) for d in ("x", "y", "z")]
    measures = lv_measures(
        pts[finite], E[:, finite], current[:, finite], np.full(n, float(np.prod(spacing))),
        template, observed=np.ones((n, 3)) if name == "displacement_true" else None,
        **options,
    )  # fmt: skip
    seg = np.zeros(len(pts), dtype=np.int64)
    seg[finite] = aha_segments(pts[finite], template, anterior=measures.attrs["anterior_deg"])
    out = tracked.assign_coords(measures.drop_vars("time").coords).assign(measures.data_vars)
    out.attrs.update(measures.attrs)
    shape = tuple(u.sizes[d] for d in ("z", "y", "x"))
    out["aha_segment_grid"] = xr.DataArray(
        seg.reshape(shape), dims=("z", "y", "x"),
        attrs={"units": "1", "long_name": "AHA segment of voxels used (0: none)"},
    )  # fmt: skip
    return flag_result(out)
