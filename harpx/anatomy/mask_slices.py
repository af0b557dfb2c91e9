"""A myocardium mask read as a stack of short-axis slices: the first steps of the fit.

:func:`harpx.anatomy.mask_fit.fit_ventricle_to_mask` starts here. The label volume becomes
a myocardium fraction (integer labels picked by ``myocardium=``, the right ventricle by
``rv=``); the myocardium must be one face-connected piece (specks under 1 % of it are
dropped and flagged); each slice across ``slice_axis`` is a ring (tissue around a cavity),
part of the apical cap (tissue beyond the last ring that covers the ring's axis) or open
(left out, flagged); the septum is the myocardium of the ring slices within two voxels of
the right ventricle. What cannot be trusted raises :class:`VentricleFitError`; what should
be checked is flagged (``fit.flags``) and, for most flags, warned about with
:class:`VentricleFitWarning`.

Units: mm.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.ndimage as ndi

from harpx._typing import FloatArray, IntArray
from harpx.anatomy.contours import _covers_axis, _plane_structure
from harpx.errors import HarpxError, HarpxWarning, user_stacklevel
from harpx.io.labels import read_labels
from harpx.schema import grid_step

__all__ = ["VentricleFitError", "VentricleFitWarning"]


class VentricleFitError(HarpxError, ValueError):
    """A mask or contours the ventricle cannot be fitted to as asked.

    The message states what is wrong with the numbers (e.g. two separate blobs and their
    sizes, no cavity in any short-axis slice, an axis hint far off the slice normal) and
    what to pass instead.
    """


class VentricleFitWarning(HarpxWarning):
    """A fit that can be used but should be checked; the text is also in ``fit.flags``."""


def _labels(values: Any, what: str, myocardium: Any, rv: Any) -> tuple[FloatArray, Any]:
    """Myocardium fraction and RV mask (or None) of a label volume."""
    if not np.all(np.isfinite(values)):
        raise VentricleFitError(f"{what} contains NaN or inf; fill it (e.g. mask.fillna(0))")
    integral = values.dtype == bool or bool(np.all(np.isclose(values, np.rint(values))))
    myo = None if myocardium is None else [int(v) for v in np.atleast_1d(myocardium)]
    rvl = None if rv is None else [int(v) for v in np.atleast_1d(rv)]
    if not integral:
        if values.min() < 0 or values.max() > 1:
            raise VentricleFitError(
                f"{what} is neither integer labels nor a fraction in [0, 1] (range "
                f"{values.min():.3g} .. {values.max():.3g}); pass a myocardium mask or labels"
            )
        if myo is not None or rvl is not None:
            raise VentricleFitError(
                f"{what} is a tissue fraction, not integer labels: myocardium= and rv= select "
                "labels of an integer segmentation"
            )
        return values.astype(np.float64), None
    ints = np.rint(values).astype(np.int64)
    present = [int(v) for v in np.unique(ints) if v != 0]
    if myo is None:
        myo = [v for v in present if v not in (rvl or [])]
        if len(myo) > 1:
            raise VentricleFitError(
                f"{what} holds labels {present[:10]!r}; say which is the left-ventricular "
                "myocardium with myocardium=<label> (and the right ventricle with rv=)"
            )
    missing = [v for v in (*myo, *(rvl or [])) if v not in present]
    if missing:
        raise VentricleFitError(
            f"labels {missing!r} are not in {what} (present: {present[:10]!r}); check "
            "myocardium= and rv="
        )
    rv_mask = None if rvl is None else np.isin(ints, rvl)
    return np.isin(ints, myo).astype(np.float64), rv_mask


def _warn(flags: dict[str, str], name: str, message: str, *, warn: bool = True) -> None:
    flags[name] = message
    if warn:
        warnings.warn(message, VentricleFitWarning, stacklevel=user_stacklevel())


def _read_lax(
    sources: Sequence[Any], variable: str | None, myocardium: Any
) -> list[tuple[FloatArray, list[FloatArray], FloatArray]]:
    """Long-axis masks: padded fraction, padded (z, y, x) coordinates, tissue points (x, y, z)."""
    out = []
    for k, source in enumerate(sources):  # a few long-axis slices
        da = read_labels(source, variable=variable)
        f, _ = _labels(np.asarray(da.values), f"long_axis_slices[{k}]", myocardium, None)
        f = np.pad(f, [(1, 1)] * 3, mode="constant", constant_values=0.0)
        coords = []
        for d in ("z", "y", "x"):
            c = np.asarray(da[d].values, dtype=np.float64)
            step = grid_step(da, d) or 1.0
            coords.append(np.concatenate([[c[0] - step], c, [c[-1] + step]]))
        tissue = np.argwhere(f >= 0.5)
        if len(tissue) < 10:
            raise VentricleFitError(
                f"long_axis_slices[{k}] holds {len(tissue)} myocardium voxels; pass the "
                "long-axis slice's myocardium mask"
            )
        xyz = np.stack([coords[2 - a][tissue[:, 2 - a]] for a in range(3)], axis=1)
        out.append((f, coords, xyz))
    return out


@dataclass(frozen=True)
class _Stack:
    """The mask's grid as a stack of slices across ``slice_axis`` (mm)."""

    slice_axis: str
    normal: int  # array axis (in z, y, x order) across the slices
    coords: list[FloatArray]  # voxel centres along z, y, x
    in_plane: float  # the finest step within a slice
    step_n: float  # the step across the slices (the in-plane step for a single slice)

    @classmethod
    def of(cls, da: Any, slice_axis: str) -> _Stack:
        normal = ("z", "y", "x").index(slice_axis)
        coords = [np.asarray(da[d].values, dtype=np.float64) for d in ("z", "y", "x")]
        steps = [float(np.abs(np.diff(c)).min()) if c.size > 1 else np.inf for c in coords]
        in_plane = min(steps[d] for d in range(3) if d != normal)
        step_n = steps[normal] if np.isfinite(steps[normal]) else in_plane
        return cls(slice_axis, normal, coords, in_plane, step_n)

    @property
    def other(self) -> tuple[int, int]:
        """The two array axes within a slice."""
        a, b = (d for d in range(3) if d != self.normal)
        return a, b

    @property
    def e_n(self) -> FloatArray:
        """Unit slice normal (x, y, z)."""
        e = np.zeros(3)
        e[2 - self.normal] = 1.0
        return e

    @property
    def position(self) -> FloatArray:
        """Slice centres along the slice axis."""
        return self.coords[self.normal]

    def points(self, index: IntArray) -> FloatArray:
        """Image points (x, y, z) of voxel indices, shape (n, 3) in (z, y, x) order."""
        return np.stack([self.coords[2 - a][index[:, 2 - a]] for a in range(3)], axis=1)


@dataclass(frozen=True)
class _Slices:
    """The myocardium's short-axis slices: rings (tissue around a cavity), the apical cap."""

    inside: Any  # bool (z, y, x): myocardium
    cavity: Any  # bool (z, y, x): enclosed by the myocardium within its slice
    tissue_k: IntArray  # slices with tissue
    ring_k: IntArray  # ring slices
    cap_k: IntArray  # slices of the apical cap
    cap_low: bool  # an apical cap beyond the first ring
    cap_high: bool  # an apical cap beyond the last ring

    @classmethod
    def of(cls, f: FloatArray, stack: _Stack, flags: dict[str, str]) -> _Slices:
        """Classify the slices; refuse a mask without a ring, flag open slices inside it."""
        normal, other = stack.normal, stack.other
        inside = f >= 0.5
        cavity = ndi.binary_fill_holes(inside, structure=_plane_structure(normal)) & ~inside
        tissue_n = inside.sum(axis=other)
        cavity_n = cavity.sum(axis=other)
        ring = cavity_n >= np.maximum(3, 0.02 * (tissue_n + cavity_n))
        tissue_k = np.nonzero(tissue_n)[0]
        ring_k = np.nonzero(ring)[0]
        if ring_k.size == 0:
            raise VentricleFitError(
                f"no short-axis slice (normal {stack.slice_axis}) of the mask encloses a "
                f"cavity: its {tissue_k.size} slices with tissue are filled discs, as of a "
                "solid cylinder or of myocardium and blood pool together; pass the myocardium "
                "alone (or myocardium=<label>), or the right slice_axis"
            )
        first, last = ring_k.min(), ring_k.max()
        open_k = tissue_k[(tissue_k > first) & (tissue_k < last) & ~ring[tissue_k]]
        # an apical cap: tissue beyond the last ring that covers the ring's axis (a disc);
        # the open arcs of an oblique base do not
        cap_low = tissue_k.min() < first and _covers_axis(inside, cavity, normal, first, -1)
        cap_high = tissue_k.max() > last and _covers_axis(inside, cavity, normal, last, 1)
        cap_k = tissue_k[(cap_low & (tissue_k < first)) | (cap_high & (tissue_k > last))]
        if open_k.size:
            _warn(
                flags, "open_slices",
                f"{open_k.size} short-axis slices inside the stack have tissue but no closed "
                f"cavity ({stack.slice_axis} = {np.round(stack.position[open_k], 2).tolist()} "
                "mm) and were left out; close the ring in the segmentation to use them",
            )  # fmt: skip
        return cls(inside, cavity, tissue_k, ring_k, cap_k, bool(cap_low), bool(cap_high))


def _one_piece(f: FloatArray, stack: _Stack, flags: dict[str, str]) -> FloatArray:
    """The myocardium fraction without specks; refuse an empty mask or several pieces."""
    inside = f >= 0.5
    if not inside.any():
        raise VentricleFitError(
            f"the mask holds no myocardium (no voxel >= 0.5 among {f.size}); pass the "
            "segmentation of the left-ventricular wall"
        )
    pieces, count = ndi.label(inside)
    if count == 1:
        return f
    sizes = np.bincount(pieces.ravel())[1:]
    order = np.argsort(sizes)[::-1]
    if sizes[order[1]] >= 0.01 * sizes[order[0]]:
        coords = stack.coords
        centres = ndi.center_of_mass(inside, pieces, order[:3] + 1)
        where = [
            tuple(round(float(np.interp(c[k], np.arange(len(coords[k])), coords[k])), 1)
                  for k in (2, 1, 0))
            for c in centres
        ]  # fmt: skip
        raise VentricleFitError(
            f"the myocardium is in {count} separate pieces of {sizes[order[:5]].tolist()} "
            f"voxels (centres x, y, z mm: {where}); a ventricle is one piece: pass the "
            "left-ventricular wall only (e.g. mask.where(labels == ...)) or fix the gaps"
        )
    keep = pieces == 1 + order[0]
    _warn(
        flags, "dropped_specks",
        f"{count - 1} specks of {int(sizes.sum() - sizes[order[0]])} voxels in all "
        f"(< 1 % of the {int(sizes[order[0]])}-voxel myocardium) were left out",
        warn=False,
    )  # fmt: skip
    kept: FloatArray = np.where(ndi.binary_dilation(keep), f, 0.0)
    return kept


def _septum_contact(rv_mask: Any, rv: Any, slices: _Slices, stack: _Stack) -> IntArray:
    """Voxel indices of the myocardium of the ring slices within two voxels of the RV."""
    near = ndi.binary_dilation(rv_mask, structure=_plane_structure(stack.normal), iterations=2)
    in_rings = np.isin(np.arange(rv_mask.shape[stack.normal]), slices.ring_k)
    touch: IntArray = np.argwhere(near & slices.inside & np.expand_dims(in_rings, stack.other))
    if len(touch) == 0:
        raise VentricleFitError(
            f"the right-ventricle label {rv!r} does not touch the left-ventricular "
            "myocardium in any ring slice (within 2 voxels); check rv= and myocardium="
        )
    return touch


def _read_mask(
    mask: Any,
    variable: str | None,
    slice_axis: str,
    myocardium: Any,
    rv: Any,
    flags: dict[str, str],
) -> tuple[Any, FloatArray, _Stack, _Slices, IntArray | None]:
    """The mask read for the fit: its label DataArray (:func:`~harpx.io.labels.read_labels`),
    the myocardium fraction without specks, its grid as a stack, its slices and the septal
    voxels (None without ``rv``)."""
    da = read_labels(mask, variable=variable)
    f, rv_mask = _labels(np.asarray(da.values), "the mask", myocardium, rv)
    stack = _Stack.of(da, slice_axis)
    f = _one_piece(f, stack, flags)
    slices = _Slices.of(f, stack, flags)
    touch = None if rv_mask is None else _septum_contact(rv_mask, rv, slices, stack)
    return da, f, stack, slices, touch
