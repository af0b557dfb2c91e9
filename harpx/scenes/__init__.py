"""Synthetic scenes with ground truth: each declares only the parts of harpx it needs.

``phantom(...)`` builds the brain phantom under rotational impact (paper §4.1).
"""

from __future__ import annotations

from harpx.scenes.phantom import Scene, phantom

__all__ = ["Scene", "phantom"]
