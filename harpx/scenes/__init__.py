"""Synthetic scenes with ground truth: each declares only the parts of harpx it needs.

* ``phantom(...)``: brain phantom under rotational impact (paper §4.1), neo-Hookean only.
* ``lv(...)``: prestretched left ventricle (paper §4.2): Guccione fibres, active stress,
  cavity pressure and growth.
* ``tongue(...)``: tongue with five muscles (paper §4.3): neo-Hookean with per-muscle
  active fibre stress.
"""

from __future__ import annotations

from harpx.scenes.lv import lv
from harpx.scenes.phantom import Scene, phantom
from harpx.scenes.tongue import tongue

__all__ = ["Scene", "lv", "phantom", "tongue"]
