"""Synthetic scenes with ground truth: each declares only the parts of harpx it needs.

``harpx.scenes.phantom(...)`` builds the brain phantom (paper §4.1).
"""

from __future__ import annotations

from typing import Any

__all__ = ["phantom"]


def phantom(*args: Any, **kwargs: Any) -> Any:
    """Build the brain-phantom scene; see :func:`harpx.scenes.phantom.phantom`."""
    from harpx.scenes.phantom import phantom as build

    return build(*args, **kwargs)
