"""DICOM headers read into per-image records, and the patient positions of their pixels.

Files are found and their headers read one record per 2D image (a classic single-frame
file or one frame of an enhanced multi-frame file, per-frame functional groups first) for
:func:`~harpx.io.dicom.read_tagged`. pydicom is an optional dependency
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

which :func:`voxel_positions` evaluates.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np

from harpx._typing import FloatArray, PathLike
from harpx.errors import HarpxError, HarpxWarning, user_stacklevel

__all__ = ["voxel_positions"]

_INSTALL_HINT = "pip install harpx[dicom]"


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
    #: whether the header has (RescaleSlope, RescaleIntercept); 1.0 and 0.0 stand in if not
    rescale: tuple[bool, bool] = (False, False)
    #: why the image cannot be used (raised as a HarpxError when a stack uses it)
    problem: str | None = None
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


def _rescale(slope: Any, intercept: Any, where: str) -> dict[str, Any]:
    """``slope``, ``intercept``, ``rescale`` (which of the two the header has) and
    ``problem`` (a value that is not a number, or a zero slope; naming ``where``) of an
    image; 1.0 and 0.0 stand in for absent or unreadable values."""
    present = (slope is not None and slope != "", intercept is not None and intercept != "")
    out: dict[str, Any] = {"slope": 1.0, "intercept": 0.0, "rescale": present, "problem": None}
    for name, keyword, raw, given in (
        ("slope", "RescaleSlope", slope, present[0]),
        ("intercept", "RescaleIntercept", intercept, present[1]),
    ):
        value = _float(raw) if given else out[name]
        if value is None:
            out["problem"] = (
                f"DICOM attribute {keyword!r} of {where} is {str(raw)!r}, which is not a "
                "finite number; harpx needs it to turn stored values into pixel values (fix "
                "the export or drop the file)"
            )
        else:
            out[name] = value
    if out["problem"] is None and out["slope"] == 0:
        out["problem"] = (
            f"DICOM attribute 'RescaleSlope' of {where} is {str(slope)!r}: a zero slope maps "
            f"every stored value to the intercept {out['intercept']:g}, so the image would "
            "be blank (fix the export or drop the file)"
        )
    return out


def _group_value(header: Any, per_frame: Any, sequence: str, keyword: str) -> Any:
    """Value of ``keyword`` from a functional group: per-frame, then shared, then top level."""
    shared = header.get("SharedFunctionalGroupsSequence")
    groups = [per_frame] + ([shared[0]] if shared else [])
    for group in groups:
        items = group.get(sequence) if group is not None else None
        if items and keyword in items[0]:
            return items[0].get(keyword)
    return header.get(keyword)


def _images_of(header: Any, path: Path, geometry_only: bool = False) -> list[_Image]:
    """Split a DICOM header into per-image records (one per frame of a multi-frame file).

    Multi-frame times are resolved (:func:`_frame_times`) unless ``geometry_only``."""
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
            **_rescale(header.get("RescaleSlope"), header.get("RescaleIntercept"), str(path)),
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
    delay_name = "NominalCardiacTriggerDelayTime (CardiacSynchronizationSequence)"
    for index, item in enumerate(per_frame):

        def value(sequence: str, keyword: str, item: Any = item) -> Any:
            return _group_value(header, item, sequence, keyword)

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
                time=_float(
                    value("CardiacSynchronizationSequence", "NominalCardiacTriggerDelayTime")
                ),
                **_rescale(
                    value("PixelValueTransformationSequence", "RescaleSlope"),
                    value("PixelValueTransformationSequence", "RescaleIntercept"),
                    f"{path} (frame {index + 1})",
                ),
                time_name=delay_name,
                **common,
            )
        )
    if not geometry_only:
        _frame_times(images, stamps, header)
    return images


def _frame_times(images: list[_Image], stamps: list[datetime | None], header: Any) -> None:
    """Times of the frames of a multi-frame file: every frame's trigger delay; when no frame
    has one, the time since the file's first acquired frame (``time_name`` ``_STAMP_TIME``:
    the stack warns), else the file's TriggerTime. HarpxError naming the frame when only
    some frames have a delay (their ``problem``)."""
    lacking = [im for im in images if im.time is None]
    if not lacking:
        return
    if len(lacking) < len(images):
        for im in lacking:
            im.problem = (
                f"{im.where()} has no readable NominalCardiacTriggerDelayTime but other frames "
                f"of the file have one ({len(lacking)} of {len(images)} frames lack it); "
                "harpx will not mix trigger delays with another clock: fix the export or drop "
                "the file"
            )
        return
    if all(s is not None for s in stamps):
        first = min(s for s in stamps if s is not None)
        for im, s in zip(images, stamps, strict=True):
            im.time = (s - first) / timedelta(milliseconds=1) if s is not None else None
            im.time_name = _STAMP_TIME
        return
    trigger = _float(header.get("TriggerTime"))
    for im in images:
        im.time = trigger
        im.time_name = "TriggerTime" if trigger is not None else im.time_name


#: ``_Image.time_name`` of frame times taken from FrameAcquisitionDateTime.
_STAMP_TIME = "FrameAcquisitionDateTime (FrameContentSequence)"


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
        where = Path(str(getattr(header, "filename", "<dataset>")))
        records.extend(_images_of(header, where, geometry_only=True))
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
        warnings.warn(
            message + "; those images are skipped", HarpxWarning, stacklevel=user_stacklevel()
        )
    if not images:
        where = ", ".join(repr(str(e)) for e in entries)
        raise HarpxError(
            f"no DICOM images found in {where}; pass a folder holding the tagged series or "
            "a list of .dcm files"
        )
    return images
