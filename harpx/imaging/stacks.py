r"""Slice stacks resampled onto a common grid, and the ``tagged/1`` datasets they make.

An acquisition images tissue in *stacks* of parallel 2D slices (short-axis slices carrying
the x and y tags, long-axis slices carrying the z tag, ...). harpx works on one Cartesian
grid, so every stack is resampled onto it, and where a stack has no data is recorded in the
tag's ``mask``. This module holds that one resampler (:func:`resample_stack`, used by the
DICOM reader, the synthetic scenes and anything else that acquires stacks) and the one
constructor of ``tagged/1`` datasets (:func:`tagged_dataset`).

Geometry of a stack (:class:`SliceStack`): pixel ``(i, j)`` (row ``i``, column ``j``) of the
slice at offset ``o`` along the normal sits at

.. math:: p = P + j\,\Delta c\, r + i\,\Delta r\, c + o\, n, \qquad n = r \times c,

with ``P`` the position of pixel (0, 0) of the offset-0 plane, ``r`` the (unit) direction of
increasing column index, ``c`` that of increasing row index and ``(Δr, Δc)`` the pixel
spacing (the DICOM convention, PS3.3 C.7.6.2.1.1).

Resampling and masks
--------------------
Each stack is interpolated (tri)linearly in its own (slice, row, column) index space; between
slices the interpolation is linear in the slice position, so uneven slice spacing is handled.
A grid point has data from a stack (``mask`` True) when

* in plane, it lies within the hull of the pixel centres (0 ≤ column ≤ columns − 1 and
  0 ≤ row ≤ rows − 1), where bilinear interpolation needs no extrapolation, and
* through plane, it lies in the stack's slab (:attr:`SliceStack.slab`, usually from half a
  slice thickness below the first slice centre to half a thickness above the last). Between
  the outermost slice centre and the slab face the nearest slice is used, since a slice's
  signal is an average over its thickness. Gaps between slices count as data.

Outside its mask a tag's image is 0. The mask is a fixed region of space (the field of view
and the slab), not the tissue: the tissue's support at the reference frame is ``body``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from harpx._typing import FloatArray
from harpx.imaging.tagged_shapes import check_tagged_shapes
from harpx.schema import AXES, GRID_DIMS, standard_attrs, validate

__all__ = [
    "ALIGNMENT_TOL",
    "SliceStack",
    "common_grid",
    "image_coords",
    "resample_stack",
    "resample_stacks",
    "slice_coords",
    "stacks_slice_geometry",
    "tagged_dataset",
]

_INDEX_EPS = 1e-6  # index units: rounding slack of the in-plane mask test
_SLAB_EPS = 1e-6  # mm: rounding slack of the through-plane mask test

#: Largest component of a stack's unit normal off its grid axis for the stack's slices to
#: count as planes of the grid (:meth:`SliceStack.centres_along`): 0.2 mm of tilt across a
#: 200 mm field of view.
ALIGNMENT_TOL = 1e-3

#: in-plane (row direction r, column direction c) of an axis-aligned stack normal to an axis,
#: chosen so that r x c is the axis itself (offsets increase with the coordinate)
_IN_PLANE = {"z": ("x", "y"), "y": ("z", "x"), "x": ("y", "z")}


@dataclass(frozen=True)
class SliceStack:
    """Geometry of one stack of parallel 2D slices (lengths in mm, patient/grid x-y-z).

    Attributes
    ----------
    origin : ndarray, shape (3,)
        Position of pixel (0, 0) of the offset-0 plane, mm.
    along_row : ndarray, shape (3,)
        Unit direction ``r`` of increasing column index.
    along_column : ndarray, shape (3,)
        Unit direction ``c`` of increasing row index.
    pixel_spacing : tuple of float
        ``(Δr, Δc)``: spacing between rows and between columns, mm.
    rows, columns : int
        Slice matrix size.
    offsets : ndarray, shape (S,)
        Slice positions along the normal ``n = r × c`` from ``origin``, increasing, mm.
    slab : tuple of float
        Through-plane extent ``(low, high)`` of the data along ``n`` from ``origin``, mm.
    """

    origin: FloatArray
    along_row: FloatArray
    along_column: FloatArray
    pixel_spacing: tuple[float, float]
    rows: int
    columns: int
    offsets: FloatArray
    slab: tuple[float, float]

    @property
    def normal(self) -> FloatArray:
        """Unit slice normal ``r × c``."""
        n = np.cross(self.along_row, self.along_column)
        return np.asarray(n / np.linalg.norm(n), dtype=np.float64)

    def centres_along(self, axis: str) -> FloatArray | None:
        """Slice centres as coordinates along a grid axis, when the slices are its planes.

        Parameters
        ----------
        axis : {"x", "y", "z"}
            The grid axis (a tag's ``slice_axis``).

        Returns
        -------
        ndarray, shape (S,), or None
            The ``axis`` coordinate of each slice centre in mm, increasing; None when the
            normal is tilted off ``axis`` by more than :data:`ALIGNMENT_TOL` (an oblique
            stack's slices are no planes of the grid, so their centres have no single
            coordinate along it).

        Raises
        ------
        ValueError
            If ``axis`` is not an axis name.
        """
        if axis not in AXES:
            raise ValueError(f"axis={axis!r}; expected one of {list(AXES)!r}")
        a = AXES.index(axis)
        normal = self.normal
        if np.max(np.abs(np.delete(normal, a))) > ALIGNMENT_TOL:
            return None
        centres = self.origin[a] + self.offsets * np.sign(normal[a])
        return np.asarray(np.sort(centres), dtype=np.float64)

    @property
    def affine(self) -> FloatArray:
        """Columns map (column index, row index, normal offset mm) to offsets from origin (mm)."""
        return np.column_stack(
            [
                self.along_row * self.pixel_spacing[1],
                self.along_column * self.pixel_spacing[0],
                self.normal,
            ]
        )

    def corners(self) -> tuple[FloatArray, FloatArray]:
        """Corners of the pixel-centre hull and of the slab.

        Returns
        -------
        hull, slab : ndarray, shape (8, 3)
            Corner positions (x, y, z) in mm.
        """

        def box(low: float, high: float) -> FloatArray:
            local = np.array(
                [
                    (j, i, o)
                    for j in (0.0, self.columns - 1.0)
                    for i in (0.0, self.rows - 1.0)
                    for o in (low, high)
                ]
            )
            return np.asarray(self.origin + local @ self.affine.T, dtype=np.float64)

        return box(float(self.offsets[0]), float(self.offsets[-1])), box(*self.slab)

    @classmethod
    def axis_aligned(
        cls, ds: xr.Dataset, slice_axis: str, *, thickness: float | None = None
    ) -> SliceStack:
        """The stack of images stored on a grid whose slices are normal to ``slice_axis``.

        Parameters
        ----------
        ds : xarray.Dataset
            Any dataset with evenly spaced ``z``, ``y``, ``x`` coordinates (mm), e.g. the
            output of :func:`harpx.imaging.synth.synthesize_tagged` on a slice lattice.
        slice_axis : {"x", "y", "z"}
            Axis normal to the slices.
        thickness : float, optional
            Slice thickness in mm (the slab reaches half of it beyond the outer slice
            centres). Default: ``ds.attrs["slice_thickness"]`` if set, else the slice spacing.

        Returns
        -------
        SliceStack
            Rows and columns follow the two other axes (``r × c`` along ``+slice_axis``);
            :meth:`volume` orders an array of ``ds`` accordingly.

        Raises
        ------
        ValueError
            If ``slice_axis`` is not an axis, or a single slice has no ``thickness``.
        """
        if slice_axis not in _IN_PLANE:
            raise ValueError(f"slice_axis={slice_axis!r}; expected one of {list(AXES)!r}")
        r_axis, c_axis = _IN_PLANE[slice_axis]
        values = {d: np.asarray(ds[d].values, dtype=np.float64) for d in AXES}
        offsets = values[slice_axis] - values[slice_axis][0]
        if thickness is None:
            thickness = ds.attrs.get("slice_thickness")
        if thickness is None:
            if offsets.size < 2:
                raise ValueError(
                    f"a single slice along {slice_axis!r} needs thickness= (mm): the slice "
                    "spacing cannot be read from one slice position"
                )
            thickness = float(offsets[1] - offsets[0])
        half = 0.5 * float(thickness)

        def step(d: str) -> float:
            v = values[d]
            return float(v[1] - v[0]) if v.size > 1 else 1.0

        unit = dict(zip(AXES, np.eye(3), strict=True))
        return cls(
            origin=np.array([values[d][0] for d in AXES]),
            along_row=unit[r_axis],
            along_column=unit[c_axis],
            pixel_spacing=(step(c_axis), step(r_axis)),
            rows=int(values[c_axis].size),
            columns=int(values[r_axis].size),
            offsets=offsets,
            slab=(float(offsets[0] - half), float(offsets[-1] + half)),
        )

    @staticmethod
    def volume(data: xr.DataArray, slice_axis: str) -> FloatArray:
        """The image array of an axis-aligned stack in stack order.

        Parameters
        ----------
        data : xarray.DataArray
            Images with dims (..., z, y, x).
        slice_axis : {"x", "y", "z"}
            The grid axis normal to the slices.

        Returns
        -------
        ndarray, shape (..., slice, row, column)
            ``data``'s values as float64, leading dims first.
        """
        r_axis, c_axis = _IN_PLANE[slice_axis]
        lead = [d for d in data.dims if d not in GRID_DIMS]
        return np.asarray(data.transpose(*lead, slice_axis, c_axis, r_axis).values, np.float64)


def common_grid(
    stacks: Sequence[SliceStack], spacing: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Isotropic voxel-centre coordinates ``(x, y, z)`` (mm) covering the union of the slabs.

    The grid is aligned so that its points fall on the pixel centres of an axis-aligned stack
    whose pixel spacing equals ``spacing`` (no in-plane interpolation in that case).

    Parameters
    ----------
    stacks : sequence of SliceStack
        The stacks to cover.
    spacing : float
        Grid spacing, mm.

    Returns
    -------
    tuple of ndarray
        ``x``, ``y``, ``z`` coordinates, mm.
    """
    hulls, slabs = zip(*(s.corners() for s in stacks), strict=True)
    centre_lo = np.min([h.min(axis=0) for h in hulls], axis=0)
    slab_lo = np.min([s.min(axis=0) for s in slabs], axis=0)
    slab_hi = np.max([s.max(axis=0) for s in slabs], axis=0)
    start = centre_lo - spacing * np.floor((centre_lo - slab_lo) / spacing + 1e-9)
    count = np.floor((slab_hi - start) / spacing + 1e-9).astype(int) + 1
    x, y, z = (start[a] + spacing * np.arange(count[a]) for a in range(3))
    return x, y, z


def resample_stack(
    stack: SliceStack, volume: ArrayLike, x: ArrayLike, y: ArrayLike, z: ArrayLike
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Resample one stack onto a grid: image (..., z, y, x) and mask (z, y, x).

    Parameters
    ----------
    stack : SliceStack
        The stack's geometry.
    volume : array_like, shape (..., S, rows, columns)
        Its images (any leading dims, e.g. (tag, time)).
    x, y, z : array_like
        Grid coordinates, mm.

    Returns
    -------
    image : ndarray, shape (..., z, y, x)
        Linear interpolation in (slice position, row, column); 0 outside the mask.
    mask : ndarray of bool, shape (z, y, x)
        Where the stack has data (module notes).

    Raises
    ------
    ValueError
        If the trailing shape of ``volume`` is not (slices, rows, columns) of ``stack``.
    """
    data = np.asarray(volume, dtype=np.float64)
    expected = (stack.offsets.size, stack.rows, stack.columns)
    if data.ndim < 3 or data.shape[-3:] != expected:
        raise ValueError(
            f"volume has shape {data.shape!r}; expected (..., {expected[0]}, {expected[1]}, "
            f"{expected[2]}) = (..., slices, rows, columns) of the stack"
        )
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    inverse = np.linalg.inv(stack.affine)
    dx, dy, dz = x - stack.origin[0], y - stack.origin[1], z - stack.origin[2]
    column, row, offset = (
        inverse[m, 0] * dx[None, None, :]
        + inverse[m, 1] * dy[None, :, None]
        + inverse[m, 2] * dz[:, None, None]
        for m in range(3)
    )
    mask = (
        (column >= -_INDEX_EPS)
        & (column <= stack.columns - 1 + _INDEX_EPS)
        & (row >= -_INDEX_EPS)
        & (row <= stack.rows - 1 + _INDEX_EPS)
        & (offset >= stack.slab[0] - _SLAB_EPS)
        & (offset <= stack.slab[1] + _SLAB_EPS)
    )
    slice_index = np.interp(offset[mask], stack.offsets, np.arange(stack.offsets.size))
    coords = np.stack([slice_index, row[mask], column[mask]])
    lead = data.shape[:-3]
    flat = data.reshape(-1, *expected)
    image = np.zeros((flat.shape[0], *mask.shape), dtype=np.float64)
    for k in range(flat.shape[0]):
        image[k][mask] = ndimage.map_coordinates(flat[k], coords, order=1, mode="nearest")
    return image.reshape(*lead, *mask.shape), mask


def _axis_aligned_stacks(
    stacks: Sequence[xr.Dataset],
) -> Iterator[tuple[xr.Dataset, str, SliceStack]]:
    """Each stack with its one ``slice_axis`` and its :meth:`SliceStack.axis_aligned`.

    Raises
    ------
    ValueError
        If the tags of one dataset have different slice axes.
    """
    for ds in stacks:
        axes = {str(s) for s in np.asarray(ds["slice_axis"].values)}
        if len(axes) != 1:
            raise ValueError(
                f"the tags of one stack must share a slice_axis, got {sorted(axes)!r}; "
                "pass one dataset per stack"
            )
        (axis,) = axes
        yield ds, axis, SliceStack.axis_aligned(ds, axis)


def resample_stacks(
    stacks: Sequence[xr.Dataset], x: ArrayLike, y: ArrayLike, z: ArrayLike
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Axis-aligned ``tagged/1`` stacks on their own slice lattices onto one common grid.

    Parameters
    ----------
    stacks : sequence of xarray.Dataset
        ``tagged/1`` datasets whose tags of one dataset share a ``slice_axis`` (e.g. from
        :func:`harpx.imaging.synth.synthesize_tagged` with ``slice_axis`` and the slice
        lattice as its grid), with ``attrs["slice_thickness"]`` or evenly spaced slices.
    x, y, z : array_like
        Common grid coordinates, mm.

    Returns
    -------
    image : ndarray, shape (tag, time, z, y, x)
        The tags of all stacks, in order (:func:`resample_stack`).
    mask : ndarray of bool, shape (tag, z, y, x)
        Each tag's field of view and slab.

    Raises
    ------
    ValueError
        If the tags of one dataset have different slice axes.
    """
    images, masks = [], []
    for ds, axis, stack in _axis_aligned_stacks(stacks):
        volume = SliceStack.volume(ds["image"].transpose("tag", "time", *GRID_DIMS), axis)
        image, mask = resample_stack(stack, volume, x, y, z)
        images.append(image)
        masks.append(np.broadcast_to(mask, (image.shape[0], *mask.shape)))
    return np.concatenate(images, axis=0), np.concatenate(masks, axis=0)


def stacks_slice_geometry(stacks: Sequence[xr.Dataset]) -> tuple[FloatArray, list[FloatArray]]:
    """Slice thickness and slice centres of every tag of the stacks :func:`resample_stacks` takes.

    Parameters
    ----------
    stacks : sequence of xarray.Dataset
        As for :func:`resample_stacks`: axis-aligned ``tagged/1`` stacks on their own slice
        lattices (``attrs["slice_thickness"]`` or evenly spaced slices).

    Returns
    -------
    thickness : ndarray, shape (tag,)
        Each tag's slice thickness, mm (the slab of :meth:`SliceStack.axis_aligned`).
    positions : list of ndarray
        Each tag's slice centres along its ``slice_axis``, mm, increasing; with
        ``thickness`` the ``slice_thickness`` and ``slice_position`` arguments of
        :func:`tagged_dataset`.

    Raises
    ------
    ValueError
        If the tags of one dataset have different slice axes.
    """
    thickness: list[float] = []
    positions: list[FloatArray] = []
    for ds, axis, stack in _axis_aligned_stacks(stacks):
        centres = stack.centres_along(axis)
        assert centres is not None  # an axis-aligned stack's slices are grid planes
        for _ in range(ds.sizes["tag"]):
            thickness.append(2.0 * (stack.slab[1] - float(stack.offsets[-1])))
            positions.append(centres)
    return np.asarray(thickness, dtype=np.float64), positions


def slice_coords(
    ntag: int, thickness: ArrayLike, positions: Sequence[ArrayLike]
) -> dict[str, tuple[Any, ...]]:
    """The ``slice_thickness`` (tag) and ``slice_position`` (tag, slice) coordinates.

    Parameters
    ----------
    ntag : int
        Number of tags.
    thickness : array_like, shape (tag,) or scalar
        Slice thickness of each tag's slices along its ``slice_axis``, mm (NaN: unknown).
    positions : sequence of array_like
        One entry per tag: its slice centres along its ``slice_axis``, mm, increasing
        (empty or all NaN: unknown). Shorter rows are NaN-padded.

    Returns
    -------
    dict
        ``{name: (dims, values, attrs)}`` for ``slice_thickness`` and ``slice_position``.

    Raises
    ------
    ValueError
        If ``thickness`` or ``positions`` does not have one entry per tag, or an entry of
        ``positions`` is not one-dimensional.
    """
    thick = np.asarray(thickness, dtype=np.float64)
    thick = np.broadcast_to(thick, (ntag,)).copy() if thick.ndim == 0 else thick
    rows = [np.atleast_1d(np.asarray(p, dtype=np.float64)) for p in positions]
    if thick.shape != (ntag,) or len(rows) != ntag or any(r.ndim != 1 for r in rows):
        raise ValueError(
            f"slice geometry for {ntag} tags: slice_thickness has shape {thick.shape} and "
            f"slice_position {len(rows)} rows (shapes {[r.shape for r in rows]}); expected one "
            "thickness and one 1-D row of slice centres (mm) per tag"
        )
    rows = [r[np.isfinite(r)] for r in rows]
    table = np.full((ntag, max([1, *(r.size for r in rows)])), np.nan)
    for t, r in enumerate(rows):  # per tag (<= 3)
        table[t, : r.size] = r
    return {
        "slice_thickness": ("tag", thick, standard_attrs("slice_thickness")),
        "slice_position": (("tag", "slice"), table, standard_attrs("slice_position")),
    }


def tagged_dataset(
    image: ArrayLike,
    *,
    tag: Sequence[str],
    tag_frequency: ArrayLike,
    slice_axis: Sequence[str],
    time: ArrayLike,
    z: ArrayLike,
    y: ArrayLike,
    x: ArrayLike,
    sequence: str,
    tag_direction: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    body: ArrayLike | None = None,
    displacement_true: ArrayLike | None = None,
    attrs: Mapping[str, Any] | None = None,
    slice_thickness: ArrayLike | None = None,
    slice_position: Sequence[ArrayLike] | None = None,
    check: bool = True,
) -> xr.Dataset:
    """Assemble a ``tagged/1`` dataset with the standard coordinates, units and names.

    Parameters
    ----------
    image : array_like, shape (tag, time, z, y, x)
        Magnitude (SPAMM) or difference (CSPAMM) images.
    tag : sequence of str
        Tag labels.
    tag_frequency : array_like, shape (tag,) or scalar
        Tag spatial frequency, cycles/mm.
    slice_axis : sequence of str
        Axis normal to each tag's acquisition slices.
    time : array_like, shape (time,)
        Frame times after tagging, ms; index 0 is the reference frame.
    z, y, x : array_like
        Voxel-centre coordinates, mm.
    sequence : {"SPAMM", "CSPAMM"}
        Tagging sequence.
    tag_direction : array_like, shape (tag, 3), optional
        Unit tag wave directions (x, y, z); default: the axis named by each label.
    mask : array_like of bool, shape (tag, z, y, x), optional
        Where each acquisition has data: its field of view and slice slab (a fixed region of
        space, not the tissue).
    body : array_like, shape (z, y, x), optional
        Tissue density fraction in [0, 1] at the reference frame.
    displacement_true : array_like, shape (time, axis, z, y, x), optional
        True Lagrangian displacement at the reference voxel centres, mm (NaN outside the
        body).
    attrs : mapping, optional
        Further dataset attributes (``noise_sigma``, ``snr``, ...).
    slice_thickness : array_like, shape (tag,) or scalar, optional
        Thickness of each tag's slices along its ``slice_axis``, mm (NaN: unknown); given
        together with ``slice_position`` (:func:`slice_coords`). The blur correction of the
        tracker models the slice profile with them
        (:func:`harpx.imaging.harp.slice_geometry`).
    slice_position : sequence of array_like, optional
        Each tag's slice centres along its ``slice_axis``, mm, increasing (rows of
        different lengths are NaN-padded; an empty row: unknown).
        :func:`stacks_slice_geometry` gives both for the stacks of :func:`resample_stacks`,
        :meth:`SliceStack.centres_along` for one stack.
    check : bool, default True
        Run :func:`harpx.schema.validate` on the result.

    Returns
    -------
    xarray.Dataset
        ``attrs["harpx_schema"] = "tagged/1"``.

    Raises
    ------
    ValueError
        If an array's shape disagrees with the labels and coordinates (names it, its shape
        and the expected one; :func:`~harpx.imaging.tagged_shapes.check_tagged_shapes`), a
        label has no default direction (pass ``tag_direction``), only one of
        ``slice_thickness`` and ``slice_position`` is given, or either has not one entry
        per tag.
    SchemaError
        If ``check`` and the dataset breaks ``tagged/1`` (e.g. slice centres not increasing,
        a thickness that is not positive).

    Examples
    --------
    >>> from harpx.imaging.stacks import tagged_dataset
    >>> ds = tagged_dataset(np.zeros((1, 1, 1, 2, 4)), tag=["x"], tag_frequency=0.125,
    ...                     slice_axis=["z"], time=[0.0], z=[0.0], y=[0.0, 1.0],
    ...                     x=[0.0, 1.0, 2.0, 3.0], sequence="CSPAMM")
    >>> ds.tag_direction.values.tolist(), ds.attrs["harpx_schema"]
    ([[1.0, 0.0, 0.0]], 'tagged/1')
    """
    check_tagged_shapes(image, dict(
        tag=tag, tag_frequency=tag_frequency, slice_axis=slice_axis, time=time, z=z, y=y, x=x,
        tag_direction=tag_direction, mask=mask, body=body, displacement_true=displacement_true,
    ))  # fmt: skip
    labels = [str(t) for t in tag]
    data_vars: dict[str, Any] = {
        "image": (("tag", "time", *GRID_DIMS), np.asarray(image), standard_attrs("image"))
    }
    if mask is not None:
        mask_arr = np.broadcast_to(np.asarray(mask, dtype=bool), (len(labels), *_shape(z, y, x)))
        data_vars["mask"] = (("tag", *GRID_DIMS), mask_arr.copy(), standard_attrs("mask"))
    if body is not None:
        data_vars["body"] = (GRID_DIMS, np.asarray(body), standard_attrs("body"))
    if displacement_true is not None:
        data_vars["displacement_true"] = (
            ("time", "axis", *GRID_DIMS),
            np.asarray(displacement_true),
            standard_attrs("displacement_true"),
        )
    coords = image_coords(
        tag=labels,
        tag_direction=tag_direction,
        tag_frequency=tag_frequency,
        slice_axis=slice_axis,
        time=time,
        z=z,
        y=y,
        x=x,
    )
    if (slice_thickness is None) != (slice_position is None):
        raise ValueError(
            "slice_thickness and slice_position come together (either alone cannot place the "
            "slabs); pass both or neither"
        )
    if slice_thickness is not None and slice_position is not None:
        coords.update(slice_coords(len(labels), slice_thickness, slice_position))
    ds = xr.Dataset(
        data_vars,
        coords=coords,
        attrs={"harpx_schema": "tagged/1", "sequence": sequence, **dict(attrs or {})},
    )
    if check:
        validate(ds, "tagged")
    return ds


def image_coords(
    *,
    tag: Sequence[str],
    tag_frequency: ArrayLike,
    slice_axis: Sequence[str],
    time: ArrayLike,
    z: ArrayLike,
    y: ArrayLike,
    x: ArrayLike,
    tag_direction: ArrayLike | None = None,
) -> dict[str, tuple[Any, ...]]:
    """Coordinates shared by ``tagged/1`` and ``phase/1``.

    Parameters
    ----------
    tag, tag_frequency, slice_axis, time, z, y, x, tag_direction : see :func:`tagged_dataset`
        The coordinates, as :func:`tagged_dataset` takes them.

    Returns
    -------
    dict
        ``{name: (dims, values, attrs)}`` for ``tag``, ``axis``, ``tag_direction``,
        ``tag_frequency``, ``slice_axis``, ``time``, ``z``, ``y``, ``x``.

    Raises
    ------
    ValueError
        If ``tag_direction`` is None and a label is not an axis name.
    """
    labels = [str(t) for t in tag]
    if tag_direction is None:
        unknown = [t for t in labels if t not in AXES]
        if unknown:
            raise ValueError(
                f"tags {unknown!r} are not axis names, so their direction is unknown; "
                "pass tag_direction= (one unit 3-vector (x, y, z) per tag)"
            )
        direction = np.eye(3)[[AXES.index(t) for t in labels]]
    else:
        direction = np.asarray(tag_direction, dtype=np.float64)
    frequency = np.broadcast_to(np.asarray(tag_frequency, dtype=np.float64), (len(labels),))
    return {
        "tag": ("tag", np.array(labels, dtype=object), standard_attrs("tag")),
        "axis": ("axis", np.array(AXES, dtype=object), standard_attrs("axis")),
        "tag_direction": (("tag", "axis"), direction, standard_attrs("tag_direction")),
        "tag_frequency": ("tag", frequency.copy(), standard_attrs("tag_frequency")),
        "slice_axis": (
            "tag",
            np.array([str(s) for s in slice_axis], dtype=object),
            standard_attrs("slice_axis"),
        ),
        "time": ("time", np.asarray(time, dtype=np.float64), standard_attrs("time")),
        **{
            d: (d, np.asarray(v, dtype=np.float64), standard_attrs(d))
            for d, v in zip(GRID_DIMS, (z, y, x), strict=True)
        },
    }


def _shape(z: ArrayLike, y: ArrayLike, x: ArrayLike) -> tuple[int, int, int]:
    return (np.asarray(z).size, np.asarray(y).size, np.asarray(x).size)
