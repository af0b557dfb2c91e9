"""Wrap-safe interpolation of harmonic phase and its gradient at arbitrary points.

Wrapped phase cannot be interpolated directly: across the jump from π to -π a spline or a
linear interpolant produces values anywhere in between. :class:`PhaseSampler` interpolates
the complex harmonic image instead, after removing the known tag carrier, so everything it
interpolates is smooth:

1. Per tag ``t`` with wave vector :math:`k_t = 2\\pi f_t d_t` (rad/mm), form the harmonic image
   :math:`H = |H| e^{i\\varphi}` from ``magnitude`` and ``phase`` and demodulate it,
   :math:`D = H e^{-i k_t \\cdot x}`. At the reference frame :math:`D \\approx |H|`; later
   :math:`D \\approx |H| e^{-i k_t \\cdot u}` varies as slowly as the displacement ``u``.
2. Prefilter the real and imaginary parts of ``D`` once per frame into cubic B-spline
   coefficients (:func:`scipy.ndimage.spline_filter`, mirror boundaries).
3. At the points, evaluate the spline and its exact derivative with one shared set of tap
   weights for all tags, and remodulate:

   .. math::

       \\varphi = W(\\arg D + k_t \\cdot x), \\qquad
       \\nabla \\varphi = k_t + \\frac{\\operatorname{Im}(\\bar D \\, \\nabla D)}{|D|^2}
       = \\frac{\\operatorname{Im}(\\bar H \\, \\nabla H)}{|H|^2},

   with :math:`W(a) = \\operatorname{angle}(e^{ia}) \\in [-\\pi, \\pi)` (the
   complex form of the phase gradient, exact wherever :math:`|H| > 0`).

No wrapped difference ever enters the interpolation, so points straddling a phase wrap are
as accurate as any other. Everything is vectorised over points; the Python loop runs over
chunks of a few thousand points, sorted by voxel for memory locality.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from harpx.errors import SchemaError
from harpx.imaging._kernels import percentile_99, wrap
from harpx.imaging.bspline import (
    _EDGE,
    _cubic_taps,
    _demodulated_taps,
    _tap_dtype,
    _tensor_weights,
    _weights,
)
from harpx.schema import AXES, GRID_DIMS

__all__ = ["PhaseSampler", "reference_phase", "wrap"]

_TWO_PI = 2.0 * np.pi
# Points this close (in voxels) beyond the first/last voxel centre still count as inside.
_FOV_TOL = 1e-9
#: Voxels of real data kept around a requested ``region`` for the cubic prefilter. Its
#: influence decays by 2 − √3 ≈ 0.268 per voxel, so inside the region the spline differs from
#: the whole grid's by ~0.268**20 ≈ 4e-12 of the data (the trilinear taps need no margin);
#: float32 data hold ~1e-7 of their size, reached after 13 voxels (0.268**13 ≈ 4e-8).
_REGION_MARGIN = {np.dtype(np.float64): 20, np.dtype(np.float32): 13}


class PhaseSampler:
    """Phase, phase gradient and magnitude of one frame of a ``phase/1`` dataset at points.

    Parameters
    ----------
    phase_ds : xarray.Dataset
        A ``phase/1`` dataset (``phase``, ``magnitude`` (tag, time, z, y, x), coordinates
        ``tag_direction``, ``tag_frequency``, ``z``, ``y``, ``x``; optional ``mask``). Only
        its structure is checked here (cheaply); run :func:`harpx.schema.validate` once
        upstream. The selected frame is loaded into memory (computed if dask-backed).
    time_index : int
        Frame to sample (index along ``time``; negative values count from the end).
    order : {3, 1}, default 3
        B-spline order: 3 (cubic, default) or 1 (trilinear).
    magnitude_floor : float, default 0.05
        A point is valid only where every tag's harmonic magnitude is at least this fraction
        of that tag's robust maximum (99th percentile over the frame, inside the mask if
        there is one). Dimensionless. At the reference frame (``time_index`` 0) a dataset
        with ``body`` also requires the point to be tissue there (``body >= 0.5`` at its
        nearest voxel): partial-volume edge voxels carry a background-contaminated phase.
    chunk_size : int, default 1024
        Points evaluated per vectorised batch of the cubic spline (memory ~ 4 kB per point;
        small batches keep the gathered taps in cache); the linear spline, with 8 taps
        instead of 64, takes batches of eight times as many points.
    region : array_like of shape (2, 3), optional
        Lower and upper corners (rows) of a box in mm, columns (x, y, z), that holds every
        point this sampler will be asked about. Only the grid inside it (plus a margin of
        20 voxels for the cubic prefilter) is prepared, which makes construction cheaper in
        proportion; the samples inside the box are those of the whole grid to ~1e-11 of the
        data (exactly for ``order=1``). Points outside the box are reported as outside the
        field of view (invalid, not acquired). Default: the whole grid.
    reuse : PhaseSampler, optional
        A sampler that is no longer needed (e.g. the previous frame's): its tap array is
        reused where it is big enough, sparing the allocation and zero-filling of some
        hundred MB per frame. ``reuse`` cannot sample afterwards.

    Raises
    ------
    SchemaError
        If the dataset lacks a variable or coordinate the sampler needs.
    IndexError
        If ``time_index`` is out of range.
    ValueError
        If ``order`` is not 1 or 3, or ``region`` is not a finite (2, 3) box.

    Notes
    -----
    The field of view is the box spanned by the first and last voxel centres along every
    grid axis with more than one sample. A grid axis with a single sample (a single slice)
    is treated as invariant: the coordinate of a point along it is ignored, and so is the
    tag wave vector's component along it (the phase gradient component there is 0).

    Precision: the spline coefficients keep the data's precision, float32 for float32
    ``phase`` and ``magnitude`` (the :func:`~harpx.imaging.harp.extract_phase` default), at
    half the memory traffic; phase and gradient are returned in float64 either way.

    Cost: one spline prefilter per tag at construction; per point ``(order+1)**d`` taps
    shared by all tags (``d`` grid axes with more than one sample); timings in
    ``benchmarks/results/phase.md``.

    Examples
    --------
    >>> x = np.arange(16.0)
    >>> ds = xr.Dataset(
    ...     {"phase": (("tag", "time", "z", "y", "x"),
    ...                wrap(2 * np.pi / 8 * x)[None, None, None, None, :].repeat(16, 3)),
    ...      "magnitude": (("tag", "time", "z", "y", "x"), np.ones((1, 1, 1, 16, 16)))},
    ...     coords={"tag": ["x"], "axis": ["x", "y", "z"], "x": x, "y": x, "z": [0.0],
    ...             "tag_direction": (("tag", "axis"), [[1.0, 0.0, 0.0]]),
    ...             "tag_frequency": ("tag", [1 / 8])})
    >>> phi, grad, valid = PhaseSampler(ds, 0).sample(np.array([[7.9, 5.0, 0.0]]))
    >>> round(float(phi[0, 0]), 6) == round(float(wrap(2 * np.pi / 8 * 7.9)[()]), 6)
    True
    >>> (np.round(grad[0, 0], 6) + 0.0).tolist(), bool(valid[0])
    ([0.785398, 0.0, 0.0], True)
    """

    def __init__(
        self,
        phase_ds: xr.Dataset,
        time_index: int,
        *,
        order: int = 3,
        magnitude_floor: float = 0.05,
        chunk_size: int = 1024,
        region: ArrayLike | None = None,
        reuse: PhaseSampler | None = None,
    ) -> None:
        if order not in (1, 3):
            raise ValueError(f"order={order!r} is not supported; use 3 (cubic) or 1 (linear)")
        _check_structure(phase_ds)
        ntime = phase_ds.sizes["time"]
        if not -ntime <= int(time_index) < ntime:
            raise IndexError(f"time_index={time_index!r} is out of range for {ntime} frames")
        self.order = order
        self.chunk_size = int(chunk_size)
        self.time_index = int(time_index) % ntime
        self.tags: list[str] = [str(t) for t in phase_ds["tag"].values]
        direction = np.asarray(phase_ds["tag_direction"].transpose("tag", "axis").values, float)
        frequency = np.asarray(phase_ds["tag_frequency"].values, float)
        #: Tag wave vectors k_t = 2π f_t d_t, shape (ntag, 3), columns (x, y, z), rad/mm.
        self.wavevectors: NDArray[np.float64] = _TWO_PI * frequency[:, None] * direction

        frame = phase_ds.isel(time=self.time_index)
        # float32 phase/magnitude (the extract_phase default) stay float32 here: every use
        # below promotes them to float64 arithmetic
        phase = _floating(frame["phase"].transpose("tag", *GRID_DIMS).values)
        magnitude = _floating(frame["magnitude"].transpose("tag", *GRID_DIMS).values)
        grid = [np.asarray(phase_ds[d].values, np.float64) for d in GRID_DIMS]
        self._set_grid(grid, phase.shape[1:])
        # the prepared window [lo, hi) of voxel indices along the active axes
        margin = _REGION_MARGIN[_tap_dtype(phase, magnitude)] if order == 3 else 0
        self._lo, self._hi = self._window(region, margin)
        self._windowed = bool(np.any(self._lo > 0) or np.any(self._hi < self._shape))
        cut = [slice(None)] * 3
        for j, a in enumerate(self._active):
            cut[a] = slice(int(self._lo[j]), int(self._hi[j]))
        window = (slice(None), *cut)

        # k·x as a sum of per-axis terms, each wrapped to [-π, π) (in float64) so that in the
        # phase's precision (float32 for the extract_phase default) φ − k·x keeps float32's
        # resolution of ~1e-6 rad; k·x itself reaches hundreds of rad across the field of view
        terms = [
            wrap(self.wavevectors[:, AXES.index(d), None] * grid[g][cut[g]][None, :])
            .astype(phase.dtype)
            .reshape([len(self.tags)] + [-1 if i == g else 1 for i in range(3)])
            for g, d in enumerate(GRID_DIMS)
        ]
        carrier = terms[0] + terms[1] + terms[2]
        squeeze = tuple(a + 1 for a in range(3) if a not in self._active)
        self._ntag = len(self.tags)
        # Extend D by odd reflection (2 D[0] - D[k]), which keeps value and slope continuous
        # at the border, before prefiltering: the spline's own mirror boundary (a slope
        # discontinuity) then sits `edge` voxels outside the field of view, where its error
        # has decayed by 0.268**edge. A window edge inside the grid needs no extension: the
        # margin of real data beyond it does that job.
        edge = np.minimum(_EDGE if order == 3 else 0, self._hi - self._lo - 1)
        self._before = np.where(self._lo == 0, edge, 0)
        self._after = np.where(self._hi == self._shape, edge, 0)
        buffer = reuse._release() if reuse is not None else None
        data = phase[window], magnitude[window]
        if order == 1:
            # trilinear taps need no prefilter: write cos/sin of the demodulated phase
            # straight into the padded tap array (no complex temporaries, one pass per tag)
            padded = _demodulated_taps(*data, carrier, squeeze, buffer)
        else:
            padded = _cubic_taps(*data, carrier, squeeze, self._before, self._after, buffer)
        self._padded: NDArray[np.floating] | None = padded
        self._padded_dtype = padded.dtype
        self._buffer: NDArray[np.floating] | None = padded if padded.base is None else padded.base

        self._set_validity(phase_ds, magnitude, magnitude_floor)

    def _set_grid(self, grid: list[NDArray[np.float64]], shape: tuple[int, ...]) -> None:
        """The grid's geometry: the axes along which it varies, their origin and spacing."""
        # grid axes (0=z, 1=y, 2=x) that vary; the others are invariant (single slice)
        self._active = [a for a in range(3) if shape[a] > 1]
        if not self._active:
            raise SchemaError("the phase grid has a single voxel; cannot interpolate")
        self._origin = np.array([grid[a][0] for a in self._active])
        self._spacing = np.array(
            [(grid[a][-1] - grid[a][0]) / (shape[a] - 1) for a in self._active]
        )
        self._shape = np.array([shape[a] for a in self._active])
        # point columns (x, y, z) of the active grid axes
        self._columns = np.array([AXES.index(GRID_DIMS[a]) for a in self._active])
        #: Names of the axes along which the field varies, in point-column names.
        self.active_axes: tuple[str, ...] = tuple(GRID_DIMS[a] for a in self._active)
        self._k_active = self.wavevectors[:, self._columns]  # (ntag, d)
        # remodulation uses the slice position along invariant axes
        self._fixed = np.zeros(3)
        for a in range(3):
            if a not in self._active:
                self._fixed[AXES.index(GRID_DIMS[a])] = grid[a][0]

    def _set_validity(
        self, phase_ds: xr.Dataset, magnitude: NDArray[np.floating], magnitude_floor: float
    ) -> None:
        """What makes a point valid: the tags' masks, the reference support, the floors."""
        squeeze = tuple(a + 1 for a in range(3) if a not in self._active)
        mask = None
        if "mask" in phase_ds.variables:
            mask = np.asarray(phase_ds["mask"].transpose("tag", *GRID_DIMS).values, bool)
            mask = mask.squeeze(axis=squeeze) if squeeze else mask
        self._mask = mask
        # at the reference frame the tissue's support is known: `body` (voxel-averaged
        # density at time index 0); a point there is tissue only where body >= 0.5
        support = None
        if self.time_index == 0 and "body" in phase_ds.variables:
            support = np.asarray(phase_ds["body"].transpose(*GRID_DIMS).values) >= 0.5
            support = support.squeeze(axis=tuple(a - 1 for a in squeeze)) if squeeze else support
        self._support = support
        self._floor = np.zeros(self._ntag)
        for t in range(self._ntag):
            mag = magnitude[t].squeeze(axis=tuple(a - 1 for a in squeeze))
            inside = mask[t] if mask is not None and mask[t].any() else None
            self._floor[t] = magnitude_floor * percentile_99(mag, inside)

    # ------------------------------------------------------------------------------------
    def sample(
        self, points: ArrayLike, *, per_tag: bool = False
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """Phase and phase gradient of every tag at physical points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Positions in mm, columns (x, y, z).
        per_tag : bool, default False
            Report validity per tag, shape (n, ntag): a point inside one stack's slab
            (e.g. short-axis slices) but outside another's (long-axis slices) keeps the
            tags it has.

        Returns
        -------
        phi : numpy.ndarray, shape (n, ntag)
            Wrapped harmonic phase in rad, in [-π, π).
        grad : numpy.ndarray, shape (n, ntag, 3)
            Spatial phase gradient in rad/mm, columns (x, y, z).
        valid : numpy.ndarray of bool, shape (n,) or (n, ntag)
            Inside the field of view, inside every tag's mask (if any) and above the
            magnitude floor for every tag, and at the reference frame inside ``body``
            (``per_tag``: inside that tag's mask, and above the floor for every tag whose
            mask holds the point). Invalid points (or
            point–tag pairs) get ``phi = 0`` and ``grad = 0``.
        """
        pts = _as_points(points)
        values, size, valid_tags = self._evaluate(pts, derivatives=True)
        valid = valid_tags if per_tag else cast(NDArray[np.bool_], valid_tags.all(axis=1))
        ntag = self._ntag
        invalid = ~(valid_tags if per_tag else valid_tags.all(axis=1, keepdims=True))
        invalid = cast(NDArray[np.bool_], invalid)
        re, im = values[0, :ntag], values[0, ntag:]  # (ntag, n) rows: contiguous
        phi = self._remodulate(pts, re, im)
        # Im(conj(D) dD) / |D|^2 per voxel of each active axis, per mm, plus k: one factor
        # 1 / |D|^2 per tag and point (0 where invalid, which zeroes the derivative part)
        power = size * size
        inverse = np.divide(1.0, power, out=np.zeros_like(power), where=power > 0)
        np.copyto(inverse, 0.0, where=np.broadcast_to(invalid, phi.shape).T)
        grad = np.zeros((pts.shape[0], ntag, 3))  # invariant axes: no variation along them
        cross = np.empty_like(re)
        for j, column in enumerate(self._columns.tolist()):
            np.multiply(re, values[1 + j, ntag:], out=cross)
            cross -= im * values[1 + j, :ntag]
            cross *= inverse
            cross *= 1.0 / self._spacing[j]
            cross += self._k_active[:, j, None]
            grad[:, :, column] = cross.T
        np.copyto(grad, 0.0, where=invalid[..., None])
        np.copyto(phi, 0.0, where=invalid)
        return phi, grad, valid

    def phase(
        self, points: ArrayLike, *, per_tag: bool = False
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Phase only, as :meth:`sample` without the gradient (cheaper).

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Positions in mm, columns (x, y, z).
        per_tag : bool, default False
            Report validity per tag, as in :meth:`sample`.

        Returns
        -------
        phi : numpy.ndarray, shape (n, ntag)
            Wrapped harmonic phase in rad, in [-π, π) (0 where invalid).
        valid : numpy.ndarray of bool, shape (n,) or (n, ntag)
            As in :meth:`sample`.
        """
        phi, _, valid = self._phase(_as_points(points), per_tag)
        return phi, valid

    def phase_and_magnitude(
        self, points: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """:meth:`phase` (``per_tag=True``) and :meth:`magnitude` from one evaluation.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Positions in mm, columns (x, y, z).

        Returns
        -------
        phi, magnitude : numpy.ndarray, shape (n, ntag)
            Wrapped phase (rad; 0 where invalid) and ``|H|`` (as :meth:`magnitude`).
        valid : numpy.ndarray of bool, shape (n, ntag)
            As :meth:`phase` with ``per_tag=True``; ``valid.all(axis=1)`` is the validity
            :meth:`magnitude` reports.
        """
        phi, size, valid = self._phase(_as_points(points), True)
        return phi, np.ascontiguousarray(size.T, dtype=np.float64), valid

    def _phase(
        self, pts: NDArray[np.float64], per_tag: bool
    ) -> tuple[NDArray[np.float64], NDArray[np.floating], NDArray[np.bool_]]:
        """``(phi, |D| (ntag, n), valid)`` of :meth:`phase`."""
        values, size, valid_tags = self._evaluate(pts, derivatives=False)
        valid = valid_tags if per_tag else cast(NDArray[np.bool_], valid_tags.all(axis=1))
        phi = self._remodulate(pts, values[0, : self._ntag], values[0, self._ntag :])
        np.copyto(
            phi, 0.0, where=~(valid_tags if per_tag else valid_tags.all(axis=1, keepdims=True))
        )
        return phi, size, valid

    def magnitude(self, points: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Harmonic magnitude ``|H|`` of every tag at points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Positions in mm, columns (x, y, z).

        Returns
        -------
        magnitude : numpy.ndarray, shape (n, ntag)
            ``|H|`` in the units of the dataset's ``magnitude``. Unlike :meth:`sample`, points
            below the magnitude floor keep their value (they are still invalid); points
            outside the field of view get 0.
        valid : numpy.ndarray of bool, shape (n,)
            As in :meth:`sample`.
        """
        pts = _as_points(points)
        _, size, valid_tags = self._evaluate(pts, derivatives=False)
        magnitude = np.ascontiguousarray(size.T, dtype=np.float64)
        return magnitude, cast(NDArray[np.bool_], valid_tags.all(axis=1))

    def acquired(self, points: ArrayLike) -> NDArray[np.bool_]:
        """Which tags have data at points: inside the field of view and the tag's ``mask``.

        The acquisition only, a fixed region of space: unlike the validity of
        :meth:`sample`, the magnitude floor (whether there is tissue signal) is not tested.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Positions in mm, columns (x, y, z).

        Returns
        -------
        numpy.ndarray of bool, shape (n, ntag)
            True where the tag was acquired at the point.
        """
        return self._locate(_as_points(points))[1]

    def outside_window(self, points: ArrayLike) -> int:
        """Count the points in the field of view but outside the prepared window.

        A sampler of the whole grid would sample them; one prepared for a ``region`` calls
        them invalid.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Positions in mm, columns (x, y, z).

        Returns
        -------
        int
            Number of such points (0 for a sampler of the whole grid).
        """
        if not self._windowed:
            return 0
        pts = _as_points(points)
        u = (pts[:, self._columns] - self._origin) / self._spacing  # (n, d) in voxels
        in_grid = np.all((u >= -_FOV_TOL) & (u <= self._shape - 1 + _FOV_TOL), axis=1)
        in_window = np.all((u >= self._lo - _FOV_TOL) & (u <= self._hi - 1 + _FOV_TOL), axis=1)
        return int(np.count_nonzero(in_grid & ~in_window))

    # ------------------------------------------------------------------------------------
    def _window(
        self, region: ArrayLike | None, margin: int
    ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Voxel index range [lo, hi) along the active axes that covers ``region``."""
        if region is None:
            return np.zeros(self._shape.size, np.int64), self._shape.astype(np.int64)
        box = np.asarray(region, dtype=np.float64)
        if box.shape != (2, 3) or not np.isfinite(box).all():
            raise ValueError(
                f"region must be a finite (2, 3) box (rows: lower and upper corner, columns "
                f"x, y, z, mm); got shape {box.shape}"
            )
        u = (box[:, self._columns] - self._origin) / self._spacing  # (2, d) in voxels
        lo = np.floor(u.min(axis=0)).astype(np.int64) - margin
        hi = np.ceil(u.max(axis=0)).astype(np.int64) + 1 + margin
        lo = np.clip(lo, 0, self._shape - 2)  # at least two voxels: a box off the grid
        hi = np.clip(hi, lo + 2, self._shape)  # samples nothing but stays well formed
        return lo, hi

    def _release(self) -> NDArray[np.floating] | None:
        """Hand this sampler's tap buffer to a new sampler (this one cannot sample after)."""
        buffer, self._buffer, self._padded = self._buffer, None, None
        return buffer

    def _remodulate(
        self, pts: NDArray[np.float64], re: NDArray[np.floating], im: NDArray[np.floating]
    ) -> Any:
        """W(arg D + k·x) (n, ntag) from Re and Im of D (ntag, n), with the slice position
        along invariant axes."""
        # = np.angle(re + i im), (ntag, n); k·x (hundreds of rad) is added in float64
        phase = np.arctan2(im, re).astype(np.float64, copy=False)
        for c in range(3):  # k·x column by column (a (n, 3) @ (3, ntag) matmul is slower)
            coordinate = pts[None, :, c] if c in self._columns.tolist() else self._fixed[c]
            phase += self.wavevectors[:, c, None] * coordinate
        return np.ascontiguousarray(wrap(phase).T)

    def _evaluate(
        self, pts: NDArray[np.float64], *, derivatives: bool
    ) -> tuple[NDArray[np.floating], NDArray[np.floating], NDArray[np.bool_]]:
        """Spline values (nq, 2 ntag, n) in the coefficients' precision: Re then Im of D and
        of its derivative along each active axis (per voxel); ``|D|`` (ntag, n); validity per
        tag (n, ntag)."""
        n = pts.shape[0]
        d = len(self._active)
        ntag = self._ntag
        u, tag_ok = self._locate(pts)
        needed = tag_ok.any(axis=1)
        nq = 1 + d if derivatives else 1
        if needed.all():
            values = self._spline(u, nq)
        else:
            values = np.zeros((nq, 2 * ntag, n), dtype=self._padded_dtype)
            index = np.flatnonzero(needed)
            if index.size:
                values[..., index] = self._spline(u[index], nq)
        re, im = values[0, :ntag], values[0, ntag:]
        size = np.sqrt(re * re + im * im)  # = |D| (np.hypot guards overflow, 3x slower)
        # the masks say which tags were acquired where (per tag); the magnitude floor says
        # whether there is tissue signal at all, so it holds for every acquired tag at once
        # (near an edge one tag's magnitude can pass while another's fails: such a point
        # is background-contaminated for all of them)
        signal = np.all(((size >= self._floor[:, None]) & (size > 0)) | ~tag_ok.T, axis=0)
        if self._support is not None and needed.any():
            inside = np.zeros(n, dtype=bool)
            inside[needed] = self._support[tuple(np.rint(u[needed]).astype(np.int64).T)]
            signal &= inside
        valid_tags = tag_ok & signal[:, None]
        return values, size, valid_tags

    def _locate(self, pts: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Voxel coordinates (n, d) (clipped into the grid) and which tags acquired each point."""
        u = (pts[:, self._columns] - self._origin) / self._spacing  # (n, d) in voxels
        inside = np.all(np.isfinite(u), axis=1)
        # the prepared window: the whole grid unless a region was given
        inside &= np.all((u >= self._lo - _FOV_TOL) & (u <= self._hi - 1 + _FOV_TOL), axis=1)
        u = np.clip(np.where(inside[:, None], u, self._lo), self._lo, self._hi - 1)
        tag_ok = np.repeat(inside[:, None], self._ntag, axis=1)  # (n, ntag)
        if self._mask is not None and inside.any():
            nearest = tuple(np.rint(u[inside]).astype(np.int64).T)
            tag_ok[inside] = self._mask[(slice(None), *nearest)].T
        return u, tag_ok

    def _spline(self, u: NDArray[np.float64], nq: int) -> NDArray[np.floating]:
        """Spline value (q=0) and derivatives along each active axis (q=1..d) at ``u``.

        Returns shape (nq, channels, n): one contiguous row per quantity and channel, so that
        the per-point algebra downstream runs on contiguous rows (on (n, 3) slices of an
        (n, nq, channels) array numpy's inner loops are 3 long, several times slower).
        """
        runs, first, frac, offsets = self._taps(u)
        if self.order == 1:
            return self._linear(runs, first, frac, offsets, nq)
        padded = self._padded
        assert padded is not None  # checked by _taps
        taps = self.order + 1
        d = u.shape[1]
        nf = padded.shape[-1]
        # sort by voxel so gathers walk memory in order
        order = np.argsort(first, kind="stable")
        n = u.shape[0]
        # rows (q, channel), columns in the sorted order; in the coefficients' precision
        ordered = np.empty((nq * nf, n), dtype=padded.dtype)
        # separable contraction: the leading axes with their tensor-product weights (value,
        # and the derivative along each leading axis), then the last axis (value weights for
        # those, slope weights for the derivative along it)
        lead = d if nq > 1 else 1
        for s in range(0, u.shape[0], self.chunk_size):
            chunk = order[s : s + self.chunk_size]
            m = chunk.size
            weights = _weights(frac[chunk], self.order)
            gathered = runs[first[chunk, None] + offsets]  # (m, taps**(d-1)) runs
            gathered = gathered.view(padded.dtype).reshape(m, taps ** (d - 1), taps * nf)
            if d > 1:
                head = np.matmul(_tensor_weights(weights[:, :-1], lead), gathered)
            else:
                head = gathered  # (m, 1, taps * nf)
            # (m, lead, taps, nf) -> (m, taps, lead * nf): the last axis's taps as rows
            rows = head.reshape(m, lead, taps, nf).transpose(0, 2, 1, 3).reshape(m, taps, -1)
            last = np.matmul(weights[:, -1, : 1 if nq == 1 else 2], rows)  # (m, 1|2, lead*nf)
            ordered[: lead * nf, s : s + m] = last[:, 0].T
            if nq > 1:
                ordered[lead * nf :, s : s + m] = last[:, 1, :nf].T
        rank = np.empty_like(order)  # back to the points' own order
        rank[order] = np.arange(n)
        return np.take(ordered, rank, axis=1).reshape(nq, nf, n)

    def _linear(
        self,
        runs: NDArray[np.void],
        first: NDArray[np.int64],
        frac: NDArray[np.floating],
        offsets: NDArray[np.int64],
        nq: int,
    ) -> NDArray[np.floating]:
        """The linear spline of :meth:`_spline`: interpolation along one axis at a time.

        Each block of points is gathered once and turned channel-major, so that every step
        (the difference of a cell's two faces along an axis is the derivative there, their
        interpolation the value; derivatives along the axes done carry along) works on
        contiguous rows of a block. The points keep their own order: the tracker's points
        come cell by cell, already close in memory (a sort and its inverse cost more here
        than they save).
        """
        padded = self._padded
        assert padded is not None
        nf = padded.shape[-1]
        n, d = frac.shape
        out = np.empty((nq, nf, n), dtype=padded.dtype)
        block = 8 * self.chunk_size
        for s in range(0, n, block):
            m = min(block, n - s)
            taps = runs[first[s : s + m, None] + offsets].view(padded.dtype).reshape(m, -1)
            # (corner of the leading axes, face along the last axis, channel, point)
            faces = np.ascontiguousarray(taps.T).reshape(-1, 2, nf, m)
            t = np.ascontiguousarray(frac[s : s + m].T)  # (d, m)
            slopes = [faces[:, 1] - faces[:, 0]]  # along axis d-1
            value = faces[:, 0] + t[d - 1] * slopes[0]
            for a in range(d - 2, -1, -1):  # pairs of corners along axis a, innermost first
                pair = value.reshape(-1, 2, nf, m)
                along = [q.reshape(-1, 2, nf, m) for q in slopes] if nq > 1 else []
                slopes = [q[:, 0] + t[a] * (q[:, 1] - q[:, 0]) for q in along]
                slopes.append(pair[:, 1] - pair[:, 0])
                value = pair[:, 0] + t[a] * slopes[-1]
            out[0, :, s : s + m] = value[0]
            for j in range(1, nq):  # slopes run from axis d-1 down to axis 0
                out[j, :, s : s + m] = slopes[d - j][0]
        return out

    def _taps(
        self, u: NDArray[np.float64]
    ) -> tuple[NDArray[np.void], NDArray[np.int64], NDArray[np.floating], NDArray[np.int64]]:
        """Where each point's spline taps are, as :meth:`_spline` gathers them.

        Returns ``runs`` (one opaque item per run of ``order + 1`` consecutive voxels along
        the last axis, all channels: one gather index fetches a whole run; runs overlap, one
        voxel apart, and numpy copies an item as a block, twice as fast as a (taps, nf)
        subarray), the index ``first`` (n,) of each point's first run, its fraction
        ``frac`` (n, d) within its cell in the coefficients' precision (no promoted copy of
        the gathered taps), and the ``offsets`` of the runs of one point's taps along the
        leading axes.
        """
        padded = self._padded
        if padded is None:
            raise RuntimeError(
                "this PhaseSampler handed its buffers to another one (reuse=); sample with that"
            )
        taps = self.order + 1
        d = u.shape[1]
        pshape = padded.shape[:-1]
        nf = padded.shape[-1]
        nvox = padded.size // nf
        runs = np.ndarray(
            shape=(nvox - taps + 1,),
            dtype=np.dtype((np.void, taps * nf * padded.itemsize)),
            buffer=np.ascontiguousarray(padded),
            strides=(nf * padded.itemsize,),
        )
        strides = np.cumprod((*pshape[1:], 1)[::-1])[::-1]  # element strides of the grid
        offsets = np.zeros(1, dtype=np.int64)
        for a in range(d - 1):
            offsets = (offsets[:, None] + strides[a] * np.arange(taps)).ravel()
        # padded index of the first tap: cubic taps i-1..i+2, linear taps i..i+1 (pad of 1)
        start = 0 if self.order == 3 else 1
        u = u - self._lo + self._before  # index in the extended window
        extended = self._hi - self._lo + self._before + self._after
        cell = np.clip(np.floor(u).astype(np.int64), 0, extended - 2)
        frac = (u - cell).astype(padded.dtype, copy=False)
        return runs, (cell + start) @ strides[:d], frac, offsets


def _floating(values: ArrayLike) -> NDArray[np.floating]:
    """``values`` as float32 or float64 (other dtypes become float64), without a copy."""
    array = np.asarray(values)
    return array if array.dtype in (np.float32, np.float64) else array.astype(np.float64)


def _as_points(points: ArrayLike) -> NDArray[np.float64]:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3) with columns (x, y, z); got {pts.shape}")
    return pts


def _check_structure(ds: xr.Dataset) -> None:
    problems = []
    for name in ("phase", "magnitude"):
        if name not in ds.variables:
            problems.append(f"missing data variable {name!r}; PhaseSampler needs a phase/1 dataset")
        elif set(ds[name].dims) != {"tag", "time", *GRID_DIMS}:
            problems.append(
                f"{name!r} has dims {ds[name].dims}; expected ('tag', 'time', 'z', 'y', 'x')"
            )
    for name in ("tag_direction", "tag_frequency", *GRID_DIMS):
        if name not in ds.variables:
            problems.append(f"missing coordinate {name!r}; PhaseSampler needs a phase/1 dataset")
    if problems:
        raise SchemaError(problems)


def reference_phase(
    phase_ds: xr.Dataset, points: ArrayLike, **kwargs: Any
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Phase of every tag at reference positions (time index 0): φ0(X).

    Parameters
    ----------
    phase_ds : xarray.Dataset
        A ``phase/1`` dataset.
    points : array_like, shape (n, 3)
        Reference positions X in mm, columns (x, y, z).
    **kwargs
        Passed to :class:`PhaseSampler` (``order``, ``magnitude_floor``, ``chunk_size``).

    Returns
    -------
    phi0 : numpy.ndarray, shape (n, ntag)
        Wrapped phase in rad (0 where invalid).
    valid : numpy.ndarray of bool, shape (n,)
        See :meth:`PhaseSampler.sample`.
    """
    return PhaseSampler(phase_ds, 0, **kwargs).phase(points)
