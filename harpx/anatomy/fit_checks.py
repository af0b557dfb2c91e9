"""Checks of a ventricle fitted to a short-axis mask against what the stack shows.

:func:`~harpx.anatomy.mask_fit.fit_ventricle_to_mask` runs them on its template and flags
(``fit.flags``, a :class:`~harpx.anatomy.mask_slices.VentricleFitWarning`) a fit whose
shape says that an assumption failed:

* ``base_narrow``: the cavity narrows towards the base plane, as it would if base and apex
  were swapped (:func:`check_base_width`);
* ``axis_tilt``: the long axis was held at the slice normal, but the rings' cavity centres
  drift across the slices, so the real axis is tilted (:func:`check_held_tilt`).

Units: mm, degrees.
"""

from __future__ import annotations

import numpy as np

from harpx.anatomy.mask_slices import _Slices, _Stack, _warn
from harpx.anatomy.ventricle_template import VentricleTemplate

__all__: list[str] = []

#: Cavity radius at the base plane, as a fraction of the widest, below which the fit is
#: flagged ``base_narrow`` (:func:`check_base_width`)
BASE_WIDTH_LIMIT = 0.85
#: Estimated tilt (degrees) of the long axis from the slice normal above which a fit that
#: held the axis at the normal is flagged ``axis_tilt`` (:func:`check_held_tilt`)
HELD_TILT_LIMIT = 7.5


def check_base_width(
    template: VentricleTemplate, stack: _Stack, sense: float, flags: dict[str, str]
) -> None:
    """Flag a cavity that narrows towards the base plane: its radius there below
    :data:`BASE_WIDTH_LIMIT` of the widest (the base plane beyond 0.53 of the cavity
    half-length past the widest level). A left ventricle is widest near its base, so base
    and apex may be swapped. 0.85 lies below the most base-narrowed truncated ellipsoid in
    common use (the base 30 degrees past the equator, radius 0.87 of the widest) and above
    short-axis stacks fitted with the base given at their apical end that reach a third of
    the cavity below the equator (0.82 or less)."""
    g = template.geometry
    ratio = float(np.sqrt(max(1.0 - (g.truncation / g.inner[1]) ** 2, 0.0)))
    if g.truncation <= 0.0 or ratio >= BASE_WIDTH_LIMIT:
        return
    side = "high" if sense > 0 else "low"
    _warn(
        flags, "base_narrow",
        f"the cavity narrows towards the base: its radius at the base plane is {ratio:.2f} of "
        f"the widest ({ratio * g.inner[0]:.1f} of {g.inner[0]:.1f} mm; the base plane lies "
        f"{g.truncation / g.inner[1]:.2f} of the cavity half-length beyond the widest level), "
        "whereas a left ventricle is widest near its base: base and apex may be swapped; "
        f"check base_side / base_level (the base was taken towards {side} "
        f"{stack.slice_axis})",
    )  # fmt: skip


def check_held_tilt(
    template: VentricleTemplate, stack: _Stack, slices: _Slices, flags: dict[str, str]
) -> float:
    """Flag a long axis held at the slice normal that the rings show to be tilted.

    The centres of parallel plane sections of an ellipsoid lie on the diameter conjugate to
    the planes. For a spheroid with short and long radii ``a`` and ``c`` tilted by
    :math:`\\theta` from the planes' normal, that diameter leans by :math:`\\varphi` with
    :math:`\\tan\\varphi = (c^2 - a^2) t / (a^2 t^2 + c^2)`, :math:`t = \\tan\\theta` (less
    than the axis: 12.4 degrees for a 15 degree tilt at ``a / c = 0.4``). :math:`\\varphi` is
    the slope of a least-squares line through the cavity centres of at least three rings;
    :math:`\\theta` follows from the smaller root with the fitted endocardial radii. Above
    :data:`HELD_TILT_LIMIT` the fit is flagged ``axis_tilt``: held at the normal, the axis
    misplaces the segments and tilts the longitudinal direction by about :math:`\\theta`.
    Returns :math:`\\theta` in degrees (NaN with fewer than three rings).
    """
    ring = slices.ring_k
    if ring.size < 3:
        return float("nan")
    cavity = np.moveaxis(slices.cavity, stack.normal, 0)[ring]  # (ring, a, b)
    a_coords, b_coords = (stack.coords[d] for d in stack.other)
    count = cavity.sum(axis=(1, 2))
    centres = np.stack([cavity.sum(axis=2) @ a_coords, cavity.sum(axis=1) @ b_coords], axis=1)
    slope = np.polyfit(stack.position[ring], centres / count[:, None], 1)[0]  # mm per mm
    lean = float(np.hypot(*slope))  # tan(phi)
    a2, c2 = (float(r) ** 2 for r in template.geometry.inner)
    spread = c2 - a2
    disc = spread**2 - 4.0 * a2 * c2 * lean**2
    if lean == 0.0 or spread <= 0.0:  # no lean, or no long axis to lean: take it as seen
        tilt = float(np.degrees(np.arctan(lean)))
    elif disc < 0.0:  # more lean than any tilt of this shape gives: at least the largest
        tilt = float(np.degrees(np.arctan(np.sqrt(c2 / a2))))
    else:
        tilt = float(np.degrees(np.arctan((spread - np.sqrt(disc)) / (2.0 * a2 * lean))))
    if tilt > HELD_TILT_LIMIT:
        _warn(
            flags, "axis_tilt",
            f"the cavity's centre moves {lean * stack.step_n:.1f} mm from one slice to the "
            f"next: the long axis is about {tilt:.0f} degrees off the slice normal "
            f"{stack.slice_axis}, where it was held (a short-axis stack of few or thick "
            "slices); the segments and the longitudinal direction are off by about that "
            "angle. Resample the images across the long axis, add long_axis_slices=, or pass "
            "axis= (the long axis, apex to base)",
        )  # fmt: skip
    return tilt
