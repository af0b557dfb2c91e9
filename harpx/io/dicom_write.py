"""Write a ``tagged/1`` dataset as classic tagged cine DICOM series (one per tag).

Meant for examples and tests: synthetic scenes written as a scanner would write them, so
that :func:`harpx.io.dicom.read_tagged` can be exercised end to end. Each tag becomes one
series of *MR Image Storage* files, one per (slice, frame): slices are the grid planes
normal to the tag's ``slice_axis`` where its ``mask`` holds data (every plane without a
mask), in the grid's patient coordinates (LPS, mm), with ``SliceThickness`` equal to the
grid spacing along that axis, ``TriggerTime`` from ``time`` and the pixel values stored as
``uint16`` with one ``RescaleSlope``/``RescaleIntercept`` per series (quantisation error at
most half a slope, i.e. range/131070). pydicom is needed (``pip install harpx[dicom]``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import PathLike
from harpx.schema import validate

__all__ = ["write_tagged"]

# (row direction r, column direction c) per slice axis: r along increasing column index
_PLANES = {
    "z": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "y": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "x": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
}
# image axes (rows, columns) of the (z, y, x) grid per slice axis
_IMAGE_DIMS = {"z": ("y", "x"), "y": ("z", "x"), "x": ("z", "y")}


def _decimal(value: float) -> str:
    return f"{value:.10g}"  # DICOM decimal strings hold at most 16 characters


def write_tagged(ds: xr.Dataset, folder: PathLike) -> dict[str, str]:
    """Write every tag of a ``tagged/1`` dataset as one DICOM series under ``folder``.

    Parameters
    ----------
    ds : xarray.Dataset
        ``tagged/1`` dataset (uniform grid, mm; ``time`` in ms).
    folder : str or os.PathLike
        Output folder (created); files go to ``folder/<tag>/``.

    Returns
    -------
    dict of str to str
        ``SeriesDescription`` of each tag's series (``"tagged <tag>"``), for the
        ``tag_directions`` argument of :func:`~harpx.io.dicom.read_tagged`.

    Raises
    ------
    SchemaError
        If ``ds`` is not a valid ``tagged/1`` dataset.
    ImportError
        Without pydicom.
    """
    validate(ds, "tagged")
    try:
        import pydicom  # noqa: F401
        from pydicom.dataset import FileDataset, FileMetaDataset
        from pydicom.uid import ExplicitVRLittleEndian, MRImageStorage, generate_uid
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("writing DICOM needs pydicom: pip install harpx[dicom]") from exc
    root = Path(folder)
    study = generate_uid(entropy_srcs=[str(root), "study"])
    described: dict[str, str] = {}
    times = np.asarray(ds["time"].values, dtype=np.float64)
    for number, tag in enumerate(ds["tag"].values, start=1):  # one series per tag (≤ 3)
        label = str(tag)
        axis = str(ds["slice_axis"].sel(tag=tag).values)
        rows_dim, cols_dim = _IMAGE_DIMS[axis]
        r, c = _PLANES[axis]
        image = ds["image"].sel(tag=tag).transpose("time", axis, rows_dim, cols_dim)
        values = np.asarray(image.values, dtype=np.float64)
        planes = np.arange(ds.sizes[axis])
        if "mask" in ds:
            mask = ds["mask"].sel(tag=tag).transpose(axis, rows_dim, cols_dim).values
            planes = planes[mask.reshape(len(planes), -1).any(axis=1)]
        lo, hi = float(values.min()), float(values.max())
        slope = max((hi - lo) / 65535.0, 1e-12)
        stored = np.rint((values - lo) / slope).clip(0, 65535).astype("<u2")
        coords = {d: np.asarray(ds[d].values, dtype=np.float64) for d in ("x", "y", "z")}
        spacing = {d: float(np.diff(v).mean()) if v.size > 1 else 1.0 for d, v in coords.items()}
        series = generate_uid(entropy_srcs=[str(root), label])
        description = f"tagged {label}"
        described[label] = description
        out = root / label
        out.mkdir(parents=True, exist_ok=True)
        for k in planes:  # slices of this series
            origin = {d: coords[d][0] for d in ("x", "y", "z")}
            origin[axis] = coords[axis][k]
            position = [origin["x"], origin["y"], origin["z"]]
            for t in range(len(times)):  # frames
                path = out / f"{label}_{int(k):04d}_{t:03d}.dcm"
                meta = FileMetaDataset()
                meta.MediaStorageSOPClassUID = MRImageStorage
                meta.MediaStorageSOPInstanceUID = generate_uid(entropy_srcs=[str(path)])
                meta.TransferSyntaxUID = ExplicitVRLittleEndian
                f: Any = FileDataset(str(path), {}, file_meta=meta, preamble=b"\0" * 128)
                f.SOPClassUID = MRImageStorage
                f.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
                f.Modality = "MR"
                f.StudyInstanceUID = study
                f.SeriesInstanceUID = series
                f.SeriesDescription = description
                f.SeriesNumber = number
                f.SequenceName = str(ds.attrs.get("sequence", "SPAMM"))
                f.InstanceNumber = int(k) * len(times) + t + 1
                f.ImagePositionPatient = [_decimal(v) for v in position]
                f.ImageOrientationPatient = [_decimal(v) for v in (*r, *c)]
                f.PixelSpacing = [_decimal(spacing[rows_dim]), _decimal(spacing[cols_dim])]
                f.SliceThickness = _decimal(spacing[axis])
                f.TriggerTime = _decimal(times[t])
                f.RescaleSlope, f.RescaleIntercept = _decimal(slope), _decimal(lo)
                f.Rows, f.Columns = values.shape[2], values.shape[3]
                f.BitsAllocated, f.BitsStored, f.HighBit = 16, 16, 15
                f.PixelRepresentation, f.SamplesPerPixel = 0, 1
                f.PhotometricInterpretation = "MONOCHROME2"
                f.PixelData = np.ascontiguousarray(stored[t, k]).tobytes()
                f.save_as(path, enforce_file_format=True)
    return described
