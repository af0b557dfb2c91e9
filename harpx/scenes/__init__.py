"""Synthetic scenes with ground truth: each declares only the parts of harpx it needs.

* ``phantom(...)``: brain phantom under rotational impact (paper §4.1), neo-Hookean only.
* ``lv(...)``: prestretched left ventricle (paper §4.2): Guccione fibres, active stress,
  cavity pressure and growth.
* ``short_axis(...)``: a contracting, twisting, shortening tube imaged by short-axis slices
  with in-plane (x, y) tags only: nothing sees the through-plane motion.
* ``tongue(...)``: tongue with five muscles (paper §4.3): neo-Hookean with per-muscle
  active fibre stress.
"""

from __future__ import annotations

from harpx.scenes.lv import lv
from harpx.scenes.phantom import Scene, phantom
from harpx.scenes.short_axis import short_axis
from harpx.scenes.tongue import tongue

__all__ = ["Scene", "lv", "phantom", "short_axis", "tongue"]
