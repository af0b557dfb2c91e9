r"""What a cardiac strain result can claim: input checks, segment coverage, observed directions.

Input checks
------------
Strain in the ventricle's frame only means something for a left ventricle described by its
template, in mm. :func:`check_template` refuses a template whose size is not a heart's
(:data:`HEART_SIZE_MM`, the larger of the epicardial diameter :math:`2 a_{epi}` and the
length :math:`c_{epi} + z_b` from the epicardial apex to the base plane); metres or µm are
named with the conversion. :func:`check_body` refuses a body that is not the template's
wall: at least :data:`IN_WALL_FRACTION` of its volume must lie within the fitted wall, that
is at a transmural fraction :math:`-\tau \le t \le 1 + \tau` and at most :math:`\tau h` above
the base plane, with :math:`\tau` = :data:`WALL_TOLERANCE` and :math:`h = a_{epi} -
a_{endo}` the equatorial wall thickness. A solid cylinder filling the cavity (:math:`t < 0`)
or a mesh in the wrong units fails.

Coverage
--------
The template volume of AHA segment :math:`k` is exact for the truncated ellipsoidal wall
(a body of revolution cut by the planes of the segment's ring and by its sector):

.. math::

    V(z_1, z_2) = \pi \left[a_{epi}^2 \left(\Delta z - \frac{z_2^3 - z_1^3}{3 c_{epi}^2}\right)
    - a_{endo}^2 \left(\Delta z - \frac{z_2^3 - z_1^3}{3 c_{endo}^2}\right)\right]

for a ring between :math:`-c_{endo} \le z_1 < z_2`, times :math:`1/6` (basal and mid
sectors) or :math:`1/4` (apical sectors); the apex (17) is the epicardial cap below
:math:`z = -c_{endo}`. A segment's *coverage* is the volume of its cells (or voxels) that
have image data, divided by that template volume and capped at 1 (cells are assigned by
their centre, so a coarse mesh can put a little more than a segment's volume in it).

Observed and inferred directions
--------------------------------
A tag measures motion along its wave vector only; the tracker stores, per cell, the
fraction of each image axis its tags see, :math:`f_a = |P e_a|^2` (``observed_fraction``,
:mod:`harpx.tracking.observability`), :math:`P` the projector onto the seen directions. The
fraction of a local direction :math:`e` (radial, circumferential or longitudinal) that the
tags see is taken as

.. math::

    s(e) = \sum_a e_a^2 f_a ,

which equals :math:`|P e|^2` whenever the seen subspace is spanned by image axes or is a
whole image plane (x/y tags of short-axis slices, x/y/z tags: the usual acquisitions), and
approximates it otherwise. A normal strain :math:`E_{ee}` needs the motion along :math:`e`,
so a segment's component is *observed* when the volume-weighted mean of :math:`s(e)` over
its cells with data is at least :data:`OBSERVED_MIN`, *inferred* (the model's guess) below
:data:`INFERRED_BELOW`, and *partly inferred* in between. Rotation, twist and torsion are
the in-plane motion of material points at the basal and apical levels; which material sits
in an imaged plane depends on the through-plane (longitudinal) motion, so they count as
observed only where both the circumferential and the longitudinal directions are.

Radial strain is taken as observed only where an in-wall direction is seen as well: its
fraction is :math:`\min(s(e_r), \max(s(e_c), s(e_l)))` (:func:`strain_seen_fraction`).
Across a wall about one tag period thick the phase resolves the thickening itself poorly
(next section); a nearly incompressible model then takes much of it from the in-wall
stretch, so where no in-wall direction is seen the radial value rests on the model and the
blur model rather than on the images. The apical cap imaged by long-axis slices alone,
whose through-plane tag runs across the cap, is that case: its radial strain reads "partly
inferred" (what it costs on the infarct scene is in the user guide, "Wall thickening").
Short-axis tags alone (x, y) see the circumferential direction, so they leave the
short-axis rings' radial strain observed, as 2-D tagging analyses report it.

Radial strain and the band-pass blur
------------------------------------
The harmonic phase is the angle of a band-passed image, an average over a disk of radius
``radius`` × the tag frequency in k-space, i.e. over about a tag period in the image, and
(in thick short-axis slices) over the slice profile. Across a wall barely wider than a tag
period, whose inner layers move more than its outer ones, that average pulls the phase of
each layer towards its neighbours: the wall seems to thicken less than it does. The
tracker's blur correction (:mod:`harpx.tracking.blur`) predicts and removes that bias; its
fixed point needs a few passes, and a wider band-pass (which CSPAMM allows, having no DC
peak) leaves less to remove; the correction also needs the phase upsampled (the
tracker samples it between voxels of a wall only a few voxels thick).
:func:`radial_strain_caution` therefore names the settings of a result below
:data:`THICKENING_RADIUS`, :data:`THICKENING_PASSES` or :data:`THICKENING_UPSAMPLE`,
frames whose default tracking target fell to an ``epsilon_min`` below
:data:`THICKENING_EPSILON_MIN` (a fit that follows the phase the correction leaves), and
any conventional HARP result (which has no correction): their radial strain (wall
thickening) is under-reported. The measured biases are in the user guide ("Wall thickening").
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx._typing import BoolArray, FloatArray
from harpx.errors import HarpxError, HarpxWarning, SchemaError, user_stacklevel

__all__ = [
    "HEART_SIZE_MM",
    "INFERRED_BELOW",
    "IN_WALL_FRACTION",
    "OBSERVED_MIN",
    "THICKENING_PASSES",
    "THICKENING_RADIUS",
    "THICKENING_EPSILON_MIN",
    "THICKENING_UPSAMPLE",
    "WALL_TOLERANCE",
    "VentricleShapeError",
    "check_body",
    "check_template",
    "flag_result",
    "radial_strain_caution",
    "seen_fraction",
    "source_labels",
    "strain_seen_fraction",
    "template_segment_volume",
]

#: plausible extent of a (human or large-animal) left ventricle, mm
HEART_SIZE_MM = (20.0, 150.0)
#: transmural tolerance of the wall test, in wall thicknesses
WALL_TOLERANCE = 0.3
#: least fraction of a body's volume that must lie within the template's wall
IN_WALL_FRACTION = 0.8
#: least mean seen fraction of a direction for a component to count as observed
OBSERVED_MIN = 0.9
#: below this mean seen fraction a component is the model's inference
INFERRED_BELOW = 0.5
#: least band-pass radius (fraction of the tag frequency) for an unbiased radial strain
THICKENING_RADIUS = 0.8
#: least blur-correction passes for an unbiased radial strain
THICKENING_PASSES = 3
#: least in-plane upsampling of the phase for an unbiased radial strain
THICKENING_UPSAMPLE = 2
#: least default tracking target (rad) when the images show almost no noise: the
#: residual the blur correction leaves is about this, and a tighter fit follows it
THICKENING_EPSILON_MIN = 0.03


class VentricleShapeError(HarpxError, ValueError):
    """The body is not the wall of the left-ventricle template it is analysed with."""


def _extent(template: Any) -> float:
    g = template.geometry
    return float(max(2.0 * g.outer[0], g.outer[1] + g.truncation))


def check_template(template: Any, heart_size: tuple[float, float] = HEART_SIZE_MM) -> None:
    """Refuse what is not a ventricle template of a heart's size in mm.

    Parameters
    ----------
    template : VentricleTemplate
        Fitted ventricle (:class:`~harpx.anatomy.ventricle_fit.VentricleTemplate`).
    heart_size : tuple of 2 float, default :data:`HEART_SIZE_MM`
        Least and largest plausible extent of the ventricle, mm (the larger of its
        epicardial diameter and its apex-to-base length).

    Raises
    ------
    TypeError
        If ``template`` has no ``geometry``, ``to_local`` or ``local_basis``.
    SchemaError
        If the ventricle's extent is outside ``heart_size`` (the message names metres or
        µm and the conversion).
    """
    missing = [n for n in ("geometry", "to_local", "local_basis") if not hasattr(template, n)]
    if missing:
        raise TypeError(
            f"template must be a VentricleTemplate (e.g. fit_ventricle_to_mask(mask).template); "
            f"got a {type(template).__name__} without {', '.join(missing)}"
        )
    size = _extent(template)
    lo, hi = (float(v) for v in heart_size)
    if lo <= size <= hi:
        return
    if size < lo:
        hint = (
            "coordinates in metres? multiply every coordinate by 1000"
            if size * 1000.0 >= lo
            else "coordinates in cm? multiply by 10"
            if size * 10.0 >= lo
            else "check the units of the coordinates"
        )
    else:
        hint = (
            "coordinates in µm? divide every coordinate by 1000"
            if size / 1000.0 <= hi
            else "check the units of the coordinates"
        )
    raise SchemaError(
        f"the ventricle template is {size:.4g} across, but harpx works in mm and a left "
        f"ventricle is {lo:g}-{hi:g} mm across ({hint}: the images' x, y, z and the mesh "
        "points, then fit the template again); for a small-animal heart pass "
        "heart_size=(lo, hi) in mm"
    )


def check_body(points: FloatArray, weights: FloatArray, template: Any) -> None:
    """Refuse a body whose volume does not lie in the template's wall.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Cell or voxel centres, mm.
    weights : ndarray, shape (n,)
        Their volumes, mm³.
    template : VentricleTemplate
        The fitted ventricle.

    Raises
    ------
    VentricleShapeError
        If less than :data:`IN_WALL_FRACTION` of the volume lies within the wall (see the
        module notes), naming where the rest lies (cavity, outside, above the base) and,
        when the body is a thousand times larger or smaller than the template, the units.
    """
    if len(points) == 0:
        raise VentricleShapeError("the body has no cells or voxels with a finite strain")
    g = template.geometry
    q = template.to_local(points)
    t = g.transmural(q)
    wall = g.outer[0] - g.inner[0]
    cavity = t < -WALL_TOLERANCE
    outside = t > 1.0 + WALL_TOLERANCE
    above = ~cavity & ~outside & (q[:, 2] > g.truncation + WALL_TOLERANCE * wall)
    w = np.asarray(weights, dtype=np.float64)
    total = float(w.sum())
    fractions = {n: float(w[m].sum()) / total for n, m in
                 (("in the cavity", cavity), ("outside the epicardium", outside),
                  ("above the base plane", above))}  # fmt: skip
    inside = 1.0 - sum(fractions.values())
    if inside >= IN_WALL_FRACTION:
        return
    span = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 0.0
    ratio = span / _extent(template)
    units = (
        f" The body spans {span:.4g} against the template's {_extent(template):.4g} mm: "
        "are the mesh points or the image coordinates in metres or µm rather than mm?"
        if ratio < 0.01 or ratio > 100.0
        else ""
    )
    where = ", ".join(f"{100 * f:.0f} % {n}" for n, f in fractions.items() if f > 0.0)
    raise VentricleShapeError(
        f"only {100 * inside:.0f} % of the body's volume lies in the wall of the ventricle "
        f"template ({where}; at least {100 * IN_WALL_FRACTION:.0f} % is needed, with a "
        f"tolerance of {WALL_TOLERANCE:g} wall thickness): this is not the left ventricle the "
        "template describes. Analyse a body meshed from the template or from the same "
        f"segmentation it was fitted to.{units}"
    )


def _ring_volume(template: Any, z1: float, z2: float) -> float:
    g = template.geometry
    (ai, ci), (ao, co) = g.inner, g.outer

    def layer(a: float, c: float, lo: float, hi: float) -> float:
        return float(np.pi * a**2 * ((hi - lo) - (hi**3 - lo**3) / (3.0 * c**2)))

    return layer(ao, co, z1, z2) - layer(ai, ci, z1, z2)


def template_segment_volume(template: Any) -> FloatArray:
    """Volume of each AHA segment of the template's wall (see the module notes).

    Parameters
    ----------
    template : VentricleTemplate
        The fitted ventricle; rings as in :func:`harpx.cardiac.strain.aha_segments`.

    Returns
    -------
    ndarray, shape (17,)
        Volumes in mm³, segment k at index k-1; they sum to the wall volume below the base.
    """
    g = template.geometry
    ci, (ao, co) = g.inner[1], g.outer
    bottom, top = -ci, g.truncation
    edges = bottom + (top - bottom) * np.arange(4) / 3.0
    apical, mid, basal = (_ring_volume(template, edges[k], edges[k + 1]) for k in range(3))
    apex = float(np.pi * ao**2 * ((co - ci) - (co**3 - ci**3) / (3.0 * co**2)))
    return np.array([basal / 6.0] * 6 + [mid / 6.0] * 6 + [apical / 4.0] * 4 + [apex])


def seen_fraction(basis: tuple[FloatArray, ...], observed: ArrayLike) -> FloatArray:
    """Fraction of each local direction that the tags see, ``sum_a e_a^2 f_a``.

    Parameters
    ----------
    basis : tuple of 3 ndarray, shape (n, 3)
        Unit radial, circumferential and longitudinal directions (image components).
    observed : array_like, shape (n, 3)
        Seen fraction of the image axes x, y, z (``observed_fraction``), in [0, 1].

    Returns
    -------
    ndarray, shape (n, 3)
        Seen fraction of (e_r, e_c, e_l), in [0, 1].
    """
    f = np.clip(np.asarray(observed, dtype=np.float64), 0.0, 1.0)
    frame = np.stack(basis, axis=1)  # (n, component, axis)
    return np.clip(np.einsum("nca,na->nc", frame**2, f), 0.0, 1.0)


def strain_seen_fraction(basis: tuple[FloatArray, ...], observed: ArrayLike) -> FloatArray:
    """Fraction of each strain component (radial, circumferential, longitudinal) observed.

    The circumferential and longitudinal fractions are those of their directions
    (:func:`seen_fraction`); the radial one is ``min(s_r, max(s_c, s_l))``: thickening counts
    as observed only where an in-wall direction is seen too (module notes).

    Parameters
    ----------
    basis : tuple of 3 ndarray, shape (n, 3)
        Unit radial, circumferential and longitudinal directions, as for
        :func:`seen_fraction`.
    observed : array_like, shape (n, 3)
        Seen fraction of the image axes x, y, z, in [0, 1], as for :func:`seen_fraction`.

    Returns
    -------
    ndarray, shape (n, 3)
        Observed fraction of (E_rr, E_cc, E_ll), in [0, 1].
    """
    seen = seen_fraction(basis, observed)
    seen[:, 0] = np.minimum(seen[:, 0], seen[:, 1:].max(axis=1))
    return seen


def source_labels(fraction: ArrayLike, has_data: BoolArray | None = None) -> Any:
    """``"observed"``, ``"partly inferred"``, ``"inferred"`` or ``"no data"`` per value.

    Parameters
    ----------
    fraction : array_like
        Mean seen fraction (NaN: not recorded).
    has_data : ndarray of bool, optional
        False where there is no data (label ``"no data"``), broadcast against ``fraction``.

    Returns
    -------
    ndarray of str
        Same shape as ``fraction``; ``"not recorded"`` where the fraction is NaN.
    """
    s = np.asarray(fraction, dtype=np.float64)
    out = np.select(
        [~np.isfinite(s), s >= OBSERVED_MIN, s >= INFERRED_BELOW],
        ["not recorded", "observed", "partly inferred"],
        default="inferred",
    ).astype("<U15")
    if has_data is not None:
        out = np.where(np.broadcast_to(has_data, out.shape), out, "no data")
    return out


def radial_strain_caution(attrs: Mapping[str, Any], targets: ArrayLike | None = None) -> str:
    """Why a tracked result's radial strain (wall thickening) is likely under-reported.

    Parameters
    ----------
    attrs : mapping
        The attributes of a ``tracked/1`` dataset: ``method`` (``"harp"`` for
        conventional HARP), ``phase_radius``, ``phase_upsample`` and ``sequence`` (the
        phase extraction's, recorded by the trackers), ``blur_passes_applied``
        (finite-element tracking), ``setting_epsilon`` and ``setting_epsilon_min`` (its
        target settings).
    targets : array_like, shape (ntime,), optional
        The finite-element result's ``epsilon_target`` per frame, rad: with the default
        target, frames whose target fell to an ``epsilon_min`` below
        :data:`THICKENING_EPSILON_MIN` (the noise floor asked for less, e.g. noise-free
        images) are named.

    Returns
    -------
    str
        Empty when the settings meet :data:`THICKENING_RADIUS`,
        :data:`THICKENING_PASSES` and :data:`THICKENING_UPSAMPLE` (an upsampling not
        recorded counts as met), or when the dataset does not record its phase
        extraction (a displacement from elsewhere, e.g. a synthetic truth); otherwise the
        reasons and the settings that remove the bias (module notes).

    Examples
    --------
    >>> radial_strain_caution({"phase_radius": 0.8, "blur_passes_applied": 3})
    ''
    >>> radial_strain_caution({"method": "harp", "phase_radius": 0.8})[:34]
    'conventional HARP has no blur corr'
    """
    if "phase_radius" not in attrs:
        return ""
    radius = float(attrs["phase_radius"])
    if attrs.get("method") == "harp":
        return (
            "conventional HARP has no blur correction: the band-pass (radius "
            f"{radius:g} of the tag frequency) averages the phase across the wall, so its "
            "radial strain (wall thickening) is under-reported; use finite-element "
            f"tracking with blur_passes={THICKENING_PASSES} for it"
        )
    reasons = []
    if radius < THICKENING_RADIUS:
        fix = (
            "SPAMM's DC peak limits the radius; use CSPAMM images where thickening matters"
            if str(attrs.get("sequence", "")).upper() == "SPAMM"
            else f"CSPAMM has no DC peak: ds.harp.phase(radius={THICKENING_RADIUS:g})"
        )
        reasons.append(f"band-pass radius {radius:g} < {THICKENING_RADIUS:g} ({fix})")
    upsample = int(attrs.get("phase_upsample", THICKENING_UPSAMPLE))
    if upsample < THICKENING_UPSAMPLE:
        reasons.append(
            f"phase upsampling {upsample} < {THICKENING_UPSAMPLE} "
            f"(ds.harp.phase(upsample={THICKENING_UPSAMPLE}), the default)"
        )
    passes = int(attrs.get("blur_passes_applied", 0))
    if passes < THICKENING_PASSES:
        reasons.append(
            f"{passes} blur-correction pass(es) < {THICKENING_PASSES} "
            f"(track(..., blur_passes={THICKENING_PASSES}))"
        )
    reasons += _tight_target(attrs, targets)
    if not reasons:
        return ""
    return (
        "the radial strain (wall thickening) is likely under-reported: the band-pass blur "
        "across the wall is not fully removed with " + " and ".join(reasons)
    )


def _tight_target(attrs: Mapping[str, Any], targets: ArrayLike | None) -> list[str]:
    """The reason a default target at a low ``epsilon_min`` gives, if it does."""
    floor_min = attrs.get("setting_epsilon_min")
    if targets is None or attrs.get("setting_epsilon") != "auto" or floor_min is None:
        return []
    floor_min = float(floor_min)
    t = np.asarray(targets, dtype=np.float64)[1:]
    frames = np.nonzero(np.isclose(t, floor_min, rtol=1e-9))[0] + 1
    if floor_min >= THICKENING_EPSILON_MIN or frames.size == 0:
        return []
    return [
        f"a tracking target at epsilon_min={floor_min:g} rad in frame(s) {frames.tolist()} "
        "(the images' noise floor asked for less: a fit that tight follows the phase the "
        f"correction leaves; track(..., epsilon_min={THICKENING_EPSILON_MIN:g}))"
    ]


def flag_result(out: Any) -> Any:
    """Record, and warn about, what a cardiac strain result cannot claim.

    Parameters
    ----------
    out : xarray.Dataset
        A :func:`~harpx.cardiac.strain.cardiac_strain` result: the tracked dataset with
        ``peak_strain`` and ``peak_time`` (segment, component) added.

    Returns
    -------
    xarray.Dataset
        ``out`` with ``attrs["radial_strain_caution"]`` (:func:`radial_strain_caution`,
        empty when none) and ``attrs["frames_missing_target"]`` (ms: the frames whose
        tracking missed its target or did not converge, from ``target_reached`` and
        ``converged``); where there are such frames, ``peak_at_missed_frame`` (segment,
        component) marks the peaks taken there.

    Warns
    -----
    HarpxWarning
        For a radial caution and for frames that missed their target.
    """
    return _flag_missed_frames(_flag_radial(out))


def _flag_missed_frames(out: xr.Dataset) -> xr.Dataset:
    """Record (and warn) the frames whose tracking missed its target or did not converge
    (the tracker's ``target_reached`` and ``converged``), and the segment peaks taken there."""
    ok = np.ones(out.sizes["time"], dtype=bool)
    for name in ("target_reached", "converged"):
        if name in out and out[name].dims == ("time",):
            ok &= np.asarray(out[name].values, dtype=bool)
    times = np.asarray(out["time"].values, dtype=np.float64)[~ok]
    out.attrs["frames_missing_target"] = times
    if not times.size:
        return out
    peaks = np.isfinite(out["peak_strain"].values)
    at = np.isin(out["peak_time"].values, times) & peaks
    out["peak_at_missed_frame"] = xr.DataArray(
        at, dims=out["peak_strain"].dims,
        attrs={"long_name": "peak taken at a frame whose tracking missed its target"},
    )  # fmt: skip
    named = ", ".join(f"{t:g}" for t in times)
    warnings.warn(
        f"the tracking missed its target or did not converge at t = {named} ms "
        f"('target_reached', 'converged'): {int(at.sum())} of {int(peaks.sum())} segment "
        "peaks were taken there ('peak_at_missed_frame'), and every segment value at those "
        "frames rests on a fit that did not follow the images; track again (more frames, "
        "a larger penalty_limit= or epsilon=) before reading them",
        HarpxWarning,
        stacklevel=user_stacklevel(),
    )
    return out


def _flag_radial(out: xr.Dataset) -> xr.Dataset:
    """Record (and warn) when the result's settings under-report radial strain."""
    targets = out["epsilon_target"].values if "epsilon_target" in out else None
    caution = radial_strain_caution(out.attrs, targets)
    out.attrs["radial_strain_caution"] = caution
    if caution:
        warnings.warn(
            f"{caution}; attrs['radial_strain_caution'] keeps this note",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return out
