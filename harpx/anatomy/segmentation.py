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
This module checks the input, its memory need and names the result; the three steps are in
:mod:`harpx.anatomy.voxel_mesh`.

Units: mm throughout.
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from harpx._moved import moved_getattr
from harpx._typing import FloatArray, IntArray
from harpx.anatomy.voxel_mesh import (
    _cubes,
    _LevelSet,
    _outer_labels,
    _smoothed,
    _surface_distance,
    _voxel_mesh,
    _with_quality,
)
from harpx.errors import HarpxError, HarpxWarning, user_stacklevel
from harpx.io.labels import read_labels
from harpx.mechanics.mesh import MeshSpec, hex_mesh, labelled_spec
from harpx.mechanics.quality import MeshQuality

__all__ = [
    "MAX_BYTES",
    "MAX_LABELS",
    "SegmentationError",
    "SegmentationMesh",
    "body_from_segmentation",
    "mesh_from_labels",
]

#: Default largest number of distinct labels handled at once (a segmentation has a few; an
#: intensity image passed as labels has thousands).
MAX_LABELS = 64
#: Default memory budget (bytes) of one :func:`mesh_from_labels` call, checked beforehand.
MAX_BYTES = 4 * 2**30
# memory estimate (bytes): per voxel of the padded volume and label (indicators, level set,
# gradient, distance transforms), per cube of the bounding box (label fractions, cube
# bookkeeping) and per cell of the mesh (vertices, skfem connectivity, smoothing graphs,
# quality arrays); upper bounds of tracemalloc peaks on balls and shells
_BYTES_PER_VOXEL = 8 * 8
_BYTES_PER_VOXEL_LABEL = 8
_BYTES_PER_BOX_CUBE = 24
_BYTES_PER_BOX_CUBE_LABEL = 8
_BYTES_PER_CELL = 5000

FacetPredicate = Callable[[FloatArray, FloatArray], ArrayLike]


class SegmentationError(HarpxError, ValueError):
    """A label volume that cannot be meshed as asked.

    Raised for a volume without foreground, one that is not a segmentation (implausibly many
    distinct labels, e.g. an intensity image) and a mesh whose estimated memory exceeds the
    budget; the message states the numbers and what to change.
    """


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


def _labels_present(values: Any) -> tuple[bool, list[int]]:
    """Whether ``values`` are integer labels, and the non-zero labels (``[1]`` for a fraction)."""
    integral = values.dtype == bool or bool(np.all(np.isclose(values, np.rint(values))))
    if not integral:
        if values.min() < 0 or values.max() > 1:
            raise ValueError(
                f"labels are neither integers nor fractions in [0, 1] (range {values.min():.3g}"
                f" .. {values.max():.3g}); pass an integer label volume or a tissue fraction"
            )
        return False, [1] if values.max() > 0 else []
    labels = np.unique(np.rint(values).astype(np.int64))
    return True, [int(v) for v in labels if v != 0]


def _padded(values: Any, first: IntArray, last: IntArray) -> FloatArray:
    """Voxels ``first .. last`` (inclusive, (z, y, x) indices) of a volume, 0 beyond it."""
    shape = np.asarray(values.shape)
    a, b = np.maximum(first, 0), np.minimum(last, shape - 1)
    inner = np.asarray(values[a[0] : b[0] + 1, a[1] : b[1] + 1, a[2] : b[2] + 1], dtype=np.float64)
    pad = [(int(a[k] - first[k]), int(last[k] - b[k])) for k in range(3)]
    return np.pad(inner, pad, mode="constant", constant_values=0.0)


def _margin(h: float, step_zyx: FloatArray, sigma: float) -> IntArray:
    """Background voxels kept or padded around the meshed labels, per (z, y, x) axis.

    Cubes reach 1.5 elements beyond the voxels and vertices move up to one more; the
    Gaussian reaches 4 sigma.
    """
    return np.ceil(3.0 * h / step_zyx).astype(np.int64) + int(np.ceil(4.0 * sigma)) + 2


def _estimate(
    h: float, extent: IntArray, step_zyx: FloatArray, sigma: float, nlabel: int, volume: float
) -> tuple[float, float, float]:
    """Estimated bytes, box cubes and cells of a mesh at element size ``h`` (mm).

    ``extent`` is the meshed labels' bounding box in voxels (z, y, x) and ``volume`` their
    tissue volume, mm³.
    """
    voxels = float(np.prod((extent + 2 * _margin(h, step_zyx, sigma)).astype(np.float64)))
    n = np.ceil(extent * step_zyx / h - 1e-9) + 2
    box = float(np.prod(n))
    cells = volume / h**3
    needed = voxels * (_BYTES_PER_VOXEL + nlabel * _BYTES_PER_VOXEL_LABEL)
    needed += box * (_BYTES_PER_BOX_CUBE + nlabel * _BYTES_PER_BOX_CUBE_LABEL)
    return needed + cells * _BYTES_PER_CELL, box, cells


def _check_size(
    h: float,
    extent: IntArray,
    step_zyx: FloatArray,
    sigma: float,
    nlabel: int,
    volume: float,
    max_bytes: float,
) -> None:
    """Refuse a mesh whose estimated memory exceeds ``max_bytes``, naming a safe size."""
    needed, box, cells = _estimate(h, extent, step_zyx, sigma, nlabel, volume)
    if needed <= max_bytes:
        return
    sizes = h * 1.02 ** np.arange(1, 400)  # up to 2700 h, 2 % apart
    fits = [
        float(v)
        for v in sizes
        if _estimate(v, extent, step_zyx, sigma, nlabel, volume)[0] <= max_bytes
    ]
    if not fits:
        raise SegmentationError(
            f"the labelled volume ({int(np.prod(extent))} voxels around the tissue, {nlabel} "
            f"labels) needs more than max_bytes={max_bytes / 2**30:.3g} GiB at any element "
            "size; crop or downsample the labels (or raise max_bytes)"
        )
    raise SegmentationError(
        f"element_size={h:g} mm gives about {cells:.3g} cells in a box of {box:.3g} cubes and "
        f"needs about {needed / 2**30:.3g} GiB (more than max_bytes={max_bytes / 2**30:.3g} "
        f"GiB); choose element_size >= {np.ceil(fits[0] * 100.0) / 100.0:.3g} mm (or raise "
        "max_bytes)"
    )


def _labels_to_mesh(
    da: Any, values: Any, mesh_labels: Sequence[int] | None, max_labels: int
) -> tuple[bool, list[int], list[int]]:
    """Whether the volume holds integer labels, its non-zero labels and those to mesh;
    refuses NaN, an empty volume, an intensity image and labels that are not there."""
    if not np.all(np.isfinite(values)):
        raise ValueError("labels contain NaN or inf; fill them (e.g. labels.fillna(0))")
    integral, present = _labels_present(values)
    if not present:
        raise SegmentationError(
            f"labels {getattr(da, 'name', None) or ''!s} of shape {values.shape} hold no "
            "foreground (every voxel is 0); pass the segmentation, not an empty mask"
        )
    if mesh_labels is None and len(present) > max_labels:
        raise SegmentationError(
            f"labels hold {len(present)} distinct non-zero values (more than max_labels="
            f"{max_labels}), which looks like an intensity image rather than a segmentation; "
            "pass an integer label volume, or mesh_labels=[...] to mesh only some labels"
        )
    meshed = list(present) if mesh_labels is None else [int(v) for v in mesh_labels]
    missing = sorted(set(meshed) - set(present))
    if missing or not meshed:
        raise ValueError(
            f"mesh_labels={mesh_labels!r}: labels {missing!r} are not in the volume "
            f"(present: {present[:20]!r}{' ...' if len(present) > 20 else ''})"
        )
    return integral, present, meshed


def _predicate_facets(
    boundaries: Mapping[str, FacetPredicate],
    centres: FloatArray,
    level: _LevelSet,
    bfacets: IntArray,
) -> dict[str, IntArray]:
    """The facets each predicate of ``boundaries`` selects from its facet centres (mm) and
    outward normals (of the level set); warns about a predicate that selects none."""
    _, gc = level(centres)
    normals = -gc / np.maximum(np.linalg.norm(gc, axis=1, keepdims=True), 1e-12)
    named: dict[str, IntArray] = {}
    for name, predicate in boundaries.items():
        hit = np.asarray(predicate(centres, normals), dtype=bool)
        named[name] = np.sort(bfacets[hit]).astype(np.int64)
        if not hit.any():
            warnings.warn(
                f"boundary {name!r} selects none of the {len(bfacets)} boundary facets "
                "(its predicate is False everywhere); a load or condition on it would act "
                "on nothing: check the predicate (e.g. the template's base plane against "
                "the extent of the mask)",
                HarpxWarning,
                stacklevel=user_stacklevel(),
            )
    return named


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
    max_labels: int = MAX_LABELS,
    max_bytes: float = MAX_BYTES,
) -> SegmentationMesh:
    r"""Hexahedral mesh following the boundary of a labelled segmentation.

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
    max_labels : int, default :data:`MAX_LABELS`
        Largest number of distinct non-zero labels handled (all labels without
        ``mesh_labels``; the meshed labels and those beside them with it): each costs one
        indicator volume and one sampling pass.
    max_bytes : float, default :data:`MAX_BYTES`
        Memory budget in bytes; the need is estimated before anything large is allocated,
        from the cubes of the bounding box and the expected cell count (tissue volume /
        ``element_size`` cubed).

    Returns
    -------
    SegmentationMesh
        ``spec``: regions named after the meshed labels, boundary facets named after the
        label on their outer side (``"exterior"`` for background) plus ``boundaries``;
        ``quality``: the :class:`~harpx.mechanics.quality.MeshQuality` report, whose
        ``max_boundary_offset`` (mm) is the largest distance of a boundary vertex from the
        smoothed iso-surface :math:`\phi = \tfrac12`: the length of the Newton path
        :math:`x \leftarrow x - (\phi - \tfrac12)\nabla\phi/|\nabla\phi|^2` onto it,
        or, where :math:`\phi` is flat and Newton does not reach it, the Euclidean distance
        transform of :math:`\phi \ge \tfrac12` less half the largest voxel step.

    Raises
    ------
    SegmentationError
        (a ``ValueError``) If the volume has no foreground, holds more than ``max_labels``
        distinct labels (e.g. an intensity image), the estimated memory exceeds
        ``max_bytes`` (the message names the smallest element size that fits) or no cube is
        at least half covered.
    ValueError
        If the element size, labels or quality bound are invalid.
    RuntimeError
        If a cell is inverted after all (never expected: the voxel mesh is the fallback).

    Warns
    -----
    HarpxWarning
        If a predicate of ``boundaries`` selects no facet.

    Notes
    -----
    Voxels are taken to fill their extent: the volume is padded with background beyond its
    grid, so the 0.5 level of the interpolated labels lies half a step beyond the outermost
    voxel centres (the face of a slab of slices, not the centre of its last slice).

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
    integral, present, meshed = _labels_to_mesh(da, values, mesh_labels, max_labels)

    # the volume around the meshed labels, padded with background beyond the grid: each
    # voxel fills its extent (half a step either side of its centre), so the 0.5 level of
    # the linear interpolant lies on the outer voxel faces, also at the ends of the grid
    meshed_voxels = np.isin(np.rint(values), meshed) if integral else values > 0
    where = np.argwhere(meshed_voxels)  # (n, 3) voxel indices as (z, y, x)
    if where.size == 0:
        raise SegmentationError(f"labels {meshed!r} cover no voxel; nothing to mesh")
    step_zyx = step[::-1]
    # the memory need, before anything large is allocated
    tissue = float(meshed_voxels.sum()) * float(np.prod(step))  # mm³
    extent = where.max(axis=0) - where.min(axis=0) + 1
    nlabel = min(len(present), max_labels)
    _check_size(h, extent, step_zyx, float(sigma), nlabel, tissue, max_bytes)
    margin = _margin(h, step_zyx, float(sigma))
    first = where.min(axis=0) - margin
    crop = _padded(values, first, where.max(axis=0) + margin)
    lo = lo + first[::-1] * step
    if integral:
        ints = np.rint(crop).astype(np.int64)
        present = sorted(set(meshed) | {int(v) for v in np.unique(ints) if v != 0})
        if len(present) > max_labels:
            raise SegmentationError(
                f"the labels to mesh {meshed[:20]!r} touch {len(present) - len(meshed)} other "
                f"distinct values ({len(present)} > max_labels={max_labels}), which looks like "
                "an intensity image rather than a segmentation; pass an integer label volume"
            )
    label_names = {v: ("body" if not integral else f"label_{v}") for v in present}
    label_names |= {int(k): str(v) for k, v in (names or {}).items()}
    is_meshed = np.isin(present, meshed)
    indicators = (
        np.stack([(ints == v).astype(np.float64) for v in present])  # a few labels
        if integral
        else crop[None].astype(np.float64)
    )

    # 1. cubes, 2. boundary projection and smoothing, 3. quality (module notes)
    cubes = _cubes(indicators, is_meshed, present, margin, lo, step, h)
    if cubes is None:
        raise SegmentationError(
            f"no cube of {h:g} mm is at least half covered by labels {meshed!r}; choose a "
            "smaller element_size"
        )
    voxel_points, vi, cells = _voxel_mesh(cubes)
    mesh = hex_mesh(voxel_points, cells)
    bfacets = mesh.boundary_facets()
    fverts = mesh.facets[:, bfacets].T  # (nb, 4)
    level = _LevelSet(indicators[is_meshed].sum(axis=0), float(sigma), lo, step)
    edges = mesh.edges.T.astype(np.int64)
    x = _smoothed(voxel_points, vi, edges, fverts, level, int(smoothing), h)
    x, restored, quality = _with_quality(x, voxel_points, cells, min_quality)
    far = _surface_distance(x[np.unique(fverts)], level)
    mesh = hex_mesh(x, cells)

    # names: regions from labels, facets from the label on their outer side
    regions = {
        label_names[int(v)]: np.nonzero(cubes.label == v)[0].astype(np.int64)
        for v in meshed
        if np.any(cubes.label == v)
    }
    owner = mesh.f2t[0, bfacets]
    outer = _outer_labels(cubes, owner, voxel_points[fverts].mean(axis=1), present, meshed)
    named: dict[str, IntArray] = {}
    for v in np.unique(outer):  # a few neighbouring labels
        name = "exterior" if v == 0 else label_names[int(v)]
        named[name] = np.sort(bfacets[outer == v]).astype(np.int64)
    if boundaries:
        named |= _predicate_facets(boundaries, x[fverts].mean(axis=1), level, bfacets)
    cell_fibers = None
    if fibers is not None:
        cell_fibers = np.asarray(fibers(x[cells].mean(axis=1)), dtype=np.float64)
    spec = labelled_spec(mesh, regions, named, cell_fibers)
    report = MeshQuality(
        cells=len(cells),
        min_scaled_jacobian=float(quality.min()),
        mean_scaled_jacobian=float(quality.mean()),
        inverted=int(np.count_nonzero(quality <= 0)),
        dropped_cells=cubes.dropped,
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

    Examples
    --------
    A spherical shell (label 1, radii 5 and 8 mm) around a cavity (label 2) on a 1 mm grid;
    the shell is meshed with 2 mm hex20 cells (``element`` goes to the Body) and the
    cavity only names the facets facing it:

    >>> from harpx.anatomy.segmentation import body_from_segmentation
    >>> from harpx.mechanics.materials import NeoHookean
    >>> c = np.arange(-10.0, 10.5, 1.0)
    >>> Z, Y, X = np.meshgrid(c, c, c, indexing="ij")
    >>> r = np.sqrt(X**2 + Y**2 + Z**2)
    >>> labels = xr.DataArray(np.where(r < 5.0, 2, np.where(r < 8.0, 1, 0)),
    ...                       dims=("z", "y", "x"), coords={"z": c, "y": c, "x": c})
    >>> body = body_from_segmentation(
    ...     labels, NeoHookean(c1=1.0, kappa=100.0), element_size=2.0, mesh_labels=[1],
    ...     names={1: "wall", 2: "cavity"}, element="hex20")
    >>> body.element, sorted(body.regions), sorted(body.boundaries), body.mesh_quality.inverted
    ('hex20', ['wall'], ['cavity', 'exterior'], 0)
    >>> shell = 4.0 / 3.0 * np.pi * (8.0**3 - 5.0**3)  # mm³
    >>> bool(abs(body.cell_volume.sum() / shell - 1.0) < 0.05)
    True
    """
    from harpx.mechanics.body import Body

    mesh_keys = set(inspect.signature(mesh_from_labels).parameters) - {"labels", "element_size"}
    mesh_options = {k: v for k, v in options.items() if k in mesh_keys}
    body_options = {k: v for k, v in options.items() if k not in mesh_keys}
    result = mesh_from_labels(labels, element_size=element_size, **mesh_options)
    body = Body(result.spec, material, **body_options)
    body.mesh_quality = result.quality
    return body


__getattr__ = moved_getattr(__name__)
