"""The analytic left ventricle fitted to endo- and epicardial contours or a myocardium mask.

The names of this module live in three, one job each:

* :mod:`harpx.anatomy.ventricle_template`: the template placed in the image
  (:class:`VentricleTemplate`) and its least-squares fit to contour points
  (:func:`fit_ventricle`, :class:`VentricleFit`);
* :mod:`harpx.anatomy.contours`: contour points of a myocardium mask
  (:func:`ventricle_contours`);
* :mod:`harpx.anatomy.mask_fit`: the fit to a mask or segmentation with its refusals and
  flags (:func:`fit_ventricle_to_mask`), starting from the mask read as a stack of
  short-axis slices by :mod:`harpx.anatomy.mask_slices` (:class:`VentricleFitError`,
  :class:`VentricleFitWarning`).

They stay importable from here.
"""

from __future__ import annotations

from harpx.anatomy.contours import ventricle_contours
from harpx.anatomy.mask_fit import fit_ventricle_to_mask
from harpx.anatomy.mask_slices import VentricleFitError, VentricleFitWarning
from harpx.anatomy.ventricle_template import VentricleFit, VentricleTemplate, fit_ventricle

__all__ = [
    "VentricleFit",
    "VentricleFitError",
    "VentricleFitWarning",
    "VentricleTemplate",
    "fit_ventricle",
    "fit_ventricle_to_mask",
    "ventricle_contours",
]
