"""Ideal (noise- and blur-free) phase datasets from an analytic motion, for tracking tests.

The phase of tag t at voxel x and time t is exactly W(2π f d·X(x, t)); the magnitude is the
body indicator. This isolates the tracker from image formation and filtering.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from harpx.imaging.stacks import image_coords
from harpx.schema import standard_attrs


def ideal_phase(motion, *, shape, spacing, times, tag_period=8.0, body=None, tags=("x", "y", "z")):
    nz, ny, nx = shape
    dz, dy, dx = spacing
    z = (np.arange(nz) - (nz - 1) / 2) * dz
    y = (np.arange(ny) - (ny - 1) / 2) * dy
    x = (np.arange(nx) - (nx - 1) / 2) * dx
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    dirs = np.eye(3)[["xyz".index(t) for t in tags]]
    freq = np.full(len(tags), 1.0 / tag_period)
    phase = np.empty((len(tags), len(times), nz, ny, nx))
    mag = np.empty_like(phase)
    truth = np.empty((len(times), 3, nz, ny, nx))
    inside0 = np.ones(pts.shape[0], bool) if body is None else body(pts) > 0.5
    for n, t in enumerate(times):
        ref = motion.inverse(pts, t)
        inside = np.ones(pts.shape[0], bool) if body is None else body(ref) > 0.5
        arg = 2 * np.pi * freq[:, None] * (ref @ dirs.T).T
        phase[:, n] = np.angle(np.exp(1j * arg)).reshape(len(tags), nz, ny, nx)
        mag[:, n] = np.where(inside, 1.0, 0.0).reshape(nz, ny, nx)
        u = motion(pts, t)
        u[~inside0] = np.nan
        truth[n] = u.T.reshape(3, nz, ny, nx)
    dims = ("tag", "time", "z", "y", "x")
    ds = xr.Dataset(
        {
            "phase": (dims, phase, standard_attrs("phase")),
            "magnitude": (dims, mag, standard_attrs("magnitude")),
            "displacement_true": (
                ("time", "axis", "z", "y", "x"),
                truth,
                standard_attrs("displacement_true"),
            ),
        },
        coords=image_coords(
            tag=list(tags),
            tag_direction=dirs,
            tag_frequency=freq,
            slice_axis=["z" if t != "z" else "y" for t in tags],
            time=times,
            z=z,
            y=y,
            x=x,
        ),
        attrs={"harpx_schema": "phase/1", "sequence": "CSPAMM", "upsample": 1, "radius": 0.5},
    )
    return ds
