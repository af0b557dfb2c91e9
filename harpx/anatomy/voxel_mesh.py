r"""The three steps of :func:`harpx.anatomy.segmentation.mesh_from_labels` on a cropped volume.

1. :func:`_cubes`: the cubes of edge ``h`` (mm) at least half covered by the meshed labels
   (each label's share the mean of its linearly interpolated indicator at 3³ points of the
   cube), the largest face-connected part of them, and each cube's label;
   :func:`_voxel_mesh` makes them a hexahedral mesh.
2. :func:`_smoothed`: boundary vertices alternate a Laplacian step along the surface and
   at most two Newton steps onto the 0.5 level of the Gaussian-smoothed indicator
   (:class:`_LevelSet`), each at most half an element and in all at most one element from
   the voxel mesh; interior vertices then relax with the boundary held.
3. :func:`_with_quality`: vertices of cells whose scaled Jacobian is below the bound move
   halfway back towards the voxel mesh until every cell passes (the voxel mesh itself, all
   cubes, is the limit).

Points are (x, y, z) in mm; volumes are (z, y, x) arrays whose first voxel centre is
``lo`` and whose steps are ``step`` (both (x, y, z), mm).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp

from harpx._typing import FloatArray, IntArray
from harpx.mechanics.quality import scaled_jacobian

__all__: list[str] = []

# cubes sampled per pass (bounds the temporary sample arrays to ~30 MB)
_CHUNK = 1 << 15

#: VTK corner offsets (x, y, z) of a hexahedron in a structured grid
_VTK_OFFSETS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
)
# sub-samples per cube edge used for the label fractions
_SUBSAMPLES = 3


@dataclass(frozen=True)
class _Cubes:
    """The cubes of the mesh on a grid of ``n`` (x, y, z) cubes of edge ``h`` from ``origin``."""

    n: IntArray  # cubes per axis (x, y, z) of the box
    origin: FloatArray  # corner of the box, mm
    h: float  # cube edge, mm
    fractions: FloatArray  # (label, box cube): each label's share of every cube of the box
    ijk: IntArray  # (cell, 3): (x, y, z) indices of the cubes kept
    label: IntArray  # (cell,): the meshed label with the largest share
    dropped: int  # cubes covered but apart from the largest connected part


class _LevelSet:
    """The Gaussian-smoothed indicator ``phi`` of the meshed labels and its gradient."""

    def __init__(
        self, foreground: FloatArray, sigma: float, lo: FloatArray, step: FloatArray
    ) -> None:
        self.phi = ndi.gaussian_filter(np.clip(foreground, 0.0, 1.0), sigma=sigma, mode="constant")
        self.grad = np.gradient(self.phi, *step[::-1])  # d/dz, d/dy, d/dx
        self.lo, self.step = lo, step

    def __call__(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``phi - 1/2`` and its gradient (n, 3; x, y, z) at points ``p`` (n, 3)."""
        g = np.stack([_sample(self.grad[2 - a], p, self.lo, self.step) for a in range(3)], 1)
        return _sample(self.phi, p, self.lo, self.step) - 0.5, g


def _cubes(
    indicators: FloatArray,
    is_meshed: Any,
    present: Sequence[int],
    margin: IntArray,
    lo: FloatArray,
    step: FloatArray,
    h: float,
) -> _Cubes | None:
    """Step 1 on ``indicators`` (label, z, y, x) of a volume with ``margin`` (z, y, x)
    background voxels around the meshed labels; None when no cube is half covered."""
    shape = np.asarray(indicators.shape[1:][::-1])  # (x, y, z)
    box_lo = lo + (margin[::-1] - 0.5) * step
    box_hi = lo + (shape - 1 - margin[::-1] + 0.5) * step
    n = np.ceil((box_hi - box_lo) / h - 1e-9).astype(np.int64) + 2  # cubes per axis (x, y, z)
    origin = 0.5 * (box_lo + box_hi) - 0.5 * n * h
    ncube = int(np.prod(n))
    fractions = np.empty((len(indicators), ncube))
    for start in range(0, ncube, _CHUNK):  # bounded temporary arrays
        ids = np.arange(start, min(start + _CHUNK, ncube))
        samples = _cube_samples(_cube_ijk(ids, n), origin, h)
        for k, ind in enumerate(indicators):  # a few labels
            fractions[k, ids] = _sample(ind, samples, lo, step).reshape(len(ids), -1).mean(axis=1)
    active = fractions[is_meshed].sum(axis=0) >= 0.5
    components, count = ndi.label(active.reshape(tuple(n[::-1])))
    if count == 0:
        return None
    sizes = np.bincount(components.ravel())[1:]
    keep = components.ravel() == 1 + int(np.argmax(sizes))
    cube_ids = np.nonzero(keep)[0]
    meshed_ids = np.nonzero(is_meshed)[0]
    label = np.asarray(present)[meshed_ids[np.argmax(fractions[meshed_ids][:, cube_ids], 0)]]
    dropped = int(active.sum() - keep.sum())
    return _Cubes(n, origin, h, fractions, _cube_ijk(cube_ids, n), label, dropped)


def _voxel_mesh(cubes: _Cubes) -> tuple[FloatArray, IntArray, IntArray]:
    """Vertices (mm), their (x, y, z) grid indices and the VTK hexahedra of the cubes."""
    n = cubes.n
    corners = cubes.ijk[:, None, :] + _VTK_OFFSETS[None]  # (ncell, 8, 3)
    flat = (corners[..., 2] * (n[1] + 1) + corners[..., 1]) * (n[0] + 1) + corners[..., 0]
    used, cells = np.unique(flat.ravel(), return_inverse=True)
    vi = np.stack(
        [used % (n[0] + 1), (used // (n[0] + 1)) % (n[1] + 1), used // ((n[0] + 1) * (n[1] + 1))],
        axis=1,
    )
    return cubes.origin + cubes.h * vi, vi, cells.reshape(-1, 8)


def _smoothed(
    voxel_points: FloatArray,
    vi: IntArray,
    edges: IntArray,
    fverts: IntArray,
    level: _LevelSet,
    smoothing: int,
    h: float,
) -> FloatArray:
    """Step 2: the vertices after ``smoothing`` rounds (``edges`` (m, 2) of the mesh,
    ``fverts`` (nb, 4) of its boundary facets)."""
    bverts = np.unique(fverts)
    # boundary graph: facet sides (vertex pairs differing along one axis)
    a_idx, b_idx = np.triu_indices(4, 1)
    pa, pb = fverts[:, a_idx].ravel(), fverts[:, b_idx].ravel()
    side = np.count_nonzero(vi[pa] != vi[pb], axis=1) == 1
    npts = len(voxel_points)
    boundary_graph = _adjacency(np.column_stack([pa[side], pb[side]]), npts)
    full_graph = _adjacency(edges, npts)
    interior = np.setdiff1d(np.arange(npts), bverts)
    x = voxel_points.copy()
    for _ in range(smoothing):  # a few smoothing + projection rounds
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
    for _ in range(2 * smoothing):
        x = _laplacian_step(x, full_graph, interior)
    return x


def _with_quality(
    x: FloatArray, voxel_points: FloatArray, cells: IntArray, min_quality: float
) -> tuple[FloatArray, IntArray, FloatArray]:
    """Step 3: the vertices with every cell's scaled Jacobian at least ``min_quality``, the
    vertices moved back, and the cells' scaled Jacobians."""
    x = x.copy()
    restored = np.zeros(len(x), dtype=bool)
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
    return x, restored, quality


def _outer_labels(
    cubes: _Cubes,
    owner: IntArray,
    facet_centres: FloatArray,
    present: Sequence[int],
    meshed: Sequence[int],
) -> IntArray:
    """The label on the outer side of each boundary facet (0: background or a meshed
    label), from the cube beyond it; ``owner`` is the facet's cell and ``facet_centres``
    its centre on the voxel mesh (mm)."""
    n, h = cubes.n, cubes.h
    cube_centre = cubes.origin + h * (cubes.ijk[owner] + 0.5)
    outward = np.rint(2.0 * (facet_centres - cube_centre) / h).astype(np.int64)
    nb_ijk = cubes.ijk[owner] + outward
    nb_flat = (nb_ijk[:, 2] * n[1] + nb_ijk[:, 1]) * n[0] + nb_ijk[:, 0]
    nb_frac = cubes.fractions[:, nb_flat]  # (nlabel, nb)
    background = 1.0 - nb_frac.sum(axis=0)
    winner = np.argmax(np.vstack([background[None], nb_frac]), axis=0) - 1
    outer = np.where(winner >= 0, np.asarray(present)[np.maximum(winner, 0)], 0)
    result: IntArray = np.where(np.isin(outer, meshed), 0, outer)
    return result


def _cube_ijk(ids: IntArray, n: IntArray) -> IntArray:
    """(x, y, z) indices (m, 3) of cubes with flat ids (x fastest) on an ``n`` grid."""
    ids = np.asarray(ids, dtype=np.int64)
    return np.stack([ids % n[0], (ids // n[0]) % n[1], ids // (n[0] * n[1])], axis=1)


def _cube_samples(ijk: IntArray, origin: FloatArray, h: float) -> FloatArray:
    """The ``_SUBSAMPLES``³ sample points (m·27, 3) of cubes, mm."""
    sub = (np.arange(_SUBSAMPLES) + 0.5) / _SUBSAMPLES
    sz, sy, sx = np.meshgrid(sub, sub, sub, indexing="ij")
    offsets = np.stack([sx.ravel(), sy.ravel(), sz.ravel()], axis=1)
    return (origin + h * (ijk[:, None, :] + offsets[None])).reshape(-1, 3)


def _surface_distance(points: FloatArray, level: _LevelSet) -> FloatArray:
    """Distance (mm) of points from the 0.5 level of ``level.phi``: the length of the Newton
    path onto it or, where it is flat, the distance transform less half a voxel (see
    :func:`harpx.anatomy.segmentation.mesh_from_labels`)."""
    step = level.step
    x = points.copy()
    todo = np.ones(len(x), dtype=bool)
    for _ in range(12):  # Newton steps onto the level set, each at most one voxel
        value, g = level(x[todo])
        g2 = np.einsum("ni,ni->n", g, g)
        done = np.abs(value) < 1e-4
        ok = (g2 > 0) & ~done
        delta = np.zeros_like(g)
        delta[ok] = -(value[ok] / g2[ok])[:, None] * g[ok]
        length = np.linalg.norm(delta, axis=1, keepdims=True)
        delta *= np.minimum(1.0, float(step.min()) / np.maximum(length, 1e-300))
        idx = np.nonzero(todo)[0]
        x[idx] += delta
        todo[idx[done | (g2 == 0)]] = False
        if not todo.any():
            break
    value, _ = level(x)
    out = np.linalg.norm(x - points, axis=1)
    # where the smoothed level set is flat (far from the surface) Newton does not reach it:
    # the Euclidean distance transform of the thresholded level set, to half a voxel
    lost = np.abs(value) > 1e-3
    if lost.any():
        inside = level.phi >= 0.5
        edt = ndi.distance_transform_edt(~inside, sampling=step[::-1])
        edt = edt + ndi.distance_transform_edt(inside, sampling=step[::-1])
        coarse = _sample(np.asarray(edt), points[lost], level.lo, step) - 0.5 * float(step.max())
        out[lost] = np.maximum(coarse, 0.0)
    return out


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
