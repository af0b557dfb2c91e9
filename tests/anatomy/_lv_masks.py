"""Synthetic left-ventricle masks with a known truth: short-axis stacks, long-axis slices, RV.

The wall is the truncated prolate-spheroidal shell of :class:`VentricleGeometry` (endocardium
25 x 70 mm, epicardium 35 x 78 mm, base plane 10 mm above the centre), long axis along +z.
A short-axis slice is the wall's cross-section at the slice centre, sampled at 1.5 mm
in-plane voxels; slices lie 8 mm apart, as in cine MRI.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from harpx.anatomy.ventricle import VentricleGeometry
from harpx.anatomy.ventricle_fit import VentricleTemplate

GEOMETRY = VentricleGeometry(inner=(25.0, 70.0), outer=(35.0, 78.0), truncation=10.0)
CENTRE = (2.0, -3.0, 0.0)  # mm, off the grid's voxel centres in x
TRUTH = VentricleTemplate(GEOMETRY, centre=CENTRE)
PIXEL = 1.5  # in-plane voxel, mm
#: four mid-ventricular slices 8 mm apart: the cavity thirds of the truth (endocardial apex
#: z = -70, base z = 10) are apical below -43.3, mid to -16.7, basal above
MID_SLICES = (-42.0, -34.0, -26.0, -18.0)


def _grid(z, half: float = 48.0) -> tuple[np.ndarray, ...]:
    x = np.arange(-half, half + 1e-9, PIXEL)
    Z, Y, X = np.meshgrid(np.asarray(z, dtype=np.float64), x, x, indexing="ij")
    return x, Z, Y, X


def short_axis_stack(
    z=MID_SLICES, template: VentricleTemplate = TRUTH, half: float = 48.0
) -> xr.DataArray:
    """Binary myocardium (label 1) of the template on short-axis slices at ``z`` (mm)."""
    x, Z, Y, X = _grid(z, half)
    p = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    inside = template.geometry.inside(template.to_local(p)).reshape(Z.shape)
    return xr.DataArray(
        inside.astype(np.int64), dims=("z", "y", "x"),
        coords={"z": np.asarray(z, dtype=np.float64), "y": x, "x": x},
    )  # fmt: skip


def volume(template: VentricleTemplate = TRUTH, step: float = 1.5) -> xr.DataArray:
    """Binary myocardium on an isotropic 3-D grid that holds the whole ventricle."""
    x = np.arange(-50.0, 50.0, step)
    z = np.arange(-86.0, 24.0, step)
    Z, Y, X = np.meshgrid(z, x, x, indexing="ij")
    p = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    inside = template.geometry.inside(template.to_local(p)).reshape(Z.shape)
    return xr.DataArray(
        inside.astype(np.int64), dims=("z", "y", "x"), coords={"z": z, "y": x, "x": x}
    )


def long_axis_slice(normal: str = "y", thickness: float = 8.0) -> xr.DataArray:
    """The wall within ``thickness``/2 of the plane through the truth's axis (normal x or y).

    On a 1.5 mm 3-D grid, background outside the slab: a long-axis slice resampled onto a
    common grid.
    """
    x = np.arange(-48.0, 48.0 + 1e-9, PIXEL)
    z = np.arange(-84.0, 24.0 + 1e-9, PIXEL)
    Z, Y, X = np.meshgrid(z, x, x, indexing="ij")
    p = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    inside = TRUTH.geometry.inside(TRUTH.to_local(p)).reshape(Z.shape) > 0.5
    k = {"x": 0, "y": 1}[normal]
    slab = np.abs(p[:, k].reshape(Z.shape) - TRUTH.centre[k]) <= thickness / 2
    return xr.DataArray(
        (inside & slab).astype(np.int64), dims=("z", "y", "x"), coords={"z": z, "y": x, "x": x}
    )


def with_rv(
    mask: xr.DataArray, start: float, stop: float, *, label: int = 2, thickness: float = 8.0
) -> xr.DataArray:
    """Add a right-ventricle crescent (``label``) against the epicardium of the truth.

    It covers template angles ``start`` .. ``stop`` (degrees, counter-clockwise about +z
    from +x; ``stop`` may exceed 360) and the ``thickness`` (mm) outside the wall, so it
    touches the LV exactly over the septum ``start`` .. ``stop``.
    """
    Z, Y, X = np.meshgrid(mask.z.values, mask.y.values, mask.x.values, indexing="ij")
    q = TRUTH.to_local(np.stack([X, Y, Z], axis=-1).reshape(-1, 3))
    t = TRUTH.geometry.transmural(q)
    wall = GEOMETRY.outer[0] - GEOMETRY.inner[0]
    angle = np.mod(np.degrees(np.arctan2(q[:, 1], q[:, 0])) - start, 360.0)
    rv = (t > 1.0) & (t < 1.0 + thickness / wall) & (angle <= stop - start)
    rv &= q[:, 2] < GEOMETRY.truncation
    out = mask.copy()
    values = out.values.reshape(-1)
    values[rv & (values == 0)] = label
    return out
