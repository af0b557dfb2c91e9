"""The anterior direction the AHA segments of :mod:`harpx.cardiac.strain` are counted from.

An ``anterior=`` argument must be an angle in degrees about the long axis from the
template's +x axis; without one the template's ``anterior`` attribute is used, and without
that the template's +x axis, with a warning.

Units: degrees.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from harpx.errors import HarpxWarning, user_stacklevel

__all__: list[str] = []


def _anterior(anterior: float | None, template: Any) -> tuple[float, str]:
    """The anterior angle (degrees) and where it came from; warns when nobody knows it."""
    if anterior is not None:
        forms = (
            "an angle in degrees about the long axis from the template's +x axis (a float); "
            "for a point on the anterior wall pass template.angle([point])[0]"
        )
        if isinstance(anterior, (str, bytes, bool)) or np.ndim(anterior) != 0:
            raise TypeError(f"anterior={anterior!r} must be {forms}")
        try:
            angle = float(anterior)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"anterior={anterior!r} must be {forms}") from exc
        if not np.isfinite(angle):
            raise ValueError(f"anterior={anterior!r} is not finite; it must be {forms}")
        return angle, "argument"
    value = getattr(template, "anterior", None)
    try:
        if value is not None and np.isfinite(float(value)):
            return float(value), "template"
    except (TypeError, ValueError):
        pass
    warnings.warn(
        "the anterior direction is unknown (no anterior= and the template has no 'anterior' "
        "angle): the segments are numbered from the template's +x axis taken as anterior, "
        "so names such as 'septal' or 'inferior' are not anatomical. Pass anterior= (degrees "
        "about the long axis from the template's +x axis to the middle of the anterior wall)",
        HarpxWarning,
        stacklevel=user_stacklevel(),
    )
    return 0.0, "unknown (template +x axis)"
