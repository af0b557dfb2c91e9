"""What cardiac users read: strain in the ventricle's frame, AHA segments, twist, torsion."""

from __future__ import annotations

from harpx.cardiac.strain import AHA_NAMES, aha_segments, cardiac_strain, lv_measures

__all__ = ["AHA_NAMES", "aha_segments", "cardiac_strain", "lv_measures"]
