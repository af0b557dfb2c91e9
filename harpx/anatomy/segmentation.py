r"""Hexahedral meshes and bodies from labelled segmentations on an image grid.

A segmentation is a label volume ``(z, y, x)`` on a uniform grid of voxel centres (mm): an
integer label per voxel (0 = background), or a tissue fraction in [0, 1] such as the
``body`` variable of a ``tagged/1`` dataset. :func:`mesh_from_labels` turns it into a
hexahedral mesh that follows the boundary:

1. **Voxel mesh at the element size.** A grid of cubes of edge ``element_size`` (mm) covers
   the foreground. Each label's fraction in a cube is the mean of its indicator, linearly
   interpolated at 3³ points of the cube; a cube belongs to the mesh when the meshed labels
   cover at least half of it and carries the label with the largest share. Only the
   largest face-connected part is kept (the rest is counted in the report).
2. **Boundary projection and smoothing.** The iso-surface is the 0.5 level of the meshed
   labels' indicator, smoothed by a Gaussian of one voxel. Boundary vertices alternate a
   Laplacian step along the surface (mean of their boundary neighbours) and a Newton step
   onto the level set, :math:`x \leftarrow x - (\phi(x) - \tfrac12)\nabla\phi/|\nabla\phi|^2`
   (each step at most half an element, the total at most one element). Interior vertices
   then relax by Laplacian smoothing with the boundary held.
3. **No inverted cells.** The scaled Jacobian of a hexahedron is the smallest, over its
   eight corners, of :math:`\det[e_1, e_2, e_3] / (|e_1||e_2||e_3|)` with :math:`e_i` the
   edges from the corner to its three neighbours (1 for a cube, ≤ 0 for an inverted
   corner). Vertices of cells below ``min_quality`` are moved back halfway towards their
   voxel positions until every cell passes; the voxel mesh itself (scaled Jacobian 1) is
   the limit, so the result is never inverted.

Regions come from the labels (one region per meshed label), and each boundary facet is
named after the label on its outer side (``"exterior"`` for background), so a mask with a
myocardium label beside a blood-pool label gives the facets facing the cavity their own
name. Further named facet sets come from predicates on facet centres and outward normals.

:func:`harpx.io.labels.read_labels` reads a label volume from a ``tagged/1`` dataset, a
NetCDF file, an :class:`xarray.DataArray` or a NIfTI file (with nibabel, an optional
dependency);
:func:`body_from_segmentation` goes straight to a :class:`~harpx.mechanics.body.Body`.

Units: mm throughout.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray
from harpx.io.labels import read_labels
from harpx.mechanics.mesh import MeshSpec, hex_mesh, labelled_spec
from harpx.mechanics.quality import MeshQuality, scaled_jacobian

__all__ = [
    "SegmentationMesh",
    "body_from_segmentation",
    "mesh_from_labels",
]

#: VTK corner offsets (x, y, z) of a hexahedron in a structured grid
_VTK_OFFSETS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
)
# sub-samples per cube edge used for the label fractions
_SUBSAMPLES = 3

FacetPredicate = Callable[[FloatArray, FloatArray], ArrayLike]


@dataclass(frozen=True)
class SegmentationMesh:
    """A mesh from a segmentation and its quality report.

    Attributes
    ----------
    spec : MeshSpec
        The mesh (mm) with regions named after the labels and named boundary facets.
    quality : MeshQuality
        The quality report.
    """

    spec: MeshSpec
    quality: MeshQuality


def _axis(values: ArrayLike, name: str) -> tuple[float, float]:
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 1 or v.size < 2:
        raise ValueError(f"coordinate {name!r} needs at least 2 voxel centres, got {v.size}")
    d = np.diff(v)
    if np.any(d <= 0) or np.ptp(d) > 1e-6 * abs(d[0]):
        raise ValueError(
            f"coordinate {name!r} is not increasing and evenly spaced (steps {d.min():.6g} .. "
            f"{d.max():.6g} mm); resample the labels onto a uniform grid"
        )
    return float(v[0]), float(d[0])


def _label_indicators(
    values: FloatArray, names: Mapping[int, str] | None
) -> tuple[list[int], FloatArray, dict[int, str]]:
    """Labels present, their indicator volumes (nlabel, z, y, x) and their names."""
    integral = values.dtype == bool or np.all(np.isclose(values, np.rint(values)))
    if not integral:
        if values.min() < 0 or values.max() > 1:
            raise ValueError(
                f"labels are neither integers nor fractions in [0, 1] (range {values.min():.3g}"
                f" .. {values.max():.3g}); pass an integer label volume or a tissue fraction"
            )
        labels, indicators = [1], values[None].astype(np.float64)
        default = {1: "body"}
    else:
        ints = np.rint(values).astype(np.int64)
        labels = [int(v) for v in np.unique(ints) if v != 0]
        indicators = np.stack([(ints == v).astype(np.float64) for v in labels])  # few labels
        default = {v: f"label_{v}" for v in labels}
    out = default | {int(k): str(v) for k, v in (names or {}).items()}
    return labels, indicators, out


def _sample(volume: FloatArray, points: FloatArray, lo: FloatArray, step: FloatArray) -> FloatArray:
    """Linear interpolation of a (z, y, x) volume at points (n, 3; x, y, z mm), 0 outside."""
    index = ((points - lo) / step)[:, ::-1]
    return ndi.map_coordinates(volume, index.T, order=1, mode="constant", cval=0.0)


def _adjacency(pairs: IntArray, n: int) -> sp.csr_matrix:
    a = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    a = ((a + a.T) > 0).astype(np.float64)
    return sp.csr_matrix(a)


def _laplacian_step(x: FloatArray, adjacency: sp.csr_matrix, movable: IntArray) -> FloatArray:
    degree = np.asarray(adjacency.sum(axis=1)).ravel()[movable]
    mean = (adjacency[movable] @ x) / np.maximum(degree, 1.0)[:, None]
    out = x.copy()
    out[movable] = np.where(degree[:, None] > 0, 0.5 * (x[movable] + mean), x[movable])
    return out


def mesh_from_labels(
    labels: Any,
    *,
    element_size: float,
    variable: str | None = None,
    names: Mapping[int, str] | None = None,
    mesh_labels: Sequence[int] | None = None,
    smoothing: int = 3,
    sigma: float = 1.0,
    min_quality: float = 0.2,
    boundaries: Mapping[str, FacetPredicate] | None = None,
    fibers: Callable[[FloatArray], ArrayLike] | None = None,
) -> SegmentationMesh:
    """Hexahedral mesh following the boundary of a labelled segmentation.

    Parameters
    ----------
    labels : xarray.Dataset, xarray.DataArray, str or os.PathLike
        The label volume (see :func:`harpx.io.labels.read_labels`): integer labels (0
        background) or a tissue fraction in [0, 1] on a uniform grid of voxel centres, mm.
    element_size : float
        Edge of the voxel-mesh cubes, mm (at least half a voxel).
    variable : str, optional
        Label variable of a dataset or NetCDF file.
    names : mapping of int to str, optional
        Region / boundary name per label; default ``"label_<k>"`` (``"body"`` for a
        fraction).
    mesh_labels : sequence of int, optional
        Labels to mesh (default all non-zero labels); the others only name the facets
        they touch.
    smoothing : int, default 3
        Boundary smoothing and projection rounds (0 keeps the voxel mesh).
    sigma : float, default 1.0
        Gaussian width of the iso-surface smoothing, in voxels.
    min_quality : float, default 0.2
        Smallest accepted scaled Jacobian (dimensionless, in (0, 1)).
    boundaries : mapping of str to callable, optional
        Extra named facet sets: ``predicate(centres, normals) -> bool`` on boundary facet
        centres (n, 3) in mm and outward unit normals (n, 3).
    fibers : callable, optional
        Fibre field ``fibers(points) -> (n, 3)`` evaluated at the cell centres (mm).

    Returns
    -------
    SegmentationMesh
        ``spec``: regions named after the meshed labels, boundary facets named after the
        label on their outer side (``"exterior"`` for background) plus ``boundaries``;
        ``quality``: the :class:`~harpx.mechanics.quality.MeshQuality` report.

    Raises
    ------
    ValueError
        If the element size, labels or quality bound are invalid, or no cube is covered.
    RuntimeError
        If a cell is inverted after all (never expected: the voxel mesh is the fallback).

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from harpx.anatomy.segmentation import mesh_from_labels
    >>> c = np.arange(-10.0, 10.5, 1.0)
    >>> Z, Y, X = np.meshgrid(c, c, c, indexing="ij")
    >>> ball = xr.DataArray((X**2 + Y**2 + Z**2 < 64).astype(int), dims=("z", "y", "x"),
    ...                     coords={"z": c, "y": c, "x": c})
    >>> result = mesh_from_labels(ball, element_size=2.0)
    >>> result.quality.inverted, sorted(result.spec.boundaries)
    (0, ['exterior'])
    """
    da = read_labels(labels, variable=variable)
    h = float(element_size)
    lo = np.array([_axis(da[d].values, d)[0] for d in ("x", "y", "z")])
    step = np.array([_axis(da[d].values, d)[1] for d in ("x", "y", "z")])
    if not (np.isfinite(h) and h >= 0.5 * step.min()):
        raise ValueError(
            f"element_size={element_size!r} mm must be at least half a voxel "
            f"({0.5 * step.min():.3g} mm)"
        )
    if not 0.0 < min_quality < 1.0:
        raise ValueError(f"min_quality={min_quality!r} must lie in (0, 1)")
    values = np.asarray(da.values)
    if not np.all(np.isfinite(values)):
        raise ValueError("labels contain NaN or inf; fill them (e.g. labels.fillna(0))")
    present, indicators, label_names = _label_indicators(values, names)
    meshed = list(present) if mesh_labels is None else [int(v) for v in mesh_labels]
    missing = sorted(set(meshed) - set(present))
    if missing or not meshed:
        raise ValueError(
            f"mesh_labels={mesh_labels!r}: labels {missing!r} are not in the volume "
            f"(present: {present!r})"
        )
    is_meshed = np.isin(present, meshed)
    foreground = indicators[is_meshed].sum(axis=0)

    # 1. cubes over the bounding box of the meshed labels, one cube of margin
    where = np.argwhere(foreground > 0)[:, ::-1]  # (n, 3) voxel indices as (x, y, z)
    if where.size == 0:
        raise ValueError(f"labels {meshed!r} cover no voxel; nothing to mesh")
    box_lo = lo + (where.min(axis=0) - 0.5) * step
    box_hi = lo + (where.max(axis=0) + 0.5) * step
    n = np.ceil((box_hi - box_lo) / h - 1e-9).astype(np.int64) + 2  # cubes per axis (x, y, z)
    origin = 0.5 * (box_lo + box_hi) - 0.5 * n * h
    s = _SUBSAMPLES
    sub = (np.arange(s) + 0.5) / s
    k, j, i = np.meshgrid(*(np.arange(m) for m in n[::-1]), indexing="ij")
    corner = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1).astype(np.float64)
    sz, sy, sx = np.meshgrid(sub, sub, sub, indexing="ij")
    offsets = np.stack([sx.ravel(), sy.ravel(), sz.ravel()], axis=1)
    samples = (origin + h * (corner[:, None, :] + offsets[None])).reshape(-1, 3)
    fractions = np.stack(
        [
            _sample(ind, samples, lo, step).reshape(len(corner), -1).mean(axis=1)
            for ind in indicators
        ]
    )  # (nlabel, ncube), one pass per label
    active = fractions[is_meshed].sum(axis=0) >= 0.5
    components, count = ndi.label(active.reshape(tuple(n[::-1])))
    if count == 0:
        raise ValueError(
            f"no cube of {h:g} mm is at least half covered by labels {meshed!r}; choose a "
            "smaller element_size"
        )
    sizes = np.bincount(components.ravel())[1:]
    keep = components.ravel() == 1 + int(np.argmax(sizes))
    dropped = int(active.sum() - keep.sum())
    cube_ids = np.nonzero(keep)[0]
    cube_ijk = corner[cube_ids].astype(np.int64)  # (ncell, 3) as (x, y, z)
    meshed_ids = np.nonzero(is_meshed)[0]
    cell_label = np.asarray(present)[meshed_ids[np.argmax(fractions[meshed_ids][:, cube_ids], 0)]]

    # 2. vertices and VTK hexahedra
    corners = cube_ijk[:, None, :] + _VTK_OFFSETS[None]  # (ncell, 8, 3)
    flat = (corners[..., 2] * (n[1] + 1) + corners[..., 1]) * (n[0] + 1) + corners[..., 0]
    used, cells = np.unique(flat.ravel(), return_inverse=True)
    cells = cells.reshape(-1, 8)
    vi = np.stack(
        [used % (n[0] + 1), (used // (n[0] + 1)) % (n[1] + 1), used // ((n[0] + 1) * (n[1] + 1))],
        axis=1,
    )
    voxel_points = origin + h * vi
    mesh = hex_mesh(voxel_points, cells)
    bfacets = mesh.boundary_facets()
    fverts = mesh.facets[:, bfacets].T  # (nb, 4)
    bverts = np.unique(fverts)

    # level set and its gradient on the image grid
    phi = ndi.gaussian_filter(np.clip(foreground, 0.0, 1.0), sigma=float(sigma), mode="constant")
    grad = np.gradient(phi, *step[::-1])  # d/dz, d/dy, d/dx

    def level(p: FloatArray) -> tuple[FloatArray, FloatArray]:
        g = np.stack([_sample(grad[2 - a], p, lo, step) for a in range(3)], axis=1)
        return _sample(phi, p, lo, step) - 0.5, g

    # boundary graph: facet sides (vertex pairs differing along one axis)
    a_idx, b_idx = np.triu_indices(4, 1)
    pa, pb = fverts[:, a_idx].ravel(), fverts[:, b_idx].ravel()
    side = np.count_nonzero(vi[pa] != vi[pb], axis=1) == 1
    npts = len(voxel_points)
    boundary_graph = _adjacency(np.column_stack([pa[side], pb[side]]), npts)
    edges = mesh.edges.T.astype(np.int64)
    full_graph = _adjacency(edges, npts)
    interior = np.setdiff1d(np.arange(npts), bverts)

    x = voxel_points.copy()
    for _ in range(int(smoothing)):  # a few smoothing + projection rounds
        x = _laplacian_step(x, boundary_graph, bverts)
        for _newton in range(2):
            value, g = level(x[bverts])
            g2 = np.einsum("ni,ni->n", g, g)
            ok = g2 > 1e-12
            delta = np.where(ok[:, None], -value[:, None] * g / np.where(ok, g2, 1.0)[:, None], 0)
            length = np.linalg.norm(delta, axis=1, keepdims=True)
            delta *= np.minimum(1.0, 0.5 * h / np.maximum(length, 1e-300))
            x[bverts] += delta
        offset = x - voxel_points
        length = np.linalg.norm(offset, axis=1, keepdims=True)
        x = voxel_points + offset * np.minimum(1.0, h / np.maximum(length, 1e-300))
    if smoothing:
        for _ in range(2 * int(smoothing)):
            x = _laplacian_step(x, full_graph, interior)

    # 3. quality: pull vertices of poor cells back towards the voxel mesh
    restored = np.zeros(npts, dtype=bool)
    for _ in range(40):  # geometric: each round halves the offsets of the poor cells
        quality = scaled_jacobian(x, cells)
        bad = quality < min_quality
        if not bad.any():
            break
        verts = np.unique(cells[bad])
        restored[verts] = True
        x[verts] = voxel_points[verts] + 0.5 * (x[verts] - voxel_points[verts])
    else:
        x = voxel_points.copy()
        restored[:] = True
    quality = scaled_jacobian(x, cells)
    if np.any(quality <= 0):  # pragma: no cover - the voxel mesh is the fallback
        raise RuntimeError(f"{int((quality <= 0).sum())} inverted cells after smoothing")
    value, g = level(x[bverts])
    far = np.abs(value) / np.maximum(np.linalg.norm(g, axis=1), 1e-12)
    mesh = hex_mesh(x, cells)

    # names: regions from labels, facets from the label on their outer side
    regions = {
        label_names[int(v)]: np.nonzero(cell_label == v)[0].astype(np.int64)
        for v in meshed
        if np.any(cell_label == v)
    }
    owner = mesh.f2t[0, bfacets]
    fcentre_voxel = voxel_points[fverts].mean(axis=1)
    cube_centre = origin + h * (cube_ijk[owner] + 0.5)
    outward = np.rint(2.0 * (fcentre_voxel - cube_centre) / h).astype(np.int64)
    nb_ijk = cube_ijk[owner] + outward
    nb_flat = (nb_ijk[:, 2] * n[1] + nb_ijk[:, 1]) * n[0] + nb_ijk[:, 0]
    nb_frac = fractions[:, nb_flat]  # (nlabel, nb)
    background = 1.0 - nb_frac.sum(axis=0)
    winner = np.argmax(np.vstack([background[None], nb_frac]), axis=0) - 1
    outer = np.where(winner >= 0, np.asarray(present)[np.maximum(winner, 0)], 0)
    outer = np.where(np.isin(outer, meshed), 0, outer)
    named: dict[str, IntArray] = {}
    for v in np.unique(outer):  # a few neighbouring labels
        name = "exterior" if v == 0 else label_names[int(v)]
        named[name] = np.sort(bfacets[outer == v]).astype(np.int64)
    if boundaries:
        centres = x[fverts].mean(axis=1)
        _, gc = level(centres)
        normals = -gc / np.maximum(np.linalg.norm(gc, axis=1, keepdims=True), 1e-12)
        for name, predicate in boundaries.items():
            hit = np.asarray(predicate(centres, normals), dtype=bool)
            named[name] = np.sort(bfacets[hit]).astype(np.int64)
    cell_fibers = None
    if fibers is not None:
        cell_fibers = np.asarray(fibers(x[cells].mean(axis=1)), dtype=np.float64)
    spec = labelled_spec(mesh, regions, named, cell_fibers)
    report = MeshQuality(
        cells=len(cells),
        min_scaled_jacobian=float(quality.min()),
        mean_scaled_jacobian=float(quality.mean()),
        inverted=int(np.count_nonzero(quality <= 0)),
        dropped_cells=dropped,
        max_boundary_offset=float(far.max()) if smoothing else float("nan"),
        restored_vertices=int(restored.sum()),
    )
    return SegmentationMesh(spec, report)


def body_from_segmentation(
    labels: Any, material: Any, *, element_size: float, **options: Any
) -> Any:
    """A :class:`~harpx.mechanics.body.Body` meshed from a labelled segmentation.

    Parameters
    ----------
    labels : xarray.Dataset, xarray.DataArray, str or os.PathLike
        The segmentation (see :func:`mesh_from_labels`).
    material : object
        Material of the body (e.g. :class:`~harpx.mechanics.materials.NeoHookean`).
    element_size : float
        Element edge length, mm.
    **options
        Keywords of :func:`mesh_from_labels` (``variable``, ``names``, ``mesh_labels``,
        ``smoothing``, ``sigma``, ``min_quality``, ``boundaries``, ``fibers``); the rest go
        to :class:`~harpx.mechanics.body.Body` (``element``, ``active``, ...).

    Returns
    -------
    Body
        hex8 (or hex20) body; the quality report is checked (no inverted cell) and kept
        as ``body.mesh_quality``.
    """
    from harpx.mechanics.body import Body

    mesh_keys = {"variable", "names", "mesh_labels", "smoothing", "sigma", "min_quality",
                 "boundaries", "fibers"}  # fmt: skip
    mesh_options = {k: v for k, v in options.items() if k in mesh_keys}
    body_options = {k: v for k, v in options.items() if k not in mesh_keys}
    result = mesh_from_labels(labels, element_size=element_size, **mesh_options)
    body = Body(result.spec, material, **body_options)
    body.mesh_quality = result.quality
    return body


def __getattr__(name: str) -> Any:
    from harpx._moved import moved_attribute

    return moved_attribute(__name__, name)
