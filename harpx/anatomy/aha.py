r"""The AHA 17-segment rule on the left-ventricle template: the one place it is written.

Cerqueira et al. (2002): the cavity, from the endocardial apex :math:`z = -c_{endo}` to the
base plane (template coordinates, the long axis :math:`z` pointing from the apex to the
base), is cut into basal, mid and apical thirds of equal length; the myocardium below the
endocardial apex is segment 17 (apex). Basal (1–6) and mid (7–12) rings have six 60°
sectors and the apical ring (13–16) four 90° sectors. Segments 1, 7 and 13 are centred on
the anterior wall, and the numbers run counter-clockwise seen from the apex (clockwise
about the template's +z): seen in the standard bull's-eye, anterior at the top and the
septum on the left. Points above the base plane count as basal.

References
----------
.. [1] Cerqueira MD et al. Standardized myocardial segmentation and nomenclature for
   tomographic imaging of the heart. Circulation 105:539--542, 2002.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from harpx._typing import IntArray

__all__ = ["segments_local"]


def segments_local(q: ArrayLike, geometry: Any, anterior: float) -> IntArray:
    """AHA segment (1–17) of points in template coordinates.

    Parameters
    ----------
    q : array_like, shape (n, 3)
        Points in the template's frame (x, y, z), mm; z runs from the apex to the base.
    geometry : VentricleGeometry
        The template's ellipsoids (``inner`` = (a, c) of the endocardium, mm) and base plane
        (``truncation``, mm).
    anterior : float
        Direction of the anterior wall (centre of segments 1, 7 and 13), degrees about
        the template's +z from its +x axis.

    Returns
    -------
    ndarray of int, shape (n,)
        Segment numbers 1..17.

    Examples
    --------
    >>> from harpx.anatomy.ventricle import VentricleGeometry
    >>> g = VentricleGeometry((25.0, 70.0), (35.0, 78.0), 10.0)
    >>> # anterior +x: the septum at -y, the lateral wall at +y; the apex
    >>> segments_local([[30.0, 1.0, 0.0], [-1.0, -30.0, -40.0], [0.0, 0.0, -74.0]], g, 0.0)
    array([ 1,  9, 17])
    """
    q = np.asarray(q, dtype=np.float64).reshape(-1, 3)
    bottom, top = -float(geometry.inner[1]), float(geometry.truncation)
    third = (top - bottom) / 3.0
    # angle from the anterior direction, counter-clockwise seen from the apex (-z rotation)
    turn = np.deg2rad(anterior) - np.arctan2(q[:, 1], q[:, 0])
    six = np.floor(np.mod(turn + np.pi / 6.0, 2.0 * np.pi) / (np.pi / 3.0)).astype(np.int64) % 6
    four = np.floor(np.mod(turn + np.pi / 4.0, 2.0 * np.pi) / (np.pi / 2.0)).astype(np.int64) % 4
    z = q[:, 2]
    return np.select(
        [z < bottom, z < bottom + third, z < bottom + 2.0 * third],
        [17, 13 + four, 7 + six],
        default=1 + six,
    ).astype(np.int64)
