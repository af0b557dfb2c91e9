"""What cardiac users read: strain in the ventricle's frame, AHA segments, twist, torsion.

:mod:`harpx.cardiac.strain` computes them; :mod:`harpx.cardiac.quality` checks the input
and says what the images covered and which components the tags observed.
"""

from __future__ import annotations

from harpx.cardiac.quality import VentricleShapeError
from harpx.cardiac.strain import AHA_NAMES, aha_segments, cardiac_strain, lv_measures

__all__ = ["AHA_NAMES", "VentricleShapeError", "aha_segments", "cardiac_strain", "lv_measures"]
