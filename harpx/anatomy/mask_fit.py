r"""The ventricle fitted to a myocardium mask or segmentation, refusing what it cannot trust.

Fit to a mask
-------------
:func:`fit_ventricle_to_mask` takes the stacks scans provide and refuses what it cannot
trust (:class:`~harpx.anatomy.mask_slices.VentricleFitError`, a ``ValueError``) or flags it
(``fit.flags`` and a :class:`~harpx.anatomy.mask_slices.VentricleFitWarning`), stating the
numbers. The first step, the mask read as a stack of short-axis slices, is
:mod:`harpx.anatomy.mask_slices`; this module takes the long axis, the base and apex, the
anterior wall and the segments from there:

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
  ``anterior=`` sets it directly: an angle, or an image point on the anterior wall (refused
  more than two wall thicknesses outside the epicardium, or too close to the axis to give
  a direction).
* **Base at the wrong end.** A cavity whose radius at the base plane is below 0.85 of its
  widest (the base plane more than 0.53 of the cavity half-length past the widest level)
  is flagged (``base_narrow``): a left ventricle is widest near its base, so base and apex
  may be swapped (check ``base_side`` and ``base_level``).
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

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray
from harpx.anatomy.aha import segments_local
from harpx.anatomy.contours import _contours, _lax_points, _lax_sense, _padded_along
from harpx.anatomy.fit_checks import check_base_width, check_held_tilt
from harpx.anatomy.mask_slices import (
    VentricleFitError,
    VentricleFitWarning,  # noqa: F401 (still importable from here)
    _read_lax,
    _read_mask,
    _Slices,
    _Stack,
    _warn,
)
from harpx.anatomy.ventricle import VentricleGeometry
from harpx.anatomy.ventricle_template import VentricleFit, VentricleTemplate, fit_ventricle

__all__ = ["fit_ventricle_to_mask"]


def _aha(template: VentricleTemplate, points: ArrayLike) -> IntArray:
    """AHA segment (1..17) of image points.

    The convention of :func:`harpx.cardiac.strain.aha_segments` with the template's
    ``anterior`` (0 when unknown): thirds of the cavity from the endocardial apex to the
    base plane; 60° (apical 90°) sectors, the first centred on ``anterior``, numbered
    counter-clockwise seen from the apex (clockwise about the template's z axis).
    """
    return segments_local(template.to_local(points), template.geometry, template.anterior or 0.0)


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


def _check_options(slice_axis: str, base_side: Any, rv: Any, anterior: Any) -> None:
    if slice_axis not in ("x", "y", "z"):
        raise VentricleFitError(f"slice_axis={slice_axis!r} must be 'x', 'y' or 'z'")
    if base_side not in (None, "high", "low"):
        raise VentricleFitError(f"base_side={base_side!r} must be 'high', 'low' or None")
    if rv is not None and anterior is not None:
        raise VentricleFitError("pass either rv= (a right-ventricle label) or anterior=, not both")
    _anterior_form(anterior)


def _anterior_form(anterior: Any) -> FloatArray | None:
    """``anterior=`` as a finite angle (0-d) or image point (3,); TypeError or
    VentricleFitError naming it and the accepted forms otherwise."""
    if anterior is None:
        return None
    forms = "an angle in degrees (a float) or an image point on the anterior wall (x, y, z mm)"
    if isinstance(anterior, (str, bytes, bool)):
        raise TypeError(f"anterior={anterior!r} must be {forms}")
    try:
        a = np.asarray(anterior, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"anterior={anterior!r} must be {forms}") from exc
    if a.shape not in ((), (3,)):
        raise VentricleFitError(f"anterior={anterior!r} has shape {a.shape}; it must be {forms}")
    if not np.all(np.isfinite(a)):
        raise VentricleFitError(f"anterior={anterior!r} is not finite; it must be {forms}")
    return a


def _axis_hint(axis: Any) -> FloatArray | None:
    """The unit axis hint of ``axis=`` (None for a mode name)."""
    if isinstance(axis, str):
        if axis not in ("auto", "slice", "fit"):
            raise VentricleFitError(f"axis={axis!r} must be 'auto', 'slice', 'fit' or a vector")
        return None
    hint = np.asarray(axis, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(hint)) and np.linalg.norm(hint) > 0):
        raise VentricleFitError(f"axis={axis!r} must be a finite non-zero vector")
    unit: FloatArray = hint / np.linalg.norm(hint)
    return unit


def _sense(
    stack: _Stack,
    slices: _Slices,
    hint: FloatArray | None,
    axis: Any,
    base_side: str | None,
    lax: list[Any],
) -> float:
    """The sense of the long axis along the slice normal: +1 when the base lies towards
    increasing slice coordinate. From the user, the axis hint, long-axis slices or the
    apical cap; refused when they disagree or none tells."""
    e_n = stack.e_n
    sense_user = None if base_side is None else (1.0 if base_side == "high" else -1.0)
    sense_hint = None if hint is None or hint @ e_n == 0 else float(np.sign(hint @ e_n))
    cap_low, cap_high = slices.cap_low, slices.cap_high
    sense_cap = 1.0 if cap_low and not cap_high else -1.0 if cap_high and not cap_low else None
    if sense_user is not None and sense_hint is not None and sense_user != sense_hint:
        raise VentricleFitError(
            f"base_side={base_side!r} contradicts axis={axis!r} (apex to base); give one of them"
        )
    sense = sense_user if sense_user is not None else sense_hint
    if lax and sense is None and sense_cap is None:
        grid_c = np.meshgrid(*stack.coords, indexing="ij")
        ring_centre = np.array([float(grid_c[2 - a][slices.cavity].mean()) for a in range(3)])
        band = max(stack.step_n, 3.0 * stack.in_plane)
        sense = _lax_sense(lax, ring_centre, e_n, band=band)
    slice_axis = stack.slice_axis
    if sense is not None and sense_cap is not None and sense != sense_cap:
        cap_k = slices.tissue_k.min() if cap_low else slices.tissue_k.max()
        raise VentricleFitError(
            f"the base is said to lie towards {'high' if sense > 0 else 'low'} {slice_axis}, "
            f"but the apical cap of the mask (tissue without cavity, {slice_axis} = "
            f"{stack.position[cap_k]:.4g} mm) lies at that end; check base_side / axis"
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
    return sense


def _axis_start(
    stack: _Stack,
    slices: _Slices,
    hint: FloatArray | None,
    axis: Any,
    sense: float,
    apex_in_view: bool,
    lax: list[Any],
    apex_level: float | None,
) -> tuple[bool, FloatArray]:
    """Whether the long axis is held, and its start (apex to base); refuses an axis hint
    far off the slices, ``apex_level`` for a 3-D fit and an apex too few rings can place."""
    thick = stack.step_n > 1.5 * stack.in_plane
    if axis == "slice":
        hold = True
    elif axis == "fit":
        hold = False
    else:
        hold = not ((apex_in_view and not thick) or bool(lax))
    e_n = stack.e_n
    u0 = sense * e_n
    if hint is not None:
        off = float(np.degrees(np.arccos(min(abs(float(hint @ e_n)), 1.0))))
        limit = 15.0 if hold else 45.0
        if off > limit:
            what = "a short-axis stack (axis held at its normal)" if hold else "the slices"
            raise VentricleFitError(
                f"axis={np.round(hint, 3).tolist()} is {off:.1f} degrees off the normal of "
                f"{what} ({stack.slice_axis}, limit {limit:g}); short-axis slices are planned "
                "across the long axis: check axis and slice_axis, or resample the images"
            )
        u0 = hint * np.sign(hint @ e_n) * sense
    if apex_level is not None and not hold:
        raise VentricleFitError(
            "apex_level is for a short-axis stack that does not reach the apex (axis held at "
            "the slice normal); this mask is fitted in 3-D (apex in view or long-axis "
            "slices): drop apex_level or pass axis='slice'"
        )
    rings = slices.ring_k.size
    if hold and not apex_in_view and apex_level is None and not lax and rings < 3:
        raise VentricleFitError(
            f"the apex is not in view and {rings} ring slices cannot place it (the "
            "ellipsoid's centre, two long and two short radii need at least 3 levels); pass "
            "apex_level= or long_axis_slices="
        )
    return hold, u0


def _base_plane(
    template: VentricleTemplate, candidates: FloatArray, source: str, stack: _Stack
) -> tuple[float, FloatArray]:
    """The base plane's level along the template axis (mm from its centre) and the base
    points it rests on: the top face of the wall among ``candidates``."""
    if len(candidates) < 3:
        raise VentricleFitError(f"{source} gives {len(candidates)} base points; pass base_level=")
    local = template.to_local(candidates)
    qz = local[:, 2]
    # the top face of the wall: its voxel staircase spans a step along the slice axis,
    # plus the rise of an oblique base plane across the ventricle
    slope = np.tan(np.arccos(min(abs(float(template.axis @ stack.e_n)), 1.0)))
    window = stack.step_n + 2.0 * stack.in_plane + template.geometry.outer[0] * slope
    t_b = template.geometry.transmural(local)
    base_used = candidates[(qz > qz.max() - window) & (t_b > -0.1) & (t_b < 1.1)]
    if len(base_used) < 3:
        raise VentricleFitError(
            f"{source} gives {len(base_used)} base points in the wall; pass base_level="
        )
    return float(np.median(template.to_local(base_used)[:, 2])), base_used


def _check_extrapolated_apex(
    template: VentricleTemplate,
    truncation: float,
    uncertainty: float,
    endo: FloatArray,
    epi: FloatArray,
    stack: _Stack,
    flags: dict[str, str],
) -> None:
    """Refuse an apex out of view whose extrapolation is uncertain beyond a slice step and
    a tenth of the cavity; flag it otherwise."""
    g, c, u, normal = template.geometry, template.centre, template.axis, stack.normal
    length = max(truncation + g.inner[1], 0.0)
    lowest = float(np.min(template.to_local(np.concatenate([endo, epi]))[:, 2]))
    allowed = max(stack.step_n, 0.1 * length)
    apex_at = c[2 - normal] - g.inner[1] * u[2 - normal]
    where = f"{stack.slice_axis} = {apex_at:.1f} ± {uncertainty:.1f} mm"
    beyond = f"{lowest + g.inner[1]:.1f} mm beyond the lowest contour"
    if uncertainty > allowed:
        raise VentricleFitError(
            f"the apex is not in view and the slices do not locate it: the ellipsoid puts "
            f"it at {where} (more than {allowed:.1f} mm), {beyond}; pass apex_level= or "
            "long_axis_slices="
        )
    _warn(
        flags, "apex_extrapolated",
        f"the apex is not in view: the fitted ellipsoid places the endocardial apex at "
        f"{where}, {beyond}; the AHA thirds depend on it (pass apex_level= if you know it)",
    )  # fmt: skip


def _anterior(
    template: VentricleTemplate,
    anterior: Any,
    touch: IntArray | None,
    rv: Any,
    stack: _Stack,
    flags: dict[str, str],
) -> tuple[float | None, tuple[float, float] | None]:
    """The anterior angle (degrees, as ``template.anterior``) and the RV insertions, from
    ``anterior=`` or the septum the RV touches; None when neither is given (flagged)."""
    a = _anterior_form(anterior)
    if a is not None:
        return (float(a) if a.ndim == 0 else _anterior_point(template, a, anterior)), None
    if touch is None:
        _warn(
            flags, "anterior_unknown",
            "no rv= or anterior=: the anterior wall (AHA segment 1) is unknown; segments are "
            "numbered from the template's +x axis",
            warn=False,
        )  # fmt: skip
        return None, None
    ant, inf, septum, width = _insertions(template, stack.points(touch), touch[:, stack.normal])
    if not np.isfinite(ant):
        raise VentricleFitError(
            f"the right-ventricle label {rv!r} touches the myocardium in too few voxels "
            f"({len(touch)}) to find the insertions; check rv="
        )
    w = float(np.median(width))
    if not 40.0 <= w <= 240.0:
        _warn(
            flags, "rv_contact",
            f"the right ventricle touches the LV myocardium over {w:.0f} degrees per "
            "slice (median; a septum spans about 120): check rv= (the RV wall or blood "
            "pool, not the LV blood pool)",
        )  # fmt: skip
    # the anterior wall is 90 degrees from the middle of the septum, on the side of the
    # anterior insertion (positive about the apex-to-base axis)
    return float(np.mod(septum + 90.0, 360.0)), (ant, inf)


def _anterior_point(template: VentricleTemplate, point: FloatArray, given: Any) -> float:
    """The angle of an image point on the anterior wall; refused when it cannot be on the
    wall: beyond the layer two wall thicknesses outside the epicardium (transmural fraction
    3; e.g. a direction vector read as a point), or within a quarter of the cavity radius of
    the long axis (no direction)."""
    g = template.geometry
    q = template.to_local(point.reshape(1, 3))[0]
    radial, near = float(np.hypot(q[0], q[1])), 0.25 * g.inner[0]
    a3, c3 = (3.0 * o - 2.0 * i for o, i in zip(g.outer, g.inner, strict=True))  # layer t = 3
    centre = np.round(template.centre, 1).tolist()
    if (radial / a3) ** 2 + (q[2] / c3) ** 2 > 1.0:
        raise VentricleFitError(
            f"anterior={given!r}, read as an image point (mm), lies {radial:.1f} mm from the "
            f"long axis and {q[2]:.1f} mm along it from the fitted centre {centre}: more than "
            "two wall thicknesses outside the epicardium, not on the anterior wall. Pass a "
            "point on the anterior wall in image coordinates (mm) or the angle in degrees "
            "about the long axis (a direction vector is not accepted)"
        )
    if radial < near:
        raise VentricleFitError(
            f"anterior={given!r}, read as an image point (mm), lies {radial:.1f} mm from the "
            f"long axis (less than a quarter of the cavity radius, {near:.1f} mm), where it "
            "gives no direction: pass a point on the anterior wall (mm) or the angle in "
            "degrees about the long axis (a direction vector is not accepted)"
        )
    return float(template.angle(point.reshape(1, 3))[0])


def _segments_in_view(
    template: VentricleTemplate, stack: _Stack, inside: Any, flags: dict[str, str]
) -> tuple[IntArray, tuple[int, ...]]:
    """Voxel count of each AHA segment (1..17) and the segments beyond the imaged tissue;
    flags empty segments in view and a base plane beyond the tissue."""
    g = template.geometry
    grid = np.stack(np.meshgrid(*stack.coords, indexing="ij"), axis=-1)[inside][:, ::-1]
    counts: IntArray = np.bincount(_aha(template, grid), minlength=18)[1:]
    qz = template.to_local(grid)[:, 2]
    lo_view, hi_view = float(qz.min()), float(qz.max())  # tissue voxel centres
    bottom, top = -g.inner[1], g.truncation
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
    top_face = hi_view + 0.5 * stack.step_n * abs(float(template.axis @ stack.e_n))
    if top > top_face + 3.0:
        _warn(
            flags, "base_out_of_view",
            f"the base plane lies {top - top_face:.1f} mm beyond the imaged tissue: a "
            "mesh of this mask has no facets on it (an empty 'base' boundary); hold the top "
            "face of the mesh instead",
        )  # fmt: skip
    return counts, out_of_view


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
        a long axis along x) or as an image point on that wall (mm; not a direction vector).
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
        myocardium; the base or apex level lies outside the fitted ventricle; ``anterior``
        is neither a scalar nor of shape (3,), or not finite, or a point more than two
        wall thicknesses outside the epicardium or within a quarter of the cavity radius of
        the long axis (e.g. a direction vector read as a point).
    TypeError
        ``anterior`` is not a number or a sequence of numbers.

    Warns
    -----
    VentricleFitWarning
        For each warned entry of ``flags`` (residual, axis, apex extrapolated, base out of
        view, empty segments in view, open slices, implausible septal arc, a cavity that
        narrows towards the base: ``base_narrow``, base and apex possibly swapped).

    Examples
    --------
    A binary mask of a truncated ellipsoidal ventricle (endocardial radii 12 and 30 mm,
    epicardial 18 and 36 mm, long axis along z) on a 2 mm grid that shows the apex. The
    short radii come back to a small fraction of a voxel; the long radii and the base
    plane to within a voxel along the axis, where a binary mask cannot place the base
    more finely:

    >>> from harpx.anatomy.mask_fit import fit_ventricle_to_mask
    >>> from harpx.anatomy.ventricle import VentricleGeometry
    >>> truth = VentricleGeometry(inner=(12.0, 30.0), outer=(18.0, 36.0), truncation=6.0)
    >>> xy, z = np.arange(-24.0, 24.5, 2.0), np.arange(-40.0, 7.0, 2.0)
    >>> Z, Y, X = np.meshgrid(z, xy, xy, indexing="ij")
    >>> inside = truth.inside(np.stack([X, Y, Z], -1).reshape(-1, 3))  # apex at z = -36
    >>> mask = xr.DataArray(inside.reshape(Z.shape), dims=("z", "y", "x"),
    ...                     coords={"z": z, "y": xy, "x": xy})
    >>> fit = fit_ventricle_to_mask(mask)
    >>> g = fit.template.geometry
    >>> np.round([*g.inner, *g.outer]).tolist(), round(float(fit.template.axis[2]), 3)
    ([12.0, 29.0, 18.0, 35.0], 1.0)
    >>> bool(fit.rms < 1.0), sorted(fit.flags), int(np.count_nonzero(fit.segment_voxels))
    (True, ['anterior_unknown'], 17)
    """
    _check_options(slice_axis, base_side, rv, anterior)
    hint = _axis_hint(axis)
    flags: dict[str, str] = {}
    da, f, stack, slices, touch = _read_mask(mask, variable, slice_axis, myocardium, rv, flags)
    lax = _read_lax(list(long_axis_slices), variable, myocardium)
    sense = _sense(stack, slices, hint, axis, base_side, lax)
    apex_in_view = bool(slices.cap_low if sense > 0 else slices.cap_high)
    hold, u0 = _axis_start(stack, slices, hint, axis, sense, apex_in_view, lax, apex_level)

    # contour points (voxels fill their extent along the slice axis)
    fp, cp = _padded_along(f, da, slice_axis)
    normal = stack.normal
    cavity_p = np.pad(slices.cavity, [(1, 1) if d == normal else (0, 0) for d in range(3)])
    # rings and the apical cap (all epicardium); not the open arcs beyond the base or the
    # open slices, whose inner side would pass for epicardium
    used = np.concatenate([slices.ring_k, slices.cap_k])
    use = np.pad(np.isin(np.arange(f.shape[normal]), used), 1)
    endo, epi, base_pts = _contours(fp, cp, normal, cavity_p, u0, use)
    apex_point = None if apex_level is None else stack.e_n * float(apex_level)
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

    t, g = first.template, first.template.geometry
    if base_level is not None:
        truncation = float((float(base_level) - t.centre[2 - normal]) / t.axis[2 - normal])
        base_used, source = np.empty((0, 3)), f"base_level={base_level:g} mm"
    else:
        if len(lax_base) >= 3:
            candidates, source = lax_base, "the long-axis slices"
        elif apex_in_view:
            candidates, source = base_pts, "the top of the mask"
        else:
            top_k = slices.tissue_k.max() if sense > 0 else slices.tissue_k.min()
            raise VentricleFitError(
                f"the base level is unknown: the mask does not show the apex, so the top of "
                f"the stack ({slice_axis} = {stack.position[top_k]:.4g} mm) need not be the "
                "base; pass base_level= (the slice-axis coordinate of the base plane, mm) or "
                "long_axis_slices="
            )
        truncation, base_used = _base_plane(t, candidates, source, stack)
    uncertainty = None if apex_in_view or apex_level is not None else first.apex_uncertainty
    if uncertainty is not None:
        _check_extrapolated_apex(t, truncation, uncertainty, endo, epi, stack, flags)
    if not -g.inner[1] < truncation < g.inner[1]:
        raise VentricleFitError(
            f"the base plane from {source} lies {truncation:.1f} mm from the fitted centre "
            f"along the axis, outside the cavity (c_endo = {g.inner[1]:.1f} mm); check the "
            "base level and base_side"
        )
    if apex_level is not None and truncation <= -g.inner[1] + 1e-6:
        raise VentricleFitError("base_level lies at or below apex_level; check both")

    geometry = VentricleGeometry(inner=g.inner, outer=g.outer, truncation=truncation)
    untold = VentricleTemplate(geometry, t.centre, t.rotation)
    angle, insertions = _anterior(untold, anterior, touch, rv, stack, flags)
    template = VentricleTemplate(geometry, t.centre, t.rotation, anterior=angle)
    check_base_width(template, stack, sense, flags)
    if hold:
        check_held_tilt(template, stack, slices, flags)

    # residuals, checks and the segments
    endo_res = template.surface_distance(endo, "endo")
    epi_res = template.surface_distance(epi, "epi")
    base_res = template.to_local(base_used)[:, 2] - truncation if len(base_used) else np.empty(0)
    limit = stack.in_plane if max_residual is None else float(max_residual)
    rms = float(np.sqrt(np.mean(np.concatenate([endo_res, epi_res]) ** 2)))
    if rms > limit:
        _warn(
            flags, "residual",
            f"the fit's rms residual is {rms:.2f} mm, above {limit:.2f} mm (one in-plane voxel "
            "by default): the mask is not well described by the truncated ellipsoid; check "
            "the segmentation",
        )  # fmt: skip
    tilt = float(np.degrees(np.arccos(np.clip(abs(float(template.axis @ stack.e_n)), 0.0, 1.0))))
    if not hold and tilt > 30.0:
        _warn(
            flags, "axis",
            f"the fitted long axis {np.round(template.axis, 3).tolist()} is {tilt:.1f} degrees "
            f"off the slice normal ({slice_axis}); the rings of slices this oblique are "
            "elongated: resample the images across the long axis, or pass axis='slice'",
        )  # fmt: skip
    counts, out_of_view = _segments_in_view(template, stack, slices.inside, flags)
    return VentricleFit(
        template,
        endo_res,
        epi_res,
        base_res,
        flags=flags,
        segment_voxels=counts,
        out_of_view=out_of_view,
        insertions=insertions,
        apex_uncertainty=uncertainty,
    )
