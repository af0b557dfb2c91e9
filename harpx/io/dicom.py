"""Import tagged cine MRI from DICOM into a ``tagged/1`` dataset.

:func:`read_tagged` reads tagged cine series as scanners write them -- one file per image
(classic *MR Image Storage*) or one enhanced multi-frame file per series (*Enhanced MR Image
Storage*, per-frame functional groups) -- and resamples every selected stack of parallel
slices onto one Cartesian grid in patient coordinates. pydicom is an optional dependency
(``pip install harpx[dicom]``); it is imported only when a function of this module runs.

Geometry (DICOM PS3.3 C.7.6.2.1.1)
----------------------------------
Positions are patient coordinates (LPS: x to the patient's left, y posterior, z head), mm.
``ImageOrientationPatient`` holds two direction cosines: the first triplet ``r`` is the
direction of *increasing column index* (along a row), the second ``c`` the direction of
*increasing row index* (down a column). ``PixelSpacing`` is ``[Δr, Δc]``: the spacing
*between rows* (along ``c``) first, then the spacing *between columns* (along ``r``). The
centre of the pixel in row ``i`` and column ``j`` of an image whose first transmitted pixel
is at ``ImagePositionPatient`` ``P`` lies at

.. math:: p_{ij} = P + j \\, Δc \\, r + i \\, Δr \\, c ,

which :func:`voxel_positions` evaluates. A *stack* is every image of one series: all must
share orientation, matrix size and pixel spacing, and their positions must differ only along
the slice normal ``n = r × c`` (slices ordered by ``(P - P_0)·n``, not by file order or
``InstanceNumber``).

Resampling and masks
--------------------
Each stack is resampled onto one grid by :func:`harpx.imaging.stacks.resample_stack`
((tri)linear in the stack's own (slice, row, column) index space, linear in the slice
position between slices, so uneven slice spacing is handled). A grid point has data from a
stack (``mask`` True) when

* in plane, it lies within the hull of the pixel centres (0 ≤ column index ≤ Columns-1 and
  0 ≤ row index ≤ Rows-1), where bilinear interpolation needs no extrapolation, and
* through plane, it lies in the stack's slab: from half a ``SliceThickness`` below the first
  slice centre to half a ``SliceThickness`` above the last (half the neighbouring slice
  spacing when ``SliceThickness`` is absent). Between the outermost slice centre and the slab
  face the nearest slice is used, since a slice's signal is an average over its thickness.
  Gaps between slices count as data (linear interpolation across them).

The mask is the acquisition's field of view and slab, a fixed region of space; DICOM says
nothing about where the tissue is, so the result has no ``body``. Outside its mask a tag's
image is 0. The grid (:func:`harpx.imaging.stacks.common_grid`) is aligned so that its
points fall on the pixel centres of an axis-aligned stack whose pixel spacing equals the grid
spacing (no interpolation at all in that case) and it covers the union of all slabs.
"""

from __future__ import annotations

import math
import numbers
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from harpx._typing import FloatArray, PathLike
from harpx.errors import HarpxError, HarpxWarning
from harpx.imaging.stacks import SliceStack, common_grid, resample_stack, tagged_dataset
from harpx.io.netcdf import _available_memory
from harpx.schema import AXES, SEQUENCES

__all__ = ["read_tagged", "voxel_positions"]

_INSTALL_HINT = "pip install harpx[dicom]"
#: Largest difference of direction cosines for two images to count as parallel.
ORIENTATION_TOL = 1e-3
#: Slice positions closer than this (mm) along the normal are the same slice.
SLICE_TOL = 1e-2
#: In-plane offset between slices of a stack tolerated, as a fraction of a pixel.
INPLANE_TOL = 1e-2
#: Output images larger than this (bytes) trigger a :class:`~harpx.errors.HarpxWarning`.
LARGE_OUTPUT_BYTES = 2**31
_TIME_DUPLICATE = 1e-3  # ms: two frames of one slice closer than this are duplicates


def _pydicom() -> Any:
    try:
        import pydicom
    except ImportError as err:
        raise ImportError(
            f"reading DICOM needs the optional dependency pydicom; install it with "
            f"`{_INSTALL_HINT}`"
        ) from err
    return pydicom


# ---------------------------------------------------------------------------------------------
# headers → per-image records


@dataclass
class _Image:
    """Header fields of one 2D image (a classic file or one frame of a multi-frame file)."""

    path: Path
    frame: int | None  # None: single-frame file
    series_uid: str
    description: str
    number: str
    sequence_name: str
    rows: int
    columns: int
    position: FloatArray | None
    orientation: FloatArray | None
    pixel_spacing: FloatArray | None
    thickness: float | None
    time: float | None
    slope: float
    intercept: float
    time_name: str = "TriggerTime"
    sop_uid: str = ""
    #: raw header values that are present but not numbers (name -> value)
    unreadable: dict[str, Any] = field(default_factory=dict)

    def where(self) -> str:
        return str(self.path) if self.frame is None else f"{self.path} (frame {self.frame + 1})"

    def require(self, name: str) -> Any:
        value = getattr(self, name)
        keyword = {
            "position": "ImagePositionPatient",
            "orientation": "ImageOrientationPatient",
            "pixel_spacing": "PixelSpacing",
            "thickness": "SliceThickness",
            "time": self.time_name,
        }[name]
        if value is None and name in self.unreadable:
            raise HarpxError(
                f"DICOM attribute {keyword!r} of {self.where()} is "
                f"{self.unreadable[name]!r}, which is not a finite number (or not the right "
                "count of them); fix the export or drop the file"
            )
        if value is None:
            raise HarpxError(
                f"DICOM attribute {keyword!r} is missing in {self.where()}; harpx needs it to "
                "place the image in patient coordinates and time (fix the export or drop the "
                "file)"
            )
        return value


def _floats(value: Any, size: int) -> FloatArray | None:
    if value is None:
        return None
    try:
        out = np.asarray([float(v) for v in value], dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return out if out.shape == (size,) and np.all(np.isfinite(out)) else None


def _float(value: Any) -> float | None:
    if value is None or value == "":
        return None
    try:
        out = float(value)
    except (TypeError, ValueError):
        return None
    return out if math.isfinite(out) else None


def _group_value(header: Any, per_frame: Any, sequence: str, keyword: str) -> Any:
    """Value of ``keyword`` from a functional group: per-frame, then shared, then top level."""
    shared = header.get("SharedFunctionalGroupsSequence")
    groups = [per_frame] + ([shared[0]] if shared else [])
    for group in groups:
        items = group.get(sequence) if group is not None else None
        if items and keyword in items[0]:
            return items[0].get(keyword)
    return header.get(keyword)


def _images_of(header: Any, path: Path) -> list[_Image]:
    """Split a DICOM header into per-image records (one per frame of a multi-frame file)."""
    common: dict[str, Any] = {
        "path": path,
        "series_uid": str(header.get("SeriesInstanceUID", "")),
        "description": str(header.get("SeriesDescription", "")),
        "number": str(header.get("SeriesNumber", "")),
        "sequence_name": " ".join(
            str(header.get(k, "")) for k in ("SequenceName", "PulseSequenceName", "ProtocolName")
        ),
        "rows": int(header.get("Rows", 0)),
        "columns": int(header.get("Columns", 0)),
    }
    common["sop_uid"] = str(header.get("SOPInstanceUID", ""))
    per_frame = header.get("PerFrameFunctionalGroupsSequence")
    if not per_frame:
        image = _Image(
            frame=None,
            position=_floats(header.get("ImagePositionPatient"), 3),
            orientation=_floats(header.get("ImageOrientationPatient"), 6),
            pixel_spacing=_floats(header.get("PixelSpacing"), 2),
            thickness=_float(header.get("SliceThickness")),
            time=_float(header.get("TriggerTime")),
            slope=_float(header.get("RescaleSlope")) or 1.0,
            intercept=_float(header.get("RescaleIntercept")) or 0.0,
            **common,
        )
        for name, keyword in (
            ("position", "ImagePositionPatient"),
            ("orientation", "ImageOrientationPatient"),
            ("pixel_spacing", "PixelSpacing"),
            ("time", "TriggerTime"),
        ):
            raw = header.get(keyword)
            if getattr(image, name) is None and raw is not None and raw != "":
                image.unreadable[name] = str(raw)
        return [image]
    images = []
    stamps: list[datetime | None] = []
    for index, item in enumerate(per_frame):

        def value(sequence: str, keyword: str, item: Any = item) -> Any:
            return _group_value(header, item, sequence, keyword)

        time = _float(value("CardiacSynchronizationSequence", "NominalCardiacTriggerDelayTime"))
        stamp = value("FrameContentSequence", "FrameAcquisitionDateTime")
        stamps.append(_datetime(stamp) if stamp else None)
        images.append(
            _Image(
                frame=index,
                position=_floats(value("PlanePositionSequence", "ImagePositionPatient"), 3),
                orientation=_floats(
                    value("PlaneOrientationSequence", "ImageOrientationPatient"), 6
                ),
                pixel_spacing=_floats(value("PixelMeasuresSequence", "PixelSpacing"), 2),
                thickness=_float(value("PixelMeasuresSequence", "SliceThickness")),
                time=time if time is not None else _float(header.get("TriggerTime")),
                slope=_float(value("PixelValueTransformationSequence", "RescaleSlope")) or 1.0,
                intercept=_float(value("PixelValueTransformationSequence", "RescaleIntercept"))
                or 0.0,
                time_name="NominalCardiacTriggerDelayTime (CardiacSynchronizationSequence)",
                **common,
            )
        )
    if any(im.time is None for im in images) and all(s is not None for s in stamps):
        # No trigger delays: time since the first acquired frame of the file.
        first = min(s for s in stamps if s is not None)
        for im, s in zip(images, stamps, strict=True):
            im.time = (s - first) / timedelta(milliseconds=1) if s is not None else None
    return images


def _datetime(value: Any) -> datetime | None:
    try:
        stamp: datetime = _pydicom().valuerep.DT(str(value))
    except (ValueError, TypeError):
        return None
    return stamp.replace(tzinfo=None)  # offsets are per study; differences are what count


# ---------------------------------------------------------------------------------------------
# geometry


def _pixel_positions(
    position: FloatArray,
    orientation: FloatArray,
    pixel_spacing: FloatArray,
    rows: int,
    columns: int,
) -> FloatArray:
    """Pixel-centre positions (rows, columns, 3) in mm; see the module docstring."""
    along_row, along_column = orientation[:3], orientation[3:]
    row_spacing, column_spacing = pixel_spacing
    i = np.arange(rows, dtype=np.float64)[:, None, None]
    j = np.arange(columns, dtype=np.float64)[None, :, None]
    return position + j * column_spacing * along_row + i * row_spacing * along_column


def voxel_positions(images: Any) -> FloatArray:
    """Patient (LPS) positions of the pixel centres of DICOM images, in mm.

    Parameters
    ----------
    images : pydicom.Dataset or sequence of pydicom.Dataset
        One image (classic single-frame or enhanced multi-frame) or a sequence of them, read
        with :func:`pydicom.dcmread`. Each needs ``Rows``, ``Columns``,
        ``ImagePositionPatient``, ``ImageOrientationPatient`` and ``PixelSpacing`` (top level
        or in the functional groups of a multi-frame image).

    Returns
    -------
    numpy.ndarray of float64
        ``(Rows, Columns, 3)`` for one single-frame image; ``(frames, Rows, Columns, 3)`` for
        a multi-frame image; a sequence stacks its images' frames along a leading axis
        ``(n, Rows, Columns, 3)``. The last axis is (x, y, z) in mm; element ``[..., i, j, :]``
        is the centre of the pixel in row ``i`` and column ``j``.

    Raises
    ------
    HarpxError
        If a geometry attribute is missing (the message names it and the file), the images
        of a sequence differ in matrix size, or there are no images.
    TypeError
        If an image is not a pydicom dataset (e.g. a file name: read it first).
    ImportError
        If pydicom is not installed.

    Notes
    -----
    .. math:: p_{ij} = P + j \\, Δc \\, r + i \\, Δr \\, c

    with ``P = ImagePositionPatient``, ``(r, c) = ImageOrientationPatient`` (first triplet:
    direction of increasing column index) and ``(Δr, Δc) = PixelSpacing`` (row spacing
    first), as DICOM PS3.3 C.7.6.2.1.1 defines them.

    Examples
    --------
    >>> from pydicom import Dataset
    >>> im = Dataset()
    >>> im.Rows, im.Columns = 2, 3
    >>> im.ImagePositionPatient = [10, 20, 30]
    >>> im.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
    >>> im.PixelSpacing = [2.0, 0.5]  # 2 mm between rows, 0.5 mm between columns
    >>> voxel_positions(im)[1, 2]  # row 1, column 2
    array([11., 22., 30.])
    """
    pydicom = _pydicom()
    single = not isinstance(images, Sequence) or isinstance(images, str | bytes)
    headers = [images] if single else list(images)
    if not headers:
        raise HarpxError("voxel_positions got no images; pass a pydicom.Dataset or a list")
    for header in headers:
        if not isinstance(header, pydicom.Dataset):
            raise TypeError(
                f"voxel_positions needs pydicom datasets (pydicom.dcmread(path)), got "
                f"{type(header).__name__!r}"
                + (": read the file first" if isinstance(header, str | os.PathLike) else "")
            )
    records: list[_Image] = []
    for header in headers:
        records.extend(_images_of(header, Path(str(getattr(header, "filename", "<dataset>")))))
    out = [
        _pixel_positions(
            im.require("position"),
            im.require("orientation"),
            im.require("pixel_spacing"),
            im.rows,
            im.columns,
        )
        for im in records
    ]
    if len({p.shape for p in out}) > 1:
        raise HarpxError(
            "images differ in matrix size "
            f"{sorted({p.shape[:2] for p in out})}; pass images of one series"
        )
    if single and records[0].frame is None:
        return out[0]
    return np.stack(out)


@dataclass
class _Stack:
    """One series: parallel slices, sorted along the normal, with matching frames."""

    uid: str
    description: str
    origin: FloatArray  # position of pixel (0, 0) of the first slice, mm
    along_row: FloatArray  # r: direction of increasing column index
    along_column: FloatArray  # c: direction of increasing row index
    normal: FloatArray  # unit r × c
    pixel_spacing: FloatArray  # (Δr between rows, Δc between columns), mm
    rows: int
    columns: int
    offsets: FloatArray  # (S,) slice positions along the normal from origin, increasing, mm
    slab: tuple[float, float]  # through-plane extent along the normal from origin, mm
    times: FloatArray  # (T,) frame times, ms
    images: list[list[_Image]]  # [slice][frame]

    @property
    def geometry(self) -> SliceStack:
        """The stack's slice geometry (patient coordinates, mm)."""
        return SliceStack(
            origin=self.origin,
            along_row=self.along_row,
            along_column=self.along_column,
            pixel_spacing=(float(self.pixel_spacing[0]), float(self.pixel_spacing[1])),
            rows=self.rows,
            columns=self.columns,
            offsets=self.offsets,
            slab=self.slab,
        )

    def name(self) -> str:
        return f"series {self.description!r} ({self.uid})"


def _build_stack(images: list[_Image], time_tolerance: float) -> _Stack:
    first = images[0]
    label = f"series {first.description!r} ({first.series_uid})"
    orientation = first.require("orientation")
    spacing = first.require("pixel_spacing")
    for im in images:
        im.require("position")
        im.require("time")
        im_orientation = im.require("orientation")
        if np.max(np.abs(im_orientation - orientation)) > ORIENTATION_TOL:
            raise HarpxError(
                f"slices of {label} are not parallel: {im.where()} has ImageOrientationPatient "
                f"{np.round(im_orientation, 4).tolist()} but {first.where()} has "
                f"{np.round(orientation, 4).tolist()}; a series must be one stack of parallel "
                "slices (split it, e.g. by passing the files of each orientation separately)"
            )
        im_spacing = im.require("pixel_spacing")
        if (im.rows, im.columns) != (first.rows, first.columns) or np.max(
            np.abs(im_spacing - spacing)
        ) > 1e-6 * max(spacing):
            raise HarpxError(
                f"images of {label} differ in matrix size or PixelSpacing: {im.where()} has "
                f"{im.rows}x{im.columns} at {im_spacing.tolist()} mm, {first.where()} "
                f"{first.rows}x{first.columns} at {spacing.tolist()} mm"
            )
    _check_geometry(first, orientation, spacing, label)
    along_row, along_column = orientation[:3], orientation[3:]
    normal = np.cross(along_row, along_column)
    normal /= np.linalg.norm(normal)
    affine = np.column_stack([along_row * spacing[1], along_column * spacing[0], normal])
    positions = np.array([im.position for im in images])
    local = np.linalg.solve(affine, (positions - positions[0]).T).T  # (col, row, offset)
    order = np.argsort(local[:, 2], kind="stable")
    cuts = np.flatnonzero(np.diff(local[order, 2]) > SLICE_TOL) + 1
    slices = np.split(order, cuts)
    base = slices[0][0]
    shift = (local[:, :2] - local[base, :2]) @ affine[:, :2].T  # in-plane offsets, mm
    worst = int(np.argmax(np.linalg.norm(shift, axis=1)))
    if np.linalg.norm(shift[worst]) > INPLANE_TOL * spacing.min():
        raise HarpxError(
            f"slices of {label} are shifted in plane by {np.linalg.norm(shift[worst]):.4g} mm "
            f"(offset {np.round(shift[worst], 4).tolist()} in x, y, z; {images[worst].where()} "
            f"against {images[base].where()}); a stack needs its slice positions to differ "
            "only along the slice normal"
        )
    frames: list[list[_Image]] = []
    for members in slices:
        ims = sorted((images[k] for k in members), key=lambda im: im.time)
        gaps = np.diff([im.time for im in ims])
        if gaps.size and gaps.min() < _TIME_DUPLICATE:
            k = int(np.argmin(gaps))
            a, b = ims[k], ims[k + 1]
            if a.sop_uid and a.sop_uid == b.sop_uid and a.frame == b.frame:
                raise HarpxError(
                    f"{a.where()} and {b.where()} are the same image twice (SOPInstanceUID "
                    f"{a.sop_uid!r}): one is a copy of the other; remove the copy"
                )
            raise HarpxError(
                f"{label} has two images at the same slice position and TriggerTime "
                f"{ims[k].time} ms: {ims[k].where()} and {ims[k + 1].where()}; put repeated "
                "acquisitions (e.g. CSPAMM A and B) in separate series or select the files"
            )
        frames.append(ims)
    counts = [len(f) for f in frames]
    if len(set(counts)) > 1:
        raise HarpxError(
            f"slices of {label} have different numbers of frames {counts}; every slice of a "
            "cine stack needs the same frames (drop incomplete slices)"
        )
    times = np.array([[im.time for im in f] for f in frames], dtype=np.float64)
    spread = times.max(axis=0) - times.min(axis=0)
    if spread.max() > time_tolerance:
        raise HarpxError(
            f"TriggerTime of the slices of {label} differ by up to {spread.max():.3g} ms at "
            f"frame {int(np.argmax(spread))} (> time_tolerance={time_tolerance:g} ms); raise "
            "time_tolerance if the frames really correspond"
        )
    offsets = local[[s[0] for s in slices], 2] - local[base, 2]
    _check_gaps(offsets, [images[s[0]] for s in slices], label)
    origin = positions[base]
    thickness = first.thickness if first.thickness is not None and first.thickness > 0 else None
    if thickness is not None:
        below = above = 0.5 * thickness
    elif offsets.size > 1:
        below, above = 0.5 * (offsets[1] - offsets[0]), 0.5 * (offsets[-1] - offsets[-2])
    else:
        raise HarpxError(
            f"DICOM attribute 'SliceThickness' is missing or not positive in {first.where()}; "
            f"{label} has a single slice, so harpx needs it to know how far the slice's data "
            "extends through plane"
        )
    return _Stack(
        uid=first.series_uid,
        description=first.description,
        origin=origin,
        along_row=along_row,
        along_column=along_column,
        normal=normal,
        pixel_spacing=spacing,
        rows=first.rows,
        columns=first.columns,
        offsets=offsets,
        slab=(float(offsets[0] - below), float(offsets[-1] + above)),
        times=times.mean(axis=0),
        images=frames,
    )


#: Largest deviation of an ImageOrientationPatient triplet from unit length, and of the
#: two triplets from orthogonality (|r . c|).
UNIT_TOL = 1e-3
#: A gap between neighbouring slices larger than this many regular gaps is an error (a slice
#: far off the stack); a smaller but irregular gap (missing slices) warns.
GAP_ERROR = 4.0
_GAP_WARN = 1.5


def _check_geometry(
    first: _Image, orientation: FloatArray, spacing: FloatArray, label: str
) -> None:
    """Unit, orthogonal direction cosines and positive pixel spacing, else HarpxError."""
    r, c = orientation[:3], orientation[3:]
    norms = [float(np.linalg.norm(r)), float(np.linalg.norm(c))]
    if max(abs(n - 1.0) for n in norms) > UNIT_TOL or abs(float(r @ c)) > UNIT_TOL:
        raise HarpxError(
            f"ImageOrientationPatient of {first.where()} ({label}) is "
            f"{np.round(orientation, 6).tolist()}: the two direction cosines must be unit "
            f"vectors at right angles (norms {np.round(norms, 6).tolist()}, dot product "
            f"{float(r @ c):.3g}); fix the export (harpx would scale or shear the geometry)"
        )
    if not np.all(spacing > 0):
        raise HarpxError(
            f"PixelSpacing of {first.where()} ({label}) is {spacing.tolist()} mm; both "
            "values must be positive (fix the export)"
        )


def _check_gaps(offsets: FloatArray, firsts: list[_Image], label: str) -> None:
    """A slice far off the stack is an error; missing slices (an irregular gap) warn."""
    if offsets.size < 3:
        return
    gaps = np.diff(offsets)
    regular = float(np.median(gaps))
    worst = int(np.argmax(gaps))
    if gaps[worst] > GAP_ERROR * regular:
        raise HarpxError(
            f"slice {firsts[worst + 1].where()} of {label} is {gaps[worst]:.4g} mm from its "
            f"neighbour {firsts[worst].where()}, {gaps[worst] / regular:.3g} times the "
            f"stack's {regular:.4g} mm slice gap; it does not belong to this stack (drop it "
            "or give it its own series)"
        )
    irregular = np.flatnonzero(gaps > _GAP_WARN * regular)
    if irregular.size:
        k = int(irregular[0])
        warnings.warn(
            f"{label} has a gap of {gaps[k]:.4g} mm between {firsts[k].where()} and "
            f"{firsts[k + 1].where()} ({gaps[k] / regular:.3g} times its {regular:.4g} mm "
            "slice gap): slices seem to be missing; the images are interpolated across the "
            "gap (its mask marks it as having data)",
            HarpxWarning,
            stacklevel=4,
        )


# ---------------------------------------------------------------------------------------------
# file discovery and pixel data


def _discover(paths_or_folder: PathLike | Sequence[PathLike]) -> list[_Image]:
    pydicom = _pydicom()
    if isinstance(paths_or_folder, str | os.PathLike):
        entries = [Path(paths_or_folder)]
    elif isinstance(paths_or_folder, Sequence) and all(
        isinstance(p, str | os.PathLike) for p in paths_or_folder
    ):
        entries = [Path(p) for p in paths_or_folder]
    else:
        raise TypeError(
            f"paths_or_folder must be a folder, a DICOM file or a list of them (str or "
            f"os.PathLike), got {paths_or_folder!r}"
        )
    if not entries:
        raise HarpxError("paths_or_folder is an empty list; pass a folder or DICOM files")
    images: list[_Image] = []
    no_series: list[Path] = []
    seen: set[Path] = set()
    for entry in entries:
        if entry.is_dir():
            files = sorted(p for p in entry.rglob("*") if p.is_file())
            explicit = False
        elif entry.is_file():
            files, explicit = [entry], True
        else:
            raise HarpxError(f"DICOM path {str(entry)!r} does not exist")
        for path in files:
            if path.resolve() in seen:
                continue  # given twice (a folder and a file inside it)
            seen.add(path.resolve())
            try:
                header = pydicom.dcmread(path, stop_before_pixels=True)
            except pydicom.errors.InvalidDicomError as err:
                if explicit:
                    raise HarpxError(f"cannot read {str(path)!r} as DICOM: {err}") from err
                continue  # a folder may hold other files (notes, thumbnails)
            except Exception as err:  # truncated or corrupt DICOM
                raise HarpxError(
                    f"cannot read DICOM file {str(path)!r} ({type(err).__name__}: {err}); the "
                    "file is truncated or corrupt: re-export it or remove it"
                ) from err
            if "Rows" not in header:
                continue  # DICOMDIR, presentation states, reports: not images
            if "SeriesInstanceUID" not in header:
                no_series.append(path)
                continue
            images.extend(_images_of(header, path))
    if no_series:
        message = (
            f"{len(no_series)} DICOM images have no SeriesInstanceUID, e.g. "
            f"{str(no_series[0])!r}; harpx groups images into stacks by it (add it, e.g. "
            "with pydicom: ds.SeriesInstanceUID = pydicom.uid.generate_uid())"
        )
        if not images:
            raise HarpxError(message)
        warnings.warn(message + "; those images are skipped", HarpxWarning, stacklevel=3)
    if not images:
        where = ", ".join(repr(str(e)) for e in entries)
        raise HarpxError(
            f"no DICOM images found in {where}; pass a folder holding the tagged series or "
            "a list of .dcm files"
        )
    return images


def _load_pixels(stacks: list[_Stack]) -> list[NDArray[np.float64]]:
    """Rescaled pixel values of each stack, (time, slice, row, column) float64."""
    pydicom = _pydicom()
    cache: dict[Path, NDArray[Any]] = {}
    volumes = []
    for stack in stacks:
        volume = np.empty(
            (stack.times.size, len(stack.images), stack.rows, stack.columns), dtype=np.float64
        )
        for k, frames in enumerate(stack.images):
            for t, im in enumerate(frames):
                if im.path not in cache:
                    try:
                        cache[im.path] = np.asarray(pydicom.dcmread(im.path).pixel_array)
                    except Exception as err:
                        raise HarpxError(
                            f"cannot decode the pixel data of {str(im.path)!r} "
                            f"({type(err).__name__}: {err}); the file is truncated, corrupt "
                            "or compressed with a codec pydicom cannot decode (install "
                            "pylibjpeg or gdcm)"
                        ) from err
                pixels = cache[im.path]
                if im.frame is not None and pixels.ndim == 3:
                    pixels = pixels[im.frame]
                if pixels.shape != (stack.rows, stack.columns):
                    raise HarpxError(
                        f"pixel data of {im.where()} has shape {pixels.shape}; expected "
                        f"(Rows, Columns) = {(stack.rows, stack.columns)} (colour or "
                        "malformed image)"
                    )
                volume[t, k] = pixels * im.slope + im.intercept
        volumes.append(volume)
    return volumes


# ---------------------------------------------------------------------------------------------
# tag specification


def _series_listing(images: list[_Image]) -> str:
    seen: dict[str, list[_Image]] = {}
    for im in images:
        seen.setdefault(im.series_uid, []).append(im)
    return "\n".join(
        f"  - SeriesDescription {ims[0].description!r}, SeriesNumber {ims[0].number!r}, "
        f"SeriesInstanceUID {uid!r}: {len(ims)} images"
        for uid, ims in seen.items()
    )


def _parse_tags(tag_directions: Any, images: list[_Image]) -> list[tuple[str, str, Any]]:
    """(series selector, tag label, direction) triples from the user's specification."""
    example = "tag_directions={'SA tagged': [('x', 'row'), ('y', 'column')]}"
    if isinstance(tag_directions, str | bytes):
        raise HarpxError(
            f"tag_directions is the string {tag_directions!r}; say which tags the series "
            f"carries, e.g. {example}"
        )
    if tag_directions is None:
        raise HarpxError(
            "tag_directions is required: say which series carries which tag direction, e.g. "
            f"{example} (directions: 'row', 'column' or a 3-vector in patient x, y, z). "
            f"Series found:\n{_series_listing(images)}"
        )
    triples: list[tuple[str, str, Any]] = []
    if isinstance(tag_directions, Mapping):
        for selector, entries in tag_directions.items():
            if isinstance(entries, str | bytes):
                raise HarpxError(
                    f"tag_directions[{selector!r}] is {entries!r}; expected a (label, "
                    f"direction) pair or a list of them, e.g. {example}"
                )
            single = (
                isinstance(entries, tuple | list)
                and len(entries) == 2
                and isinstance(entries[0], str)
            )
            for entry in [entries] if single else entries:
                if not (isinstance(entry, tuple | list) and len(entry) == 2):
                    raise HarpxError(
                        f"tag_directions[{selector!r}] entry {entry!r} is not a (label, "
                        f"direction) pair; e.g. {example}"
                    )
                triples.append((str(selector), str(entry[0]), entry[1]))
    else:
        for entry in tag_directions:
            if not (isinstance(entry, tuple | list) and len(entry) == 3):
                raise HarpxError(
                    f"tag_directions entry {entry!r} is not a (series, label, direction) "
                    "triple; pass e.g. [('SA tagged', 'x', 'row')]"
                )
            triples.append((str(entry[0]), str(entry[1]), entry[2]))
    labels = [t[1] for t in triples]
    if not triples or len(set(labels)) != len(labels):
        raise HarpxError(f"tag_directions must give unique tag labels; got {labels!r}")
    return triples


def _select(selector: str, images: list[_Image]) -> list[_Image]:
    uids = sorted(
        {im.series_uid for im in images if selector in (im.series_uid, im.description, im.number)}
    )
    if not uids:
        raise HarpxError(
            f"tag_directions names series {selector!r}, which matches no SeriesInstanceUID, "
            f"SeriesDescription or SeriesNumber; series found:\n{_series_listing(images)}"
        )
    if len(uids) > 1:
        raise HarpxError(
            f"tag_directions series {selector!r} matches {len(uids)} series {uids!r}; use the "
            "SeriesInstanceUID to pick one"
        )
    return [im for im in images if im.series_uid == uids[0]]


def _direction(label: str, value: Any, stack: _Stack) -> FloatArray:
    if isinstance(value, str):
        named = {"row": stack.along_row, "column": stack.along_column, "col": stack.along_column}
        if value not in named:
            raise HarpxError(
                f"direction {value!r} of tag {label!r} is unknown; use 'row' (along a row, the "
                "first ImageOrientationPatient triplet), 'column' or a 3-vector (x, y, z)"
            )
        vector = np.asarray(named[value], dtype=np.float64)
    else:
        vector = np.asarray(value, dtype=np.float64)
    norm = float(np.linalg.norm(vector)) if vector.shape == (3,) else 0.0
    if not (np.isfinite(norm) and norm > 0):
        raise HarpxError(
            f"direction of tag {label!r} is {value!r}; expected 'row', 'column' or a non-zero "
            "3-vector (x, y, z) in patient coordinates"
        )
    vector = vector / norm
    through = abs(float(vector @ stack.normal))
    if through > 0.5:
        raise HarpxError(
            f"direction {np.round(vector, 4).tolist()} of tag {label!r} is mostly through the "
            f"slices of {stack.name()} (|d·n| = {through:.3g}); a stack only resolves tags in "
            "its image plane: use 'row', 'column' or an in-plane vector"
        )
    return vector


def _sequence(sequence: str | None, stacks: list[_Stack]) -> str:
    if sequence is not None:
        if sequence not in SEQUENCES:
            raise HarpxError(f"sequence is {sequence!r}; expected one of {sorted(SEQUENCES)}")
        return sequence
    found: set[str | None] = set()
    for stack in stacks:
        im = stack.images[0][0]
        text = (im.sequence_name + " " + im.description).upper()
        text = text.replace("-", "").replace("_", "").replace(" ", "")
        found.add("CSPAMM" if "CSPAMM" in text else "SPAMM" if "SPAMM" in text else None)
    if len(found) == 1 and (only := found.pop()) is not None:
        return only
    raise HarpxError(
        "sequence is required: the DICOM headers (SequenceName, ProtocolName, "
        "SeriesDescription) do not say whether the images are SPAMM magnitude or CSPAMM "
        "difference images; pass sequence='SPAMM' or sequence='CSPAMM'"
    )


def _frequencies(tag_period: float | Mapping[str, float] | None, labels: list[str]) -> FloatArray:
    if tag_period is None:
        raise HarpxError(
            "tag_period is required: DICOM does not record the tag spacing; pass "
            "tag_period=<mm> (e.g. tag_period=8.0) or a mapping tag label -> mm"
        )
    periods = []
    for label in labels:
        value = tag_period.get(label) if isinstance(tag_period, Mapping) else tag_period
        period = _float(value)
        if period is None or period <= 0:
            raise HarpxError(
                f"tag_period for tag {label!r} is {value!r}; expected a positive tag spacing in mm"
            )
        periods.append(period)
    return 1.0 / np.asarray(periods)


# ---------------------------------------------------------------------------------------------
# resampling


# ---------------------------------------------------------------------------------------------
# public entry point


def read_tagged(
    paths_or_folder: PathLike | Sequence[PathLike],
    *,
    spacing: float | None = None,
    tag_period: float | Mapping[str, float] | None = None,
    tag_directions: Any = None,
    sequence: str | None = None,
    time_tolerance: float = 1.0,
) -> xr.Dataset:
    """Read tagged cine DICOM series and resample them onto one grid (``tagged/1``).

    Parameters
    ----------
    paths_or_folder : str, os.PathLike or sequence of them
        A folder (searched recursively; files that are not DICOM and DICOM objects without
        images are skipped) or DICOM files / folders. Classic single-frame MR images and
        enhanced multi-frame images are both accepted.
    spacing : float, optional
        Isotropic grid spacing in mm. Default: the finest in-plane pixel spacing of the
        selected series.
    tag_period : float or mapping of str to float
        Tag spacing in mm (one for all tags, or per tag label). Required: DICOM does not
        record it. ``tag_frequency = 1 / tag_period`` cycles/mm.
    tag_directions : mapping or sequence
        Which series carries which tags. Either a mapping from a series selector
        (SeriesInstanceUID, SeriesDescription or SeriesNumber) to a list of
        ``(label, direction)`` pairs (or one pair), or a sequence of
        ``(series, label, direction)`` triples. ``direction`` is ``"row"`` (along an image
        row: the first ``ImageOrientationPatient`` triplet), ``"column"`` (the second
        triplet) or a 3-vector (x, y, z) in patient coordinates (normalised here). A grid-
        tagged series gives two entries. Each entry becomes one ``tag`` of the result, in
        the given order.
    sequence : {"SPAMM", "CSPAMM"}, optional
        Kind of images. Default: read from SequenceName / ProtocolName / SeriesDescription
        when they mention CSPAMM or SPAMM; otherwise required.
    time_tolerance : float, default 1.0
        Largest disagreement in ms between the trigger times of one frame across slices and
        series.

    Returns
    -------
    xarray.Dataset
        ``tagged/1``: ``image`` (tag, time, z, y, x) float64 rescaled pixel values
        (``RescaleSlope``/``RescaleIntercept`` applied; 0 outside the tag's mask), ``mask``
        (tag, z, y, x) bool, coordinates ``x, y, z`` (patient LPS, mm, voxel centres),
        ``time`` (mean TriggerTime per frame, ms), ``tag_direction``, ``tag_frequency`` and
        ``slice_axis`` (the patient axis closest to each series' slice normal). Attributes
        ``sequence``, ``source="DICOM"`` and ``dicom_series`` (tag label: SeriesInstanceUID).

    Raises
    ------
    HarpxError
        No DICOM images found (names the folder); an unreadable or truncated file (names it);
        a missing geometry or timing attribute (names it and the file); slices of a series
        that are not parallel or shifted in plane; different frame counts or trigger times
        across slices or series; a series selector that matches no or several series; a
        missing ``tag_period``, ``tag_directions`` or ``sequence``; a ``spacing`` or
        ``time_tolerance`` that is not a number in range; an output grid larger than half
        the memory available (pass a coarser ``spacing``).
    TypeError
        If ``paths_or_folder`` is not a path or a list of paths.
    SchemaError
        If the result breaks ``tagged/1`` (e.g. tag frequency above the grid's Nyquist
        limit: choose a finer ``spacing``).
    ImportError
        If pydicom is not installed (``pip install harpx[dicom]``).

    Notes
    -----
    Geometry, interpolation and mask conventions are in the module docstring
    (:mod:`harpx.io.dicom`). Pixel positions follow DICOM PS3.3 C.7.6.2.1.1,

    .. math:: p_{ij} = P + j \\, Δc \\, r + i \\, Δr \\, c .

    Time index 0 is the earliest trigger time (the tagging pulse is applied on the R wave).
    CSPAMM acquisitions written as separate A and B series must be subtracted beforehand.
    The grid covers the union of the stacks' bounding boxes; two orthogonal stacks of a
    heart at 1.4 mm spacing give ~20 million voxels per frame, so pass a coarser ``spacing``
    for large fields of view (a :class:`~harpx.errors.HarpxWarning` flags outputs above
    2 GiB; above half the available memory the call is refused before allocating).
    """
    if spacing is not None and (isinstance(spacing, bool) or not isinstance(spacing, numbers.Real)):
        raise HarpxError(f"spacing is {spacing!r}; expected a positive grid spacing in mm")
    if (
        isinstance(time_tolerance, bool)
        or not isinstance(time_tolerance, numbers.Real)
        or not (math.isfinite(time_tolerance) and time_tolerance >= 0)
    ):
        raise HarpxError(
            f"time_tolerance is {time_tolerance!r}; expected a finite number of ms >= 0 (the "
            "largest disagreement of trigger times within one frame)"
        )
    images = _discover(paths_or_folder)
    triples = _parse_tags(tag_directions, images)
    by_series: dict[str, _Stack] = {}
    for selector, _, _ in triples:
        members = _select(selector, images)
        uid = members[0].series_uid
        if uid not in by_series:
            by_series[uid] = _build_stack(members, time_tolerance)
    stacks = list(by_series.values())
    tag_stacks = [by_series[_select(sel, images)[0].series_uid] for sel, _, _ in triples]
    labels = [label for _, label, _ in triples]
    directions = np.array(
        [_direction(label, d, s) for (_, label, d), s in zip(triples, tag_stacks, strict=True)]
    )
    frequencies = _frequencies(tag_period, labels)
    kind = _sequence(sequence, stacks)

    counts = {s.name(): s.times.size for s in stacks}
    if len(set(counts.values())) > 1:
        raise HarpxError(
            f"series have different numbers of frames {counts}; every tagged series needs the "
            "same cine frames (select matching series)"
        )
    reference = stacks[0]
    for s in stacks[1:]:
        gaps = np.abs(s.times - reference.times)
        if gaps.max() > time_tolerance:
            raise HarpxError(
                f"TriggerTime of {s.name()} differs from {reference.name()} by up to "
                f"{gaps.max():.3g} ms at frame {int(np.argmax(gaps))} (> time_tolerance="
                f"{time_tolerance:g} ms); raise time_tolerance if the frames really correspond"
            )
    times = np.mean([s.times for s in stacks], axis=0)

    step = float(min(s.pixel_spacing.min() for s in stacks)) if spacing is None else spacing
    if not (math.isfinite(step) and step > 0):
        raise HarpxError(f"spacing is {spacing!r}; expected a positive grid spacing in mm")
    x, y, z = common_grid([s.geometry for s in stacks], step)
    nbytes = len(triples) * times.size * x.size * y.size * z.size * 8
    limit = _available_memory() // 2
    if nbytes > limit:
        raise HarpxError(
            f"the resampled image would need {nbytes / 2**30:.1f} GiB ({z.size}x{y.size}x"
            f"{x.size} voxels at {step:g} mm, {len(triples)} tags, {times.size} frames), more "
            f"than half the memory available ({limit / 2**30:.1f} GiB); pass a coarser "
            "spacing= (in mm)"
        )
    if nbytes > LARGE_OUTPUT_BYTES:
        warnings.warn(
            f"the resampled image needs {nbytes / 2**30:.1f} GiB ({z.size}x{y.size}x{x.size} "
            f"voxels at {step:g} mm); pass a coarser spacing= to reduce it",
            HarpxWarning,
            stacklevel=2,
        )
    volumes = dict(zip(by_series, _load_pixels(stacks), strict=True))
    resampled = {
        uid: resample_stack(stack.geometry, volumes[uid], x, y, z)
        for uid, stack in by_series.items()
    }
    image = np.stack([resampled[s.uid][0] for s in tag_stacks])
    mask = np.stack([resampled[s.uid][1] for s in tag_stacks])
    slice_axes = [AXES[int(np.argmax(np.abs(s.normal)))] for s in tag_stacks]

    return tagged_dataset(
        image,
        tag=labels,
        tag_direction=directions,
        tag_frequency=frequencies,
        slice_axis=slice_axes,
        time=times,
        z=z,
        y=y,
        x=x,
        sequence=kind,
        mask=mask,
        attrs={
            "source": "DICOM",
            "dicom_series": "; ".join(
                f"{label}: {s.uid}" for label, s in zip(labels, tag_stacks, strict=True)
            ),
        },
    )
