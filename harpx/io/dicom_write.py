"""Write a ``tagged/1`` dataset as classic tagged cine DICOM series (one per tag).

Meant for examples and tests: synthetic scenes written as a scanner would write them, so
that :func:`harpx.io.dicom.read_tagged` can be exercised end to end. Each tag becomes one
series of *MR Image Storage* files, one per (slice, frame), in the grid's patient
coordinates (LPS, mm), with ``TriggerTime`` from ``time`` and the pixel values stored as
``uint16`` with one ``RescaleSlope``/``RescaleIntercept`` per series (quantisation error at
most half a slope, i.e. range/131070). pydicom is needed (``pip install harpx[dicom]``).

Slices
------
Where the dataset tells a tag's slice geometry (:func:`harpx.imaging.harp.slice_geometry`:
the ``slice_thickness`` and ``slice_position`` coordinates, or a synthetic scene's stack
attributes), the series has one slice per slice centre, at that position along the tag's
``slice_axis``, with that ``SliceThickness`` (left empty where the thickness is unknown):
the acquisition as the scanner made it, which :func:`~harpx.io.dicom.read_tagged` reads
back with the same geometry. The grid images are then taken to be the slices interpolated
as :func:`harpx.imaging.stacks.resample_stack` does (linear between slice centres, the
nearest slice between the outermost centre and the slab face), and each slice image is the
least-squares solution of that interpolation over the grid planes in the tag's ``mask``
and slab: exact when the grid images were made that way (the scenes, a read-back DICOM
stack), and a :class:`~harpx.errors.HarpxWarning` names the misfit when they were not.
Without slice geometry the slices are the grid planes normal to the ``slice_axis`` where
the ``mask`` holds data (every plane without a mask), ``SliceThickness`` the grid spacing
along that axis.

Every call writes a new study: fresh Study, Series and SOP Instance UIDs, so two exports
never share a series. The files are written into a hidden folder beside the target and
moved into place when all are written, so an interrupted export leaves nothing behind.
"""

from __future__ import annotations

import os
import re
import shutil
import uuid
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import FloatArray, IntArray, PathLike
from harpx.errors import HarpxWarning, SchemaError, user_stacklevel
from harpx.imaging.harp import slice_geometry
from harpx.io.netcdf import remove_stale_temporaries, temporary_prefix
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
    """``value`` as a DICOM decimal string: as many digits (≤ 10) as fit 16 characters."""
    for digits in range(10, 5, -1):
        text = f"{value:.{digits}g}"
        if len(text) <= 16:
            return text
    return text


def write_tagged(ds: xr.Dataset, folder: PathLike, *, overwrite: bool = False) -> dict[str, str]:
    """Write every tag of a ``tagged/1`` dataset as one DICOM series under ``folder``.

    Parameters
    ----------
    ds : xarray.Dataset
        ``tagged/1`` dataset (uniform grid, mm; ``time`` in ms).
    folder : str or os.PathLike
        Output folder, created with its parents; files go to ``folder/<tag>/``. It must be
        absent or empty: a reader of the folder would otherwise see the old files too.
    overwrite : bool, default False
        Replace the content of a non-empty ``folder``, provided it holds only what an
        earlier export wrote (sub-folders of ``.dcm`` files). The old content is removed
        only once the new export is complete.

    Returns
    -------
    dict of str to str
        ``SeriesDescription`` of each tag's series (``"tagged <tag>"``), for the
        ``tag_directions`` argument of :func:`~harpx.io.dicom.read_tagged`.

    Raises
    ------
    SchemaError
        If ``ds`` is not a valid ``tagged/1`` dataset, its images are not finite, a tag
        label cannot be a folder name (letters, digits, ``_``, ``-`` and ``.`` only), or
        its grid does not resolve the slices its slice geometry names (a slice without a
        grid plane in its reach: module notes).
    FileExistsError
        If ``folder`` is not empty and ``overwrite`` is False, or holds files that an export
        did not write (even with ``overwrite=True``), or is a file or a symbolic link.
        Nothing is written.
    PermissionError
        If the folder that holds ``folder`` is not writable (the export is staged there).
    ImportError
        Without pydicom.
    """
    validate(ds, "tagged")
    try:
        import pydicom  # noqa: F401
        from pydicom.uid import generate_uid
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("writing DICOM needs pydicom: pip install harpx[dicom]") from exc
    labels = [str(t) for t in np.asarray(ds["tag"].values).ravel()]
    bad = [label for label in labels if not _SAFE_LABEL.fullmatch(label) or set(label) == {"."}]
    if bad:
        raise SchemaError(
            f"tag labels {bad!r} cannot name the series' folders; use letters, digits, '_', "
            "'-' and '.' only (e.g. ds.assign_coords(tag=ds.tag.copy(data=['x', 'y', 'z'])), which "
            "keeps the coordinate's attributes)"
        )
    root = Path(os.path.abspath(folder))  # "." and "out/.." name their folder too
    _check_target(root, overwrite)
    root.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(root.parent, root.name)  # of exports that were killed
    staging = root.parent / f"{temporary_prefix(root.name)}{uuid.uuid4().hex[:12]}.tmp"
    try:
        staging.mkdir()
    except OSError as exc:
        raise PermissionError(
            f"cannot create the staging folder {str(staging)!r} ({exc.strerror or exc}); the "
            f"export is written beside {str(root)!r} first so that an interrupted export "
            f"leaves nothing behind: make {str(root.parent)!r} writable or write elsewhere"
        ) from exc
    try:
        described = _write_series(ds, staging, generate_uid())
        _move_into_place(staging, root)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return described


#: Tag labels usable as folder names.
_SAFE_LABEL = re.compile(r"[A-Za-z0-9_.-]+")


def _check_target(root: Path, overwrite: bool) -> None:
    """Refuse a target that is a file, or a non-empty folder unless it is an old export."""
    if root.is_symlink():
        raise FileExistsError(
            f"DICOM output folder {str(root)!r} is a symbolic link; pass the folder it points "
            f"to ({str(root.resolve())!r}) or another path"
        )
    if root.exists() and not root.is_dir():
        raise FileExistsError(
            f"DICOM output folder {str(root)!r} is a file, not a folder; choose another path"
        )
    if not root.is_dir():
        return
    entries = sorted(root.iterdir())
    if not entries:
        return
    if not overwrite:
        raise FileExistsError(
            f"DICOM output folder {str(root)!r} is not empty ({len(entries)} entries, e.g. "
            f"{entries[0].name!r}); its old files would be read back together with the new "
            "series. Write into a new or empty folder, or pass overwrite=True to replace an "
            "earlier export"
        )
    foreign = [
        e
        for e in entries
        if not e.is_dir() or e.is_symlink() or any(not _is_dicom_file(f) for f in e.iterdir())
    ]
    if foreign:
        raise FileExistsError(
            f"refusing to overwrite {str(root)!r}: {foreign[0].name!r} there is not a folder "
            "of .dcm files that write_tagged writes, so it may be other data; choose a new "
            "or empty folder"
        )


def _is_dicom_file(path: Path) -> bool:
    return path.is_file() and not path.is_symlink() and path.suffix.lower() == ".dcm"


def _move_into_place(staging: Path, root: Path) -> None:
    """Rename the finished export to ``root``; an old export there is removed after."""
    if root.is_dir() and not any(root.iterdir()):
        root.rmdir()
    if not root.exists():
        os.replace(staging, root)
        return
    old = root.parent / f"{temporary_prefix(root.name)}{uuid.uuid4().hex[:12]}-old.tmp"
    os.replace(root, old)
    try:
        os.replace(staging, root)
    except BaseException:
        os.replace(old, root)  # put the earlier export back
        raise
    shutil.rmtree(old, ignore_errors=True)


def _write_series(ds: xr.Dataset, root: Path, study: str) -> dict[str, str]:
    """Write every tag's series under ``root`` (fresh UIDs) and return their descriptions."""
    from pydicom.dataset import FileDataset, FileMetaDataset
    from pydicom.uid import ExplicitVRLittleEndian, MRImageStorage, generate_uid

    described: dict[str, str] = {}
    times = np.asarray(ds["time"].values, dtype=np.float64)
    geometry = slice_geometry(ds)
    for number, tag in enumerate(ds["tag"].values, start=1):  # one series per tag (≤ 3)
        label = str(tag)
        axis = str(ds["slice_axis"].sel(tag=tag).values)
        rows_dim, cols_dim = _IMAGE_DIMS[axis]
        r, c = _PLANES[axis]
        image = ds["image"].sel(tag=tag).transpose("time", axis, rows_dim, cols_dim)
        values = np.asarray(image.values, dtype=np.float64)
        if not np.all(np.isfinite(values)):  # a lazy dataset is only checked here
            raise SchemaError(
                f"'image' of tag {label!r} has {int(np.count_nonzero(~np.isfinite(values)))} "
                "non-finite values (NaN/inf); DICOM stores numbers only: fill or drop them"
            )
        planes = np.arange(ds.sizes[axis])
        if "mask" in ds:
            mask = ds["mask"].sel(tag=tag).transpose(axis, rows_dim, cols_dim).values
            planes = planes[mask.reshape(len(planes), -1).any(axis=1)]
        coords = {d: np.asarray(ds[d].values, dtype=np.float64) for d in ("x", "y", "z")}
        spacing = {d: float(np.diff(v).mean()) if v.size > 1 else 1.0 for d, v in coords.items()}
        centres, thickness = _tag_slices(geometry, number - 1)
        slice_coord = coords[axis][planes]
        thickness_text = _decimal(spacing[axis])
        if centres is not None:
            values = _slice_images(values, coords[axis], planes, centres, thickness, label)
            planes, slice_coord = np.arange(centres.size), centres
            thickness_text = _decimal(thickness) if np.isfinite(thickness) else ""
        lo, hi = float(values.min()), float(values.max())
        slope = max((hi - lo) / 65535.0, 1e-12)
        stored = np.rint((values - lo) / slope).clip(0, 65535).astype("<u2")
        series = generate_uid()
        description = f"tagged {label}"
        described[label] = description
        out = root / label
        out.mkdir(parents=True, exist_ok=True)
        for k in planes:  # slices of this series
            origin = {d: coords[d][0] for d in ("x", "y", "z")}
            origin[axis] = slice_coord[k] if centres is not None else coords[axis][k]
            position = [origin["x"], origin["y"], origin["z"]]
            for t in range(len(times)):  # frames
                path = out / f"{label}_{int(k):04d}_{t:03d}.dcm"
                meta = FileMetaDataset()
                meta.MediaStorageSOPClassUID = MRImageStorage
                meta.MediaStorageSOPInstanceUID = generate_uid()
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
                f.SliceThickness = thickness_text
                f.TriggerTime = _decimal(times[t])
                f.RescaleSlope, f.RescaleIntercept = _decimal(slope), _decimal(lo)
                f.Rows, f.Columns = values.shape[2], values.shape[3]
                f.BitsAllocated, f.BitsStored, f.HighBit = 16, 16, 15
                f.PixelRepresentation, f.SamplesPerPixel = 0, 1
                f.PhotometricInterpretation = "MONOCHROME2"
                f.PixelData = np.ascontiguousarray(stored[t, k]).tobytes()
                f.save_as(path, enforce_file_format=True)
    return described


def _tag_slices(geometry: dict[str, xr.Variable], t: int) -> tuple[FloatArray | None, float]:
    """Slice centres (None: unknown) and thickness (NaN: unknown) of tag number ``t``."""
    if not geometry:
        return None, float("nan")
    positions = np.asarray(geometry["slice_position"].values, dtype=np.float64)[t]
    centres = positions[np.isfinite(positions)]
    thickness = float(np.asarray(geometry["slice_thickness"].values, dtype=np.float64)[t])
    return (centres if centres.size else None), thickness


def _slice_images(
    values: FloatArray,
    grid: FloatArray,
    planes: IntArray,
    centres: FloatArray,
    thickness: float,
    label: str,
) -> FloatArray:
    """The slice images (time, slice, rows, columns) whose resampling gives the grid's.

    ``values`` (time, plane, rows, columns) on the grid planes at ``grid``; ``planes`` the
    planes that hold data (the mask). Planes outside the slab are left out.
    """
    half = 0.5 * thickness if np.isfinite(thickness) else np.inf
    at = grid[planes]
    inside = (at >= centres[0] - half - 1e-6) & (at <= centres[-1] + half + 1e-6)
    used, at = planes[inside], at[inside]
    weights = np.stack(  # linear between centres, nearest beyond them (resample_stack)
        [np.interp(at, centres, np.eye(centres.size)[s]) for s in range(centres.size)], axis=1
    )
    if used.size == 0 or np.linalg.matrix_rank(weights) < centres.size:
        step = float(np.diff(grid).mean()) if grid.size > 1 else float("nan")
        raise SchemaError(
            f"tag {label!r}: its {centres.size} slices (centres {np.round(centres, 3).tolist()}"
            f" mm) are not resolved by the {used.size} grid planes of its slab and mask "
            f"(spacing {step:.4g} mm): a slice has no plane in its reach. Write the images on "
            "a finer grid, or drop slice_thickness and slice_position to write the grid planes"
        )
    block = np.moveaxis(values[:, used], 1, 0).reshape(used.size, -1)
    slices, *_ = np.linalg.lstsq(weights, block, rcond=None)
    misfit = float(np.abs(weights @ slices - block).max())
    scale = float(np.ptp(block)) if block.size else 0.0
    if misfit > max(scale / 131070.0, 1e-9):  # above half a uint16 step of the range
        warnings.warn(
            f"tag {label!r}: the images are not linear between the slice centres that its "
            f"slice geometry gives (largest misfit {misfit:.3g} of a range {scale:.3g}); the "
            "written slices are their least-squares fit, so the series does not reproduce "
            "the grid images",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    shape = (centres.size, values.shape[0], *values.shape[2:])
    return np.moveaxis(slices.reshape(shape), 0, 1)
