r"""Strain in the ventricle's local frame, AHA 17 segments, twist and torsion.

Local frame
-----------
At every point of the wall the fitted template (:class:`~harpx.anatomy.ventricle_fit.
VentricleTemplate`) gives the circumferential direction :math:`e_c` (counter-clockwise
about the long axis, which points from the apex to the base), the longitudinal direction
:math:`e_l` (the meridian of the ellipsoidal layer through the point, apex to base) and the
radial direction :math:`e_r = e_c \times e_l` (the outward layer normal). The normal
Green–Lagrange strains are :math:`E_{aa} = e_a \cdot E\, e_a` with
:math:`E = \tfrac12 (F^T F - I)`, and the engineering (stretch) strains
:math:`\varepsilon_{aa} = \sqrt{1 + 2 E_{aa}} - 1` (the relative change of length of a
reference line element along :math:`e_a`), both dimensionless.

AHA 17 segments
---------------
Cerqueira et al. (2002): the cavity, from the endocardial apex :math:`z = -c_{endo}` to the
base plane (template coordinates), is cut into basal, mid and apical thirds of equal length;
the myocardium below the endocardial apex is segment 17 (apex). Basal (1–6) and mid (7–12)
rings have six 60° sectors and the apical ring (13–16) four 90° sectors, numbered
counter-clockwise about the long axis from the angle ``anterior`` (degrees from the
template's +x axis; in a real heart the anterior right-ventricular insertion; the template
has no right ventricle, so the caller sets it): basal and mid sector k spans
``anterior + 60° (k-1) .. anterior + 60° k``, apical sector k is centred on
``anterior + 90° (k-1)``. Segment values are volume-weighted means
over the cells (or voxels) whose centre lies in the segment.

Rotation, twist, torsion
------------------------
The rotation of a material point is the angle, in the short-axis plane, between its
reference and current position vectors from the long axis; its sign follows the cardiac
convention: positive counter-clockwise *seen from the apex* (that is, a negative rotation
about the apex-to-base axis). Level rotations are volume-weighted means over the basal
(1–6) and apical (13–16) segments; twist is apical minus basal rotation (degrees) and
torsion the twist divided by the reference distance between the two levels' centroids
along the axis (degrees/mm).

References
----------
.. [1] Cerqueira MD et al. Standardized myocardial segmentation and nomenclature for
   tomographic imaging of the heart. Circulation 105:539--542, 2002.
.. [2] Russel IK et al. Left ventricular torsion: an expanding role in the analysis of
   myocardial dysfunction. JACC Cardiovasc Imaging 2:648--655, 2009.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray

__all__ = [
    "AHA_NAMES",
    "COMPONENTS",
    "aha_segments",
    "cardiac_strain",
    "lv_measures",
]

#: names of the 17 AHA segments, index k-1 for segment k
AHA_NAMES = (
    "basal anterior", "basal anteroseptal", "basal inferoseptal", "basal inferior",
    "basal inferolateral", "basal anterolateral", "mid anterior", "mid anteroseptal",
    "mid inferoseptal", "mid inferior", "mid inferolateral", "mid anterolateral",
    "apical anterior", "apical septal", "apical inferior", "apical lateral", "apex",
)  # fmt: skip
#: the normal strain components in the local frame
COMPONENTS = ("radial", "circumferential", "longitudinal")
# trilinear corner signs (VTK order) for the cell-centre Jacobian of a hexahedron
_SIGNS = (
    2.0
    * np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
        dtype=np.float64,
    )
    - 1.0
)


def aha_segments(points: ArrayLike, template: Any, *, anterior: float = 0.0) -> IntArray:
    """AHA segment (1–17) of wall points.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Image points in mm (in the wall).
    template : VentricleTemplate
        The fitted ventricle.
    anterior : float, default 0
        Angle (degrees, about the long axis from the template's +x axis) where segment 1
        starts.

    Returns
    -------
    ndarray of int, shape (n,)
        Segment numbers 1..17 (points above the base plane count as basal).

    Examples
    --------
    >>> from harpx.anatomy.ventricle import VentricleGeometry
    >>> from harpx.anatomy.ventricle_fit import VentricleTemplate
    >>> from harpx.cardiac.strain import aha_segments
    >>> t = VentricleTemplate(VentricleGeometry((25.0, 70.0), (35.0, 78.0), 10.0))
    >>> aha_segments([[30.0, 1.0, 0.0], [-1.0, -30.0, -40.0], [0.0, 0.0, -74.0]], t).tolist()
    [1, 11, 17]
    """
    q = template.to_local(points)
    g = template.geometry
    bottom, top = -g.inner[1], g.truncation
    third = (top - bottom) / 3.0
    angle = np.mod(np.arctan2(q[:, 1], q[:, 0]) - np.deg2rad(anterior), 2.0 * np.pi)
    six = np.floor(angle / (np.pi / 3.0)).astype(np.int64) % 6
    four = np.floor(np.mod(angle + np.pi / 4.0, 2.0 * np.pi) / (np.pi / 2.0)).astype(np.int64) % 4
    z = q[:, 2]
    return np.select(
        [z < bottom, z < bottom + third, z < bottom + 2.0 * third],
        [17, 13 + four, 7 + six],
        default=1 + six,
    ).astype(np.int64)


def _local_strain(E: FloatArray, basis: tuple[FloatArray, ...]) -> FloatArray:
    """Normal components (..., n, 3) of strains E (..., n, 3, 3) along (e_r, e_c, e_l)."""
    frame = np.stack(basis, axis=-1)  # (n, 3 axis, 3 component)
    return np.einsum("nia,...nij,nja->...na", frame, E, frame)


def _rotation(reference: FloatArray, current: FloatArray, template: Any) -> FloatArray:
    """Cardiac rotation (degrees, counter-clockwise seen from the apex), (time, n)."""
    q0 = template.to_local(reference)
    q = np.stack([template.to_local(c) for c in current])  # a few frames
    cross = q0[None, :, 0] * q[..., 1] - q0[None, :, 1] * q[..., 0]
    dot = q0[None, :, 0] * q[..., 0] + q0[None, :, 1] * q[..., 1]
    return -np.rad2deg(np.arctan2(cross, dot))


def lv_measures(
    points: ArrayLike,
    green_strain: ArrayLike,
    current: ArrayLike,
    weights: ArrayLike,
    template: Any,
    *,
    time: ArrayLike,
    anterior: float = 0.0,
) -> xr.Dataset:
    """Segment strains, peaks, rotations, twist and torsion from strains at wall points.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Reference positions (cell centres or voxel centres), mm.
    green_strain : array_like, shape (ntime, n, 3, 3)
        Green–Lagrange strain at the points (dimensionless); NaN points are left out.
    current : array_like, shape (ntime, n, 3)
        Current positions of the points, mm.
    weights : array_like, shape (n,)
        Volume of each point, mm³.
    template : VentricleTemplate
        The fitted ventricle (local frame and segments).
    time : array_like, shape (ntime,)
        Frame times, ms.
    anterior : float, default 0
        Start angle of segment 1, degrees (see :func:`aha_segments`).

    Returns
    -------
    xarray.Dataset
        ``segment_strain`` and ``segment_engineering_strain`` (time, segment, component);
        ``peak_strain`` and ``peak_engineering_strain`` (segment, component): the signed
        value of largest magnitude over the frames, with ``peak_time`` (ms);
        ``segment_volume`` (segment, mm³); ``rotation`` (time, level) in degrees for the
        ``"base"`` and ``"apex"`` levels, ``twist`` (time, degrees) and ``torsion``
        (time, degrees/mm); coordinates ``segment`` (1..17), ``segment_name``,
        ``component`` (radial, circumferential, longitudinal).
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    E = np.asarray(green_strain, dtype=np.float64)
    x = np.asarray(current, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    times = np.asarray(time, dtype=np.float64)
    segment = aha_segments(p, template, anterior=anterior)
    local = _local_strain(E, template.local_basis(p))  # (time, n, 3)
    engineering = np.sqrt(np.maximum(1.0 + 2.0 * local, 0.0)) - 1.0
    valid = np.all(np.isfinite(local), axis=(0, 2)) & np.all(np.isfinite(x), axis=(0, 2))
    onehot = (segment[:, None] == np.arange(1, 18)[None, :]) & valid[:, None]  # (n, 17)
    wseg = onehot * w[:, None]
    volume = wseg.sum(axis=0)
    norm = np.where(volume > 0, volume, np.nan)

    def by_segment(values: FloatArray) -> FloatArray:
        return (
            np.einsum("tnc,ns->tsc", np.where(valid[None, :, None], values, 0.0), wseg)
            / norm[None, :, None]
        )

    seg = by_segment(local)
    seg_eng = by_segment(engineering)

    def peak(values: FloatArray) -> tuple[FloatArray, FloatArray]:
        filled = np.where(np.isfinite(values), np.abs(values), -1.0)
        k = np.argmax(filled, axis=0)  # (segment, component)
        return np.take_along_axis(values, k[None], axis=0)[0], times[k]

    peak_e, peak_t = peak(seg)
    peak_eng, _ = peak(seg_eng)
    rot = _rotation(p, x, template)
    levels = {"base": (segment <= 6) & valid, "apex": (segment >= 13) & (segment <= 16) & valid}
    level_rot = np.stack(
        [
            (rot[:, m] * w[m]).sum(axis=1) / w[m].sum() if m.any() else np.full(len(times), np.nan)
            for m in levels.values()
        ],
        axis=1,
    )  # two levels
    zq = template.to_local(p)[:, 2]
    height = [
        float((zq[m] * w[m]).sum() / w[m].sum()) if m.any() else np.nan for m in levels.values()
    ]
    distance = height[0] - height[1]
    twist = level_rot[:, 1] - level_rot[:, 0]
    seg_coords = {
        "segment": ("segment", np.arange(1, 18), {"long_name": "AHA segment", "units": "1"}),
        "segment_name": ("segment", np.array(AHA_NAMES, dtype=str), {"long_name": "AHA name"}),
        "component": ("component", np.array(COMPONENTS, dtype=str), {"long_name": "direction"}),
        "level": ("level", np.array(list(levels), dtype=str), {"long_name": "short-axis level"}),
        "time": ("time", times, {"units": "ms", "long_name": "time"}),
    }
    out = xr.Dataset(coords=seg_coords)
    dims3 = ("time", "segment", "component")

    def var(data: Any, dims: tuple[str, ...], units: str, long_name: str) -> xr.DataArray:
        return xr.DataArray(data, dims=dims, attrs={"units": units, "long_name": long_name})

    out["segment_strain"] = var(seg, dims3, "1", "segment mean Green-Lagrange strain")
    out["segment_engineering_strain"] = var(
        seg_eng, dims3, "1", "segment mean engineering strain (stretch - 1)"
    )
    out["peak_strain"] = var(
        peak_e, ("segment", "component"), "1", "peak segment Green-Lagrange strain"
    )
    out["peak_engineering_strain"] = var(
        peak_eng, ("segment", "component"), "1", "peak segment engineering strain"
    )
    out["peak_time"] = var(peak_t, ("segment", "component"), "ms", "time of peak strain")
    out["segment_volume"] = var(volume, ("segment",), "mm3", "reference volume of segment")
    out["rotation"] = var(
        level_rot, ("time", "level"), "degree", "rotation, counter-clockwise seen from apex"
    )
    out["twist"] = var(twist, ("time",), "degree", "apical minus basal rotation")
    out["torsion"] = var(
        twist / distance if np.isfinite(distance) and distance > 0 else twist * np.nan,
        ("time",),
        "degree/mm",
        "twist per base-apex distance",
    )
    out["torsion"].attrs["level_distance_mm"] = distance
    out.attrs["anterior_deg"] = float(anterior)
    return out


def _cell_weights(points: FloatArray, cells: IntArray) -> FloatArray:
    """Volume estimate |det J(centre)|·8 of hexahedra from their 8 corner vertices, mm³."""
    x = points[cells[:, :8]]
    d = np.einsum("nai,aj->nij", x, _SIGNS) / 4.0
    return np.abs(np.linalg.det(d))


def _grid_strain(u: xr.DataArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Voxel centres (n, 3), Green strain (time, n, 3, 3), current positions (time, n, 3)."""
    u = u.transpose("time", "axis", "z", "y", "x")
    data = np.asarray(u.values, dtype=np.float64)
    z, y, x = (np.asarray(u[d].values, dtype=np.float64) for d in ("z", "y", "x"))
    # du_i/dX_j by central differences on the grid (NaN next to missing voxels)
    d = np.gradient(data, z, y, x, axis=(2, 3, 4))  # list over (z, y, x)
    grad = np.stack([d[2], d[1], d[0]], axis=2)  # (time, i, j=x,y,z, z, y, x)
    nt = data.shape[0]
    grad = grad.reshape(nt, 3, 3, -1).transpose(0, 3, 1, 2)  # (time, n, i, j)
    F = grad + np.eye(3)
    E = 0.5 * (np.einsum("tnki,tnkj->tnij", F, F) - np.eye(3))
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    disp = data.reshape(nt, 3, -1).transpose(0, 2, 1)
    return pts, E, pts[None] + disp


def cardiac_strain(
    tracked: xr.Dataset,
    template: Any,
    *,
    anterior: float = 0.0,
    body: xr.DataArray | None = None,
) -> xr.Dataset:
    """Local-frame strain, AHA segment curves and peaks, twist and torsion of a result.

    Parameters
    ----------
    tracked : xarray.Dataset
        A finite-element ``tracked/1`` dataset (``points``, ``cells``, ``displacement``,
        ``green_strain``), or any dataset with a displacement on the image grid
        (``displacement_grid`` of conventional HARP, or the ``displacement_true`` of a
        synthetic ``tagged/1`` dataset), whose strain is then taken by central differences
        between voxel centres.
    template : VentricleTemplate
        The fitted ventricle: local frame, segments and long axis (e.g.
        ``fit_ventricle_to_mask(tagged).template``).
    anterior : float, default 0
        Start angle of segment 1 in degrees about the long axis from the template's +x
        axis (see :func:`aha_segments`).
    body : xarray.DataArray, optional
        For grid displacements: the voxels to use (``body >= 0.5``), default the
        ``body`` variable of the dataset when present, else every finite voxel.

    Returns
    -------
    xarray.Dataset
        ``tracked`` with the variables of :func:`lv_measures` added, plus, for a
        finite-element result, ``strain_lv`` and ``engineering_strain_lv`` (time, cell,
        component) and ``aha_segment`` (cell); for a grid result ``aha_segment_grid``
        (z, y, x, 0 outside the voxels used).

    Raises
    ------
    ValueError
        If the dataset holds neither a finite-element result nor a grid displacement.
    """
    if "time" not in tracked.coords:
        raise ValueError(
            "cardiac_strain needs a finite-element tracked/1 dataset or a grid displacement "
            "with a 'time' coordinate (ms); this dataset has none"
        )
    times = np.asarray(tracked["time"].values, dtype=np.float64)
    fe = (
        {"points", "cells", "displacement", "green_strain"} <= set(tracked.variables)
        and tracked["cells"].attrs.get("element", "hex8") != "points"
        and tracked.sizes.get("cell", 0) > 0
    )
    if fe:
        pts = np.asarray(tracked["points"].values, dtype=np.float64)
        cells = np.asarray(tracked["cells"].values, dtype=np.int64)
        disp = np.asarray(tracked["displacement"].transpose("time", "node", "axis").values)
        centres = pts[cells[:, :8]].mean(axis=1)
        current = (pts[None] + disp)[:, cells[:, :8]].mean(axis=2)
        E = np.asarray(tracked["green_strain"].transpose("time", "cell", "i", "j").values)
        measures = lv_measures(
            centres, E, current, _cell_weights(pts, cells), template, time=times,
            anterior=anterior,
        )  # fmt: skip
        local = _local_strain(E, template.local_basis(centres))
        dims = ("time", "cell", "component")
        out = tracked.assign_coords(measures.coords).assign(measures.data_vars)
        out["strain_lv"] = xr.DataArray(
            local, dims=dims,
            attrs={"units": "1", "long_name": "Green-Lagrange strain in the LV frame"},
        )  # fmt: skip
        out["engineering_strain_lv"] = xr.DataArray(
            np.sqrt(np.maximum(1.0 + 2.0 * local, 0.0)) - 1.0, dims=dims,
            attrs={"units": "1", "long_name": "engineering strain in the LV frame"},
        )  # fmt: skip
        out["aha_segment"] = xr.DataArray(
            aha_segments(centres, template, anterior=anterior), dims="cell",
            attrs={"units": "1", "long_name": "AHA segment"},
        )  # fmt: skip
        return out
    name = next((n for n in ("displacement_grid", "displacement_true") if n in tracked), None)
    if name is None:
        raise ValueError(
            "cardiac_strain needs a finite-element tracked/1 dataset (points, cells, "
            "displacement, green_strain) or a grid displacement ('displacement_grid' or "
            f"'displacement_true'); got variables {sorted(map(str, tracked.data_vars))!r}"
        )
    u = tracked[name]
    pts, E, current = _grid_strain(u)
    if body is None and "body" in tracked:
        body = tracked["body"]
    use = np.ones(len(pts), dtype=bool)
    if body is not None:
        use = np.asarray(body.transpose("z", "y", "x").values >= 0.5).ravel()
    finite = use & np.all(np.isfinite(E), axis=(0, 2, 3))
    spacing = [float(np.diff(u[d].values).mean()) for d in ("x", "y", "z")]
    measures = lv_measures(
        pts[finite], E[:, finite], current[:, finite],
        np.full(int(finite.sum()), float(np.prod(spacing))), template,
        time=times, anterior=anterior,
    )  # fmt: skip
    seg = np.zeros(len(pts), dtype=np.int64)
    seg[finite] = aha_segments(pts[finite], template, anterior=anterior)
    out = tracked.assign_coords(measures.drop_vars("time").coords).assign(measures.data_vars)
    shape = tuple(u.sizes[d] for d in ("z", "y", "x"))
    out["aha_segment_grid"] = xr.DataArray(
        seg.reshape(shape), dims=("z", "y", "x"),
        attrs={"units": "1", "long_name": "AHA segment of voxels used (0: none)"},
    )  # fmt: skip
    return out
