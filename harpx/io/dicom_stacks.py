"""DICOM images grouped into stacks of parallel slices, checked, and their pixels loaded.

A *stack* is every image of one series (:func:`~harpx.io.dicom.read_tagged` picks the
series): all must share orientation, matrix size and pixel spacing, and their positions
must differ only along the slice normal ``n = r × c`` (slices ordered by ``(P - P_0)·n``,
not by file order or ``InstanceNumber``). Its frames are the images of each slice sorted
by trigger time; every slice needs the same frames. Positions and directions are those of
:mod:`harpx.io.dicom_headers`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from harpx._typing import FloatArray
from harpx.errors import HarpxError, HarpxWarning, user_stacklevel
from harpx.imaging.stacks import SliceStack
from harpx.io.dicom_headers import _STAMP_TIME, _Image, _pydicom

__all__ = ["GAP_ERROR", "INPLANE_TOL", "ORIENTATION_TOL", "SLICE_TOL", "UNIT_TOL"]

#: Largest difference of direction cosines for two images to count as parallel.
ORIENTATION_TOL = 1e-3
#: Slice positions closer than this (mm) along the normal are the same slice.
SLICE_TOL = 1e-2
#: In-plane offset between slices of a stack tolerated, as a fraction of a pixel.
INPLANE_TOL = 1e-2
_TIME_DUPLICATE = 1e-3  # ms: two frames of one slice closer than this are always duplicates
#: A mean frame interval below this (ms) is faster than any cine MRI: times in seconds?
_MIN_FRAME_INTERVAL = 1.0
#: Frame intervals further than this fraction from their median are irregular (warning).
_INTERVAL_TOL = 0.25
#: SliceThickness values of one series further apart than this (mm) disagree.
_THICKNESS_TOL = 1e-3


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
    thickness: float | None = None  # SliceThickness, mm (None: absent or not positive)
    caveats: list[str] = field(default_factory=list)  # doubts warned about, for the result

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
    _check_alike(images, orientation, spacing, label)
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
    by_slice = [sorted((images[k] for k in members), key=lambda im: im.time) for members in slices]
    caveats, seconds = _time_caveats(by_slice, label)
    # times in seconds: frames are far closer than time_tolerance, only equal ones are copies
    duplicate = _TIME_DUPLICATE if seconds else max(time_tolerance, _TIME_DUPLICATE)
    frames = [_cine(ims, label, duplicate, time_tolerance) for ims in by_slice]
    times = _frame_times(frames, time_tolerance, label)
    caveats += _check_intervals(times, frames, label)
    offsets = local[[s[0] for s in slices], 2] - local[base, 2]
    _check_gaps(offsets, [images[s[0]] for s in slices], label)
    below, above = _slab_margins(first, offsets, label)
    thickness = first.thickness if first.thickness is not None and first.thickness > 0 else None
    return _Stack(
        uid=first.series_uid,
        description=first.description,
        origin=positions[base],
        along_row=along_row,
        along_column=along_column,
        normal=normal,
        pixel_spacing=spacing,
        rows=first.rows,
        columns=first.columns,
        offsets=offsets,
        slab=(float(offsets[0] - below), float(offsets[-1] + above)),
        times=times,
        images=frames,
        thickness=thickness,
        caveats=caveats,
    )


def _check_alike(
    images: list[_Image], orientation: FloatArray, spacing: FloatArray, label: str
) -> None:
    """Every image of a series has a position and a time, and the first one's orientation,
    matrix size and pixel spacing; else HarpxError naming the two images."""
    first = images[0]
    for im in images:
        if im.problem is not None:
            raise HarpxError(im.problem)
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
    _check_rescale(images, label)
    _check_thickness(images, label)


def _check_rescale(images: list[_Image], label: str) -> None:
    """Every image of a series has RescaleSlope/RescaleIntercept, or none has (else harpx
    would scale some images and not others)."""
    keywords = ("RescaleSlope", "RescaleIntercept")
    for k, keyword in enumerate(keywords):
        given = np.array([im.rescale[k] for im in images])
        if given.any() and not given.all():
            has, lacks = images[int(np.argmax(given))], images[int(np.argmin(given))]
            raise HarpxError(
                f"DICOM attribute {keyword!r} is missing in {lacks.where()} but present in "
                f"{has.where()} (and {int(given.sum())} of the {given.size} images of "
                f"{label}); the pixel values of the images would not be on one scale: fix "
                "the export or drop the images without it"
            )


def _check_thickness(images: list[_Image], label: str) -> None:
    """Every image of a series has the same SliceThickness (within ``_THICKNESS_TOL`` mm),
    or none has one."""
    values = np.array([np.nan if im.thickness is None else im.thickness for im in images])
    known = np.isfinite(values)
    if not known.any():
        return
    if not known.all():
        has, lacks = images[int(np.argmax(known))], images[int(np.argmin(known))]
        raise HarpxError(
            f"DICOM attribute 'SliceThickness' is missing or unreadable in {lacks.where()} "
            f"but is {has.thickness:g} mm in {has.where()} ({label}); harpx uses it for the "
            "slab and the blur model: fix the export or drop the images without it"
        )
    low, high = int(np.argmin(values)), int(np.argmax(values))
    if values[high] - values[low] > _THICKNESS_TOL:
        raise HarpxError(
            f"SliceThickness differs within {label}: {values[low]:g} mm in "
            f"{images[low].where()} but {values[high]:g} mm in {images[high].where()}; a "
            "stack needs one slice thickness (fix the export or select the files of one "
            "acquisition)"
        )


def _cine(ims: list[_Image], label: str, duplicate: float, time_tolerance: float) -> list[_Image]:
    """One slice's images in time order; HarpxError for two at most ``duplicate`` ms apart
    (a copy of one file, or repeated acquisitions in one series)."""
    gaps = np.diff([im.time for im in ims])
    if gaps.size and gaps.min() <= duplicate:
        k = int(np.argmin(gaps))
        a, b = ims[k], ims[k + 1]
        if a.sop_uid and a.sop_uid == b.sop_uid and a.frame == b.frame:
            raise HarpxError(
                f"{a.where()} and {b.where()} are the same image twice (SOPInstanceUID "
                f"{a.sop_uid!r}): one is a copy of the other; remove the copy"
            )
        raise HarpxError(
            f"{label} has two images at the same slice position {gaps[k]:.3g} ms apart "
            f"(TriggerTime {a.time:g} and {b.time:g} ms, within time_tolerance="
            f"{time_tolerance:g} ms): {a.where()} and {b.where()}; put repeated acquisitions "
            "(e.g. CSPAMM A and B) in separate series or select the files (if they are "
            "distinct frames, lower time_tolerance)"
        )
    return ims


def _time_caveats(by_slice: list[list[_Image]], label: str) -> tuple[list[str], bool]:
    """Warn (and return the caveats) when a series' times are not trigger delays in ms:
    times from FrameAcquisitionDateTime, or a mean frame interval below
    ``_MIN_FRAME_INTERVAL`` (times in seconds? then also True). HarpxError for a series
    whose images mix FrameAcquisitionDateTime with trigger times."""
    caveats = []
    flat = [im for ims in by_slice for im in ims]
    stamped = [im for im in flat if im.time_name == _STAMP_TIME]
    if stamped and len(stamped) < len(flat):
        other = next(im for im in flat if im.time_name != _STAMP_TIME)
        raise HarpxError(
            f"{label} mixes clocks: {stamped[0].path} has no NominalCardiacTriggerDelayTime "
            f"(its times are FrameAcquisitionDateTime) but {other.where()} has a "
            f"{other.time_name}; fix the export or drop the files without trigger delays"
        )
    if stamped:
        caveats.append(f"{label}: frame times from FrameAcquisitionDateTime")
        warnings.warn(
            f"{stamped[0].path} ({label}) has no NominalCardiacTriggerDelayTime: its frame "
            "times are FrameAcquisitionDateTime since the file's first frame, which equals "
            "the delay after the R wave only if the file holds one heartbeat acquired in real "
            "time (segmented acquisitions span many beats); check the time coordinate (noted "
            "in the result's attribute 'dicom_caveats')",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    times = [np.array([im.require("time") for im in ims]) for ims in by_slice]
    means = [(t[-1] - t[0]) / (t.size - 1) for t in times if t.size > 1]
    seconds = bool(means) and float(np.median(means)) < _MIN_FRAME_INTERVAL
    if seconds:
        interval = float(np.median(means))
        caveats.append(f"{label}: mean frame interval {interval:.3g} ms (TriggerTime in s?)")
        warnings.warn(
            f"the frames of {label} are {interval:.3g} ms apart on average (TriggerTime "
            f"{times[0][0]:g} to {times[0][-1]:g}): no cine MRI is that fast, so TriggerTime "
            "is most likely in seconds, not ms as DICOM defines it; the time coordinate is "
            "kept as read (multiply it by 1000 if so; noted in the result's attribute "
            "'dicom_caveats')",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return caveats, seconds


def _check_intervals(times: FloatArray, frames: list[list[_Image]], label: str) -> list[str]:
    """Warn (and return the caveat) when the frame intervals of a series are irregular: a
    missing frame, or two acquisitions interleaved in one series."""
    if times.size < 3:
        return []
    gaps = np.diff(times)
    median = float(np.median(gaps))
    deviation = np.abs(gaps - median)
    k = int(np.argmax(deviation))
    if deviation[k] <= _INTERVAL_TOL * median:
        return []
    warnings.warn(
        f"the frame intervals of {label} are irregular: {gaps[k]:.4g} ms between frames {k} "
        f"and {k + 1} ({frames[0][k].where()} and {frames[0][k + 1].where()}) against a "
        f"median of {median:.4g} ms (intervals {np.round(gaps, 3).tolist()}); frames are "
        "missing, or repeated acquisitions are interleaved in one series (select the files "
        "of one acquisition); noted in the result's attribute 'dicom_caveats'",
        HarpxWarning,
        stacklevel=user_stacklevel(),
    )
    return [f"{label}: irregular frame intervals ({gaps.min():.4g} to {gaps.max():.4g} ms)"]


def _frame_times(frames: list[list[_Image]], time_tolerance: float, label: str) -> FloatArray:
    """Each frame's mean TriggerTime over the slices (ms); HarpxError when the slices have
    different numbers of frames or their times differ by more than ``time_tolerance``."""
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
    mean: FloatArray = times.mean(axis=0)
    return mean


def _slab_margins(first: _Image, offsets: FloatArray, label: str) -> tuple[float, float]:
    """How far the data reach beyond the first and the last slice centre (mm): half the
    SliceThickness, else half the neighbouring gap; HarpxError for a single slice without
    a thickness."""
    thickness = first.thickness if first.thickness is not None and first.thickness > 0 else None
    if thickness is not None:
        return 0.5 * thickness, 0.5 * thickness
    if offsets.size > 1:
        return 0.5 * (offsets[1] - offsets[0]), 0.5 * (offsets[-1] - offsets[-2])
    raise HarpxError(
        f"DICOM attribute 'SliceThickness' is missing or not positive in {first.where()}; "
        f"{label} has a single slice, so harpx needs it to know how far the slice's data "
        "extends through plane"
    )


#: Largest deviation of an ImageOrientationPatient triplet from unit length, and of the
#: two triplets from orthogonality (``|r . c|``).
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
            stacklevel=user_stacklevel(),
        )


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
