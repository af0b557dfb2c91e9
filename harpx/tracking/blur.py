r"""The band-pass blur of the harmonic phase, predicted from a tracked motion and removed.

The phase the tracker follows is the angle of a *band-passed* harmonic image. In the
demodulated frame of a tag with wave vector :math:`k` the band-pass is a low-pass
:math:`K` (the disk of ``radius`` × the tag frequency), and the measured image at a point
:math:`x` is

.. math::

    H(x) = \int K(x - x(X))\, \rho_0(X)\, e^{-i k \cdot u(X)}\, dX,

an average over the tissue within the filter's reach (a few mm) of the phase
:math:`-k\cdot u` each material point carries; with spin density conserved,
:math:`\rho(x)\,dx = \rho_0(X)\,dX`. Where the displacement varies across that reach —
the inner wall of a thickening myocardium moves more than the outer — and at the tissue's
edges, where the average takes in one side only, the measured phase is pulled towards its
neighbours: the wall seems to thicken less than it does, and a nearly incompressible model
infers too little through-plane shortening from it.

Given a tracked motion :math:`u`, that bias is predictable: splatting the material points'
phase factors :math:`\rho_0 e^{-ik\cdot u}` onto the image grid at their current
positions gives the unblurred signal :math:`S`, and :math:`K * S` its band-passed image, so

.. math:: c(x) = \arg\big((K * S)(x)\, \overline{S(x)}\big)

is the phase the filter adds at :math:`x` (rad, zero outside the tissue). The tracker
subtracts it from the measured phase and tracks again (``blur_passes``): the data term
then compares the model with images that are consistent with it, not with a blurred
version of them. One pass is the default (what it buys on each scene:
``benchmarks/results/tracking_defaults.md``).

Slice profile
-------------
A slice of thickness :math:`h` centred at :math:`c_s` along the tag's slice axis
:math:`\zeta` measures the tissue's signal integrated over its slab (a boxcar profile),
and the images on the common grid interpolate those slices linearly in the slice
position (:func:`harpx.imaging.stacks.resample_stack`; the nearest slice between the
outermost centre and the slab face, nothing outside the slabs). With the tag's component
:math:`k_\zeta` along the slice axis carried along, the demodulated image of a grid plane
:math:`\zeta_j` is

.. math::

    M(\zeta_j) = \sum_s L_{js}\, \frac{1}{h} \int_{c_s - h/2}^{c_s + h/2}
        S(\zeta)\, e^{i k_\zeta (\zeta - \zeta_j)}\, d\zeta
      \approx \sum_i T_{ji}\, S(\zeta_i), \qquad
    T = E^{*} L W E,

with :math:`W_{si}` the overlap of plane :math:`i`'s cell with slab :math:`s` divided by
:math:`h`, :math:`L_{js}` the linear-interpolation weights between slice centres and
:math:`E = \mathrm{diag}(e^{i k_\zeta \zeta_i})`. :math:`T` acts along the slice axis
and commutes with the in-plane filter, so the ``"slice-profile"`` model predicts

.. math:: c(x) = \arg\big((K * T S)(x)\, \overline{S(x)}\big),

the phase of the measured image minus that of the ideal (unblurred) tag pattern at the
voxel. It needs each tag's slice thickness and slice centres, the ``slice_thickness``
(tag) and ``slice_position`` (tag, slice) coordinates of ``phase/1``
(:func:`harpx.imaging.harp.slice_geometry`); a tag without them, or whose grid does not
resolve its slab (spacing along the slice axis above half the thickness), keeps the
``"in-plane"`` model (:func:`blur_models` says which each tag gets).

The slice-profile prediction places the tissue within each slab by the tracked motion
along the slice axis. Where no tag sees that direction (the apical cap of a ventricle that
only long-axis slices image, whose in-plane motion across those slices no tag measures),
that placement is the model's guess, and a wrong guess biases the correction the way the
model already errs: there the correction falls back to the in-plane model. Each voxel's
correction blends the two models' phases with the seen fraction of the slice axis
(:func:`~harpx.tracking.slab.axis_seen`: from the tags whose masks hold the tissue's
reference voxel), density-weighted over the tissue splatted into the voxel (1: the
slice-profile model, 0: the in-plane one). Short-axis stacks alone (x and y tags) leave
the through-plane direction unseen everywhere: their correction is the in-plane one.

Assumptions: the tagged signal near the body comes from the body alone (``body`` density
of the images where given, else uniform inside the mesh), the tag fading is uniform, the
slice profile is a boxcar of the nominal thickness (a real excitation profile is smoother
and wider at its feet), the two interpolations of the data (slices to the common grid, that
grid to the refined phase grid) are modelled as one, and the splatted signal is piecewise
constant over a grid cell along the slice axis. The ``"in-plane"`` model treats each slice
as a plane of the refined grid. Where other tagged tissue borders the body, the correction
at that border is too small.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import xarray as xr
from scipy import sparse
from xarray.backends import BackendArray
from xarray.core import indexing

from harpx._typing import FloatArray
from harpx.imaging.fft import inplace_plans
from harpx.imaging.phase_parameters import PhaseParameters
from harpx.imaging.sample import wrap
from harpx.mechanics.locate import interpolation_matrix
from harpx.schema import GRID_DIMS
from harpx.tracking.slab import (
    SEEN_TOLERANCE,
    axis_seen,
    blend_corrections,
    grid_spacing,
    slab_geometry,
    slice_operator,
)

__all__ = [
    "BLUR_MODELS",
    "SIGNAL_FLOOR",
    "blur_correction",
    "blur_models",
    "deblurred",
    "lazily_deblurred",
    "splat",
    "splat_operator",
]

#: Splatted signal below this fraction of its largest modulus counts as outside the tissue.
SIGNAL_FLOOR = 1e-3

#: Tissue points splatted at once (their work arrays are a few MB).
_SPLAT_PART = 1 << 16

#: Forward models of the blur (module notes): the in-plane band-pass alone, or with each
#: tag's slice profile where the phase carries its slice geometry.
BLUR_MODELS = ("in-plane", "slice-profile")


def splat_operator(
    positions: FloatArray,
    origin: FloatArray,
    spacing: FloatArray,
    shape: tuple[int, int, int],
    dtype: type[np.floating] = np.float64,
) -> sparse.csc_matrix:
    """Trilinear spreading of values at ``positions`` onto a grid, as a sparse matrix.

    Parameters
    ----------
    positions : ndarray, shape (n, 3)
        Positions (z, y, x), mm.
    origin, spacing : ndarray, shape (3,)
        First voxel centre and voxel spacing (z, y, x), mm.
    shape : (int, int, int)
        Grid size (z, y, x).
    dtype : numpy floating type, default float64
        Precision of the weights (float32 halves the memory traffic of the product).

    Returns
    -------
    scipy.sparse.csc_matrix, shape (nz * ny * nx, n)
        Column ``j`` holds the 8 trilinear weights of point ``j`` at its cell's corners
        (row-major voxel index); corners beyond the grid get weight 0. ``P @ values`` spreads
        values of shape (n,) or (n, k) at once.
    """
    f = (np.asarray(positions, dtype=np.float64) - origin) / spacing
    base = np.floor(f)
    t = f - base
    corner = base.astype(np.int64)
    n = f.shape[0]
    size = int(np.prod(shape))
    index_type = np.int32 if size < np.iinfo(np.int32).max else np.int64
    # corner (dz, dy, dx) of point j at [j, dz, dy, dx]: one broadcast axis per grid axis
    flat = np.zeros((n, 1, 1, 1), dtype=index_type)
    weight = np.ones((n, 1, 1, 1), dtype=dtype)
    stride = 1
    for axis in (2, 1, 0):
        index = corner[:, axis, None] + np.arange(2)  # (n, 2)
        ok = (index >= 0) & (index < shape[axis])
        w = np.stack([1.0 - t[:, axis], t[:, axis]], axis=1)
        along = [n, 1, 1, 1]
        along[1 + axis] = 2
        flat = flat + (np.where(ok, index, 0) * stride).astype(index_type).reshape(along)
        weight = weight * np.where(ok, w, 0.0).astype(dtype).reshape(along)
        stride *= shape[axis]
    return sparse.csc_matrix(
        (weight.reshape(-1), flat.reshape(-1), np.arange(0, 8 * n + 1, 8, dtype=index_type)),
        shape=(size, n),
    )


def splat(
    values: np.ndarray,
    positions: FloatArray,
    origin: FloatArray,
    spacing: FloatArray,
    shape: tuple[int, int, int],
) -> np.ndarray:
    """Add complex ``values`` at ``positions`` onto a grid with trilinear weights.

    Parameters
    ----------
    values : ndarray of complex, shape (n,)
        Values to spread.
    positions : ndarray, shape (n, 3)
        Positions (z, y, x), mm, as for :func:`splat_operator`.
    origin, spacing : ndarray, shape (3,)
        First voxel centre and voxel spacing (z, y, x), mm.
    shape : (int, int, int)
        Grid size (z, y, x).

    Returns
    -------
    ndarray of complex, shape ``shape``
        Sum of the weighted values per voxel (values beyond the grid are dropped).

    Examples
    --------
    >>> out = splat(np.array([1.0 + 0j]), np.array([[0.0, 0.5, 0.25]]), np.zeros(3),
    ...             np.ones(3), (1, 2, 2))
    >>> out.real.round(3).tolist()
    [[[0.375, 0.125], [0.375, 0.125]]]
    """
    P = splat_operator(positions, origin, spacing, shape)
    return np.asarray(P @ np.asarray(values, dtype=np.complex128)).reshape(shape)


def _disk(phase: xr.Dataset, tag: Any, shape: tuple[int, ...], spacing: FloatArray) -> tuple:
    """Low-pass disk of a tag in its slice plane, shape (plane axis 1, plane axis 2), and the
    grid axis normal to the plane."""
    one = phase.sel(tag=tag)
    normal = str(one["slice_axis"].values)
    plane = [a for a, d in enumerate(GRID_DIMS) if d != normal]
    d1, d2 = (float(one["tag_direction"].sel(axis=GRID_DIMS[a])) for a in plane)
    f_plane = float(one["tag_frequency"]) * float(np.hypot(d1, d2))
    radius = PhaseParameters.from_dataset(phase).radius * f_plane
    nu = [np.fft.fftfreq(shape[a], spacing[a]) for a in plane]
    disk = (nu[0][:, None] ** 2 + nu[1][None, :] ** 2) <= radius**2
    return disk, GRID_DIMS.index(normal)


def blur_models(phase: xr.Dataset, model: str = "slice-profile") -> list[str]:
    """The blur model each tag of ``phase`` gets when ``model`` is asked for (module notes).

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` images.
    model : {"slice-profile", "in-plane"}, default "slice-profile"
        ``"slice-profile"`` models the slice profile of every tag whose slice geometry the
        phase carries (and its grid resolves) and whose slice axis some tag sees (in the
        voxels no tag sees it, its correction is the in-plane one: module notes); the
        others, and every tag with ``"in-plane"``, get the in-plane band-pass alone.

    Returns
    -------
    list of str
        ``"slice-profile"`` or ``"in-plane"`` per tag, in the order of ``phase.tag``.

    Raises
    ------
    ValueError
        If ``model`` is not one of :data:`BLUR_MODELS`.
    """
    if model not in BLUR_MODELS:
        raise ValueError(f"blur model {model!r}; expected one of {list(BLUR_MODELS)!r}")
    spacing = grid_spacing(phase)
    spanned = axis_seen(phase.drop_vars("mask", errors="ignore"), np.zeros(1, dtype=np.int64))[0]
    return [
        "slice-profile"
        if model == "slice-profile"
        and slab_geometry(phase, t, spacing) is not None
        and spanned[2 - GRID_DIMS.index(str(np.asarray(phase["slice_axis"].values)[t]))]
        >= 1.0 - SEEN_TOLERANCE
        else "in-plane"
        for t in range(phase.sizes["tag"])
    ]


def _filtered_phase(
    S: np.ndarray,
    disk: np.ndarray,
    normal: int,
    out: np.ndarray,
    plans: Callable[[tuple[int, ...]], tuple[np.ndarray, Any, Any]],
    work: np.ndarray,
    has: np.ndarray,
    box: tuple[slice, ...],
    profile: np.ndarray | None = None,
) -> None:
    """Write ``arg((K * T S) conj S)`` into ``out`` where ``S`` carries signal (module notes).

    ``T S`` (``profile`` applied along grid axis ``normal``; ``S`` itself when None) is
    low-passed slice by slice (planes normal to ``normal``) with ``disk`` in single precision
    (the correction is a fraction of a radian; float32 keeps it to ~1e-6 rad), in place in
    the buffer of ``plans(shape)`` (buffer, forward, backward); the inverse transform is left
    unnormalised, which the angle ignores. ``out`` is the box ``box`` (z, y, x slices) of
    the grid, outside which ``S`` is 0: the angle is taken in the box only. ``S`` is
    conjugated in place in the box; ``work`` (float32) and ``has`` (bool), of at least the
    box's size, are work arrays.
    """
    stack = np.moveaxis(S, normal, 0)  # (slices, plane 1, plane 2): the plane axes keep order
    buffer, forward, backward = plans(stack.shape)
    if profile is None:
        np.copyto(buffer, stack)
    else:  # T along the slices, written straight into the buffer
        np.matmul(
            profile.astype(np.complex64),
            stack.reshape(stack.shape[0], -1),
            out=buffer.reshape(stack.shape[0], -1),
        )
    forward.execute()
    buffer *= disk
    backward.execute()
    # S is 0 outside the box: its largest |S|² and every voxel with signal lie inside it
    inner = (box[normal], *(b for a, b in enumerate(box) if a != normal))  # in stack order
    signal, filtered = stack[inner], buffer[inner]
    size = int(np.prod(signal.shape))
    power = work[:size].reshape(signal.shape)
    np.multiply(signal.real, signal.real, out=power)  # |S|², no square roots
    power += signal.imag * signal.imag
    mask = has[:size].reshape(signal.shape)
    np.greater(power, SIGNAL_FLOOR**2 * power.max(initial=0.0), out=mask)
    np.conjugate(signal, out=signal)
    filtered *= signal
    angle = np.arctan2(filtered.imag, filtered.real, out=power)
    np.copyto(out, np.moveaxis(angle, 0, normal), where=np.moveaxis(mask, 0, normal))


class _CorrectionFrames:
    """The correction of :func:`blur_correction` frame by frame.

    ``support`` is the box (z, y, x slices) of the voxels the splatted tissue reaches in some
    frame, outside which every correction is 0. Iterating yields ``(n, c)`` for every frame
    ``n >= 1``, ``c`` float32 (tag, box z, box y, box x) in rad, the correction in that box,
    one buffer overwritten by the next frame: one frame's work arrays are held, never the
    grid-sized result of every frame.
    """

    def __init__(
        self, phase: xr.Dataset, body: Any, U: FloatArray, model: str = "slice-profile"
    ) -> None:
        nz, ny, nx = (phase.sizes[d] for d in GRID_DIMS)
        shape = (nz, ny, nx)
        coords = [np.asarray(phase[d].values, dtype=np.float64) for d in GRID_DIMS]
        origin = np.array([c[0] for c in coords])
        spacing = grid_spacing(phase)
        models = blur_models(phase, model)
        lo = body.dof_points.min(axis=0) - 1e-9  # (x, y, z)
        hi = body.dof_points.max(axis=0) + 1e-9
        # the voxel centres in the body's bounding box, C order over (z, y, x): the grid is
        # separable, so the box is found axis by axis (harpx.tracking.results.grid_points order)
        inbox = [np.flatnonzero((c >= lo[2 - a]) & (c <= hi[2 - a])) for a, c in enumerate(coords)]
        voxels = np.ravel_multi_index(np.meshgrid(*inbox, indexing="ij"), shape).ravel()
        Z, Y, X = np.meshgrid(*(c[i] for c, i in zip(coords, inbox, strict=True)), indexing="ij")
        points = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
        del X, Y, Z
        if "body" in phase.variables:
            density = np.asarray(phase["body"].transpose(*GRID_DIMS).values, dtype=np.float64)
            keep = density.reshape(-1)[voxels] > 0
            voxels, points = voxels[keep], points[keep]
            density = density.reshape(-1)[voxels]
        else:
            density = np.ones(voxels.size)
        tissue, interpolate = interpolation_matrix(body, points)  # centres in the reference
        self.reference, self.density = points[tissue], density[tissue]
        # seen fraction of each image axis (x, y, z) at the tissue's voxels (module notes)
        self.seen = axis_seen(phase, voxels[tissue])
        del points, voxels
        # the tissue's points in parts: one part's work arrays at a time
        self.parts = [
            (slice(a, a + _SPLAT_PART), interpolate[a : a + _SPLAT_PART])
            for a in range(0, self.reference.shape[0], _SPLAT_PART)
        ]
        del interpolate
        self.wavevector = (
            2.0
            * np.pi
            * np.asarray(phase["tag_frequency"].values, dtype=np.float64)[:, None]
            * np.asarray(phase["tag_direction"].transpose("tag", "axis").sel(axis=["x", "y", "z"]))
        )  # (tag, 3) rad/mm
        tags = list(phase["tag"].values)
        self.disks = [_disk(phase, tag, shape, spacing) for tag in tags]
        self.profiles: list[np.ndarray | None] = []
        for t, (_, normal) in enumerate(self.disks):
            slab = slab_geometry(phase, t, spacing) if models[t] == "slice-profile" else None
            # k_ζ in the grid's (z, y, x) order: wavevector is (x, y, z)
            self.profiles.append(
                None
                if slab is None
                else slice_operator(coords[normal], *slab, float(self.wavevector[t, 2 - normal]))
            )
        # tags whose slice-profile correction falls back to the in-plane one where their slice
        # axis is unseen (module notes): (tag, image axis of the slice normal)
        self.blended = [
            (t, 2 - normal)
            for t, (_, normal) in enumerate(self.disks)
            if self.profiles[t] is not None
            and self.seen[:, 2 - normal].min(initial=1.0) < 1.0 - SEEN_TOLERANCE
        ]
        # a tag's images hold only the tissue inside its acquisition (slab, field of view)
        self.outside = (
            [~a if not a.all() else None
             for a in np.asarray(phase["mask"].transpose("tag", *GRID_DIMS).values, dtype=bool)]
            if "mask" in phase.variables
            else [None] * len(tags)
        )  # fmt: skip
        self.shape, self.origin, self.spacing = shape, origin, spacing
        self.U = np.asarray(U, dtype=np.float64)
        self.ntag = len(tags)
        # the splat reaches the 8 voxels around each moved point (module notes)
        low, high = np.array(shape), np.zeros(3, dtype=np.int64)
        for n in range(1, self.U.shape[0]):
            for part in range(len(self.parts)):
                moved = self._moved(n, part)[0]
                if moved.shape[0]:
                    f = np.floor((moved - origin) / spacing)
                    low = np.minimum(low, f.min(axis=0).astype(np.int64))
                    high = np.maximum(high, f.max(axis=0).astype(np.int64) + 2)
        low, high = np.clip(low, 0, shape), np.clip(high, 0, shape)
        self.support: tuple[slice, ...] = tuple(
            slice(int(a), int(max(a, b))) for a, b in zip(low, high, strict=True)
        )

    def _moved(self, n: int, part: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Positions (z, y, x) in frame ``n`` of the tissue's voxel centres of one part, mm,
        with their displacement (x, y, z) and density; points without a finite displacement
        left out (the last item: which of the part's points are kept)."""
        nnode = self.U.shape[1] // 3
        rows, interpolate = self.parts[part]
        un = np.asarray(interpolate @ self.U[n].reshape(nnode, 3))  # (voxel, 3) mm
        here, rho = self.reference[rows], self.density[rows]
        ok = np.isfinite(un).all(axis=1)
        if not ok.all():
            un, here, rho = un[ok], here[ok], rho[ok]
        return (here + un)[:, ::-1], un, rho, ok

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        shape, ntag = self.shape, self.ntag
        size = int(np.prod(shape))
        cached: dict[tuple[int, ...], tuple[np.ndarray, Any, Any]] = {}
        runs = (self.U.shape[0] - 1) * ntag  # executions of a plan at most

        def plans(stack: tuple[int, ...]) -> tuple[np.ndarray, Any, Any]:
            if stack not in cached:  # every slice orientation transforms in one buffer
                memory = next(iter(cached.values()))[0] if cached else None
                cached[stack] = inplace_plans(
                    stack, np.complex64, (-2, -1), memory=memory, executions=runs
                )
            return cached[stack]

        S = np.zeros(shape, dtype=np.complex64)
        # the signal is splatted onto the support box only (zero elsewhere)
        box = self.support
        inner = tuple(b.stop - b.start for b in box)
        out = np.empty((ntag, *inner), dtype=np.float32)
        corner = self.origin + self.spacing * np.array([b.start for b in box])
        work, has = np.empty(size, dtype=np.float32), np.empty(size, dtype=bool)
        blended = dict(self.blended)  # tag -> image axis of its slice normal
        # spread's columns: cos, sin per tag, then ρ (column 2 ntag) and ρ w per blended tag
        column = {t: 2 * ntag + 1 + k for k, t in enumerate(blended)}
        plain = np.empty(inner if blended else 0, dtype=np.float32)

        def filtered(
            spread: np.ndarray, t: int, profile: np.ndarray | None, target: np.ndarray
        ) -> None:
            """Tag ``t``'s correction in the box into ``target`` (one model)."""
            target[...] = 0.0
            S[...] = 0.0
            S[box].real = spread[:, t].reshape(inner)
            S[box].imag = spread[:, ntag + t].reshape(inner)
            if self.outside[t] is not None:
                np.copyto(S, 0.0, where=self.outside[t])
            disk, normal = self.disks[t]
            _filtered_phase(S, disk, normal, target, plans, work, has, box, profile)

        for n in range(1, self.U.shape[0]):  # one splat of every tag and one filter per tag
            out[...] = 0.0
            columns = 2 * ntag + (1 + len(blended) if blended else 0)
            spread = np.zeros((int(np.prod(inner)), columns), dtype=np.float32)
            for part in range(len(self.parts)):
                moved, un, rho, kept = self._moved(n, part)
                angle = np.einsum("pi,ti->pt", un, self.wavevector)  # (point, tag) rad
                del un
                # ρ0 e^{-ik·u} as real and imaginary columns: one real sparse product spreads
                # all (in single precision, as S is filtered: the correction keeps ~1e-6 rad)
                signals = np.empty((angle.shape[0], columns), dtype=np.float32)
                np.cos(angle, out=signals[:, :ntag])
                np.sin(angle, out=signals[:, ntag : 2 * ntag])
                del angle
                signals[:, ntag : 2 * ntag] *= -1.0
                if blended:  # the density and its share whose slice axis a tag sees
                    seen = self.seen[self.parts[part][0]][kept]
                    signals[:, 2 * ntag] = 1.0
                    for t, axis in blended.items():
                        signals[:, column[t]] = seen[:, axis]
                signals *= rho[:, None]
                spread += splat_operator(moved, corner, self.spacing, inner, np.float32) @ signals
                del moved, signals
            for t in range(ntag):  # ≤ 3 tags
                filtered(spread, t, self.profiles[t], out[t])
                if t in blended:  # and the in-plane model, where the slice axis is unseen
                    filtered(spread, t, None, plain)
                    blend_corrections(out[t], plain, spread[:, column[t]], spread[:, 2 * ntag])
            del spread
            yield n, out


def blur_correction(
    phase: xr.Dataset, body: Any, U: FloatArray, model: str = "slice-profile"
) -> np.ndarray:
    """Phase the band-pass adds to each tag's image under the motion ``U`` (module notes).

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` images (their grid, tags and band-pass ``radius``); ``body`` (z, y, x)
        density, ``slice_thickness`` and ``slice_position`` if present.
    body : Body
        The tracked body (reference configuration), mm.
    U : ndarray, shape (ntime, ndof)
        Tracked displacement per frame, mm.
    model : {"slice-profile", "in-plane"}, default "slice-profile"
        Forward model (module notes); ``"slice-profile"`` falls back to ``"in-plane"`` for
        tags whose slice geometry the phase does not carry (:func:`blur_models`).

    Returns
    -------
    ndarray, shape (tag, time, z, y, x)
        Correction c in rad (0 in frame 0 and outside the tissue): subtract it from
        ``phase`` before tracking again.
    """
    out = np.zeros((phase.sizes["tag"], phase.sizes["time"], *(phase.sizes[d] for d in GRID_DIMS)),
                   dtype=np.float32)  # fmt: skip
    frames = _CorrectionFrames(phase, body, U, model)
    for n, frame in frames:
        out[:, n][(slice(None), *frames.support)] = frame
    return out


def deblurred(phase: xr.Dataset, correction: np.ndarray) -> xr.Dataset:
    """``phase`` with ``correction`` (rad, as from :func:`blur_correction`) removed, wrapped.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` images.
    correction : ndarray, shape (tag, time, z, y, x)
        Phase to subtract, rad, as from :func:`blur_correction`; voxels where it is 0 keep
        their phase unchanged.

    Returns
    -------
    xarray.Dataset
        A copy of ``phase`` whose ``phase`` variable (tag, time, z, y, x) is
        ``W(phase − correction)`` where the correction is non-zero, rad.
    """
    values = np.asarray(phase["phase"].transpose("tag", "time", *GRID_DIMS).values)
    corrected = values.copy()
    for n in range(values.shape[1]):  # frame by frame: temporaries of one frame only
        moved = correction[:, n] != 0  # the correction is zero outside the tissue
        if moved.any():
            target = corrected[:, n]
            target[moved] = wrap(values[:, n][moved] - correction[:, n][moved])
    out = phase.copy()
    out["phase"] = (("tag", "time", *GRID_DIMS), corrected, phase["phase"].attrs)
    return out


class _CorrectedPhase(BackendArray):
    """Phase (tag, time, z, y, x) of ``source`` with each frame ``n >= 1``'s box ``box``
    (z, y, x slices) replaced by ``blocks[n - 1]``, built frame by frame when read (xarray
    indexes it lazily: a frame read costs one copy of that frame)."""

    def __init__(self, source: Any, box: tuple[slice, ...], blocks: np.ndarray) -> None:
        self.source, self.box, self.blocks = source, box, blocks
        self.shape = tuple(int(n) for n in source.shape)
        self.dtype = np.dtype(source.dtype)

    def __getitem__(self, key: indexing.ExplicitIndexer) -> np.ndarray:
        return indexing.explicit_indexing_adapter(
            key, self.shape, indexing.IndexingSupport.BASIC, self._read
        )

    def _frame(self, n: int) -> np.ndarray:
        frame = np.array(self.source[:, n])  # a copy (computed, if dask-backed)
        if n:
            frame[(slice(None), *self.box)] = self.blocks[n - 1]
        return frame

    def _read(self, key: tuple) -> np.ndarray:
        key = (*key, *(slice(None),) * (len(self.shape) - len(key)))
        rest = (key[0], *key[2:])
        if isinstance(key[1], int | np.integer):
            return self._frame(int(key[1]))[rest]
        frames = [self._frame(n)[rest] for n in range(self.shape[1])[key[1]]]
        if not frames:  # an empty selection: its shape, no data
            return np.broadcast_to(np.zeros((), self.dtype), self.shape)[key].copy()
        return np.stack(frames, axis=1)


def lazily_deblurred(
    phase: xr.Dataset, body: Any, U: FloatArray, model: str = "slice-profile"
) -> tuple[xr.Dataset, np.ndarray]:
    """``deblurred(phase, blur_correction(phase, body, U, model))`` without a grid-sized copy,
    and the mean absolute correction per frame (rad, over the voxels that carry one).

    The corrected phase is lazy (:class:`_CorrectedPhase`): a frame is built when read from
    ``phase`` and the corrected values, which are held only in the box of the voxels the
    splatted tissue reaches (:class:`_CorrectionFrames`), in one array. Values equal
    :func:`deblurred`'s.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` images, as for :func:`blur_correction`.
    body : Body
        The tracked body (reference configuration), mm.
    U : ndarray, shape (ntime, ndof)
        Tracked displacement per frame, mm.
    model : {"slice-profile", "in-plane"}, default "slice-profile"
        Forward model, as for :func:`blur_correction`.

    Returns
    -------
    corrected : xarray.Dataset
        ``phase`` with its ``phase`` variable (tag, time, z, y, x, rad) corrected and read
        lazily, frame by frame.
    mean : ndarray, shape (ntime,)
        Mean absolute correction per frame, rad, over the voxels that carry one (0 in frame 0).
    """
    ntag, ntime = phase.sizes["tag"], phase.sizes["time"]
    frames = _CorrectionFrames(phase, body, U, model)
    box = frames.support
    blocks = np.empty(
        (max(ntime - 1, 0), ntag, *(b.stop - b.start for b in box)), dtype=phase["phase"].dtype
    )
    mean = np.zeros(ntime)
    for n, correction in frames:
        total = np.count_nonzero(correction)
        if total:
            mean[n] = float(np.abs(correction).sum(dtype=np.float64)) / total
        block = blocks[n - 1]
        block[...] = (
            phase["phase"].isel(time=n).transpose("tag", *GRID_DIMS).values[(slice(None), *box)]
        )
        moved = correction != 0  # the correction is zero outside the tissue
        block[moved] = wrap(block[moved] - correction[moved])
    del frames
    source = phase["phase"].transpose("tag", "time", *GRID_DIMS).data  # numpy or dask
    out = phase.copy()
    out["phase"] = xr.Variable(
        ("tag", "time", *GRID_DIMS),
        indexing.LazilyIndexedArray(_CorrectedPhase(source, box, blocks)),
        phase["phase"].attrs,
    )
    return out, mean
