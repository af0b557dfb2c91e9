"""Import tagged cine MRI from DICOM into a ``tagged/1`` dataset.

:func:`read_tagged` reads tagged cine series as scanners write them -- one file per image
(classic *MR Image Storage*) or one enhanced multi-frame file per series (*Enhanced MR Image
Storage*, per-frame functional groups) -- and resamples every selected stack of parallel
slices onto one Cartesian grid in patient coordinates. pydicom is an optional dependency
(``pip install harpx[dicom]``); it is imported only when a function of harpx.io.dicom runs.

The DICOM geometry (:mod:`harpx.io.dicom_headers`) and the stacks
(:mod:`harpx.io.dicom_stacks`) have modules of their own; their public names stay
importable from here.

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
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import FloatArray, PathLike
from harpx.errors import HarpxError, HarpxWarning, user_stacklevel
from harpx.imaging.stacks import common_grid, resample_stack, tagged_dataset
from harpx.io.dicom_headers import _discover, _float, _Image, voxel_positions
from harpx.io.dicom_stacks import (
    GAP_ERROR,
    INPLANE_TOL,
    ORIENTATION_TOL,
    SLICE_TOL,
    UNIT_TOL,
    _build_stack,
    _load_pixels,
    _Stack,
)
from harpx.io.files import _available_memory
from harpx.schema import AXES, SEQUENCES

__all__ = [
    "GAP_ERROR",
    "INPLANE_TOL",
    "LARGE_OUTPUT_BYTES",
    "ORIENTATION_TOL",
    "SLICE_TOL",
    "UNIT_TOL",
    "read_tagged",
    "voxel_positions",
]

#: Output images larger than this (bytes) trigger a :class:`~harpx.errors.HarpxWarning`.
LARGE_OUTPUT_BYTES = 2**31


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


def _slice_geometry(stacks: list[_Stack], axes: list[str]) -> tuple[FloatArray, list[FloatArray]]:
    """Each tag's SliceThickness and slice centres along its slice axis (NaN: unknown)."""
    thickness = np.full(len(stacks), np.nan)
    positions: list[FloatArray] = []
    for t, (stack, axis) in enumerate(zip(stacks, axes, strict=True)):  # per tag (<= 3)
        centres = stack.geometry.centres_along(axis)
        positions.append(np.empty(0) if centres is None else centres)
        if centres is not None and stack.thickness is not None:
            thickness[t] = stack.thickness
    return thickness, positions


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
        series. Two images of one slice at most this far apart are duplicates (an error).

    Returns
    -------
    xarray.Dataset
        ``tagged/1``: ``image`` (tag, time, z, y, x) float64 rescaled pixel values
        (``RescaleSlope``/``RescaleIntercept`` applied; 0 outside the tag's mask), ``mask``
        (tag, z, y, x) bool, coordinates ``x, y, z`` (patient LPS, mm, voxel centres),
        ``time`` (mean TriggerTime per frame, ms), ``tag_direction``, ``tag_frequency``,
        ``slice_axis`` (the patient axis closest to each series' slice normal), and the
        slice geometry the tracker's blur correction models: ``slice_thickness`` (tag,
        ``SliceThickness`` in mm) and ``slice_position`` (tag, slice: the slice centres'
        coordinates along ``slice_axis``, mm, increasing, NaN-padded). A series whose
        normal is tilted off its ``slice_axis`` (by more than
        :data:`harpx.imaging.stacks.ALIGNMENT_TOL`) gets no slice positions and NaN
        thickness, as does the thickness of a series without ``SliceThickness``: nothing
        is guessed. Attributes ``sequence``, ``source="DICOM"``, ``dicom_series`` (tag
        label: SeriesInstanceUID) and ``dicom_caveats`` (the doubts about the times that
        were warned about, ``"; "``-separated; empty when none).

    Raises
    ------
    HarpxError
        No DICOM images found (names the folder); an unreadable or truncated file (names it);
        a missing geometry or timing attribute (names it and the file); a ``RescaleSlope`` or
        ``RescaleIntercept`` that is not a number, a zero ``RescaleSlope``, or one present
        in some images of a series only; ``SliceThickness`` that differs within a series; a
        multi-frame file where only some frames have ``NominalCardiacTriggerDelayTime``;
        two images of one slice within ``time_tolerance``; slices of a series
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

    Warns
    -----
    HarpxWarning
        When the frame times are doubtful (each also noted in ``dicom_caveats``): frame
        intervals that are irregular (missing frames, or interleaved acquisitions), a mean
        frame interval under 1 ms (``TriggerTime`` in seconds?), or times taken from
        ``FrameAcquisitionDateTime`` because no frame of a multi-frame file has a trigger
        delay. Also for an output above 2 GiB.

    Notes
    -----
    Geometry, interpolation and mask conventions are in the module docstrings
    (:mod:`harpx.io.dicom_headers`, :mod:`harpx.io.dicom`). Pixel positions follow DICOM
    PS3.3 C.7.6.2.1.1,

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
            stacklevel=user_stacklevel(),
        )
    volumes = dict(zip(by_series, _load_pixels(stacks), strict=True))
    resampled = {
        uid: resample_stack(stack.geometry, volumes[uid], x, y, z)
        for uid, stack in by_series.items()
    }
    image = np.stack([resampled[s.uid][0] for s in tag_stacks])
    mask = np.stack([resampled[s.uid][1] for s in tag_stacks])
    slice_axes = [AXES[int(np.argmax(np.abs(s.normal)))] for s in tag_stacks]
    thickness, positions = _slice_geometry(tag_stacks, slice_axes)
    known = np.isfinite(thickness).any() or any(p.size for p in positions)

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
        slice_thickness=thickness if known else None,
        slice_position=positions if known else None,
        attrs={
            "source": "DICOM",
            "dicom_series": "; ".join(
                f"{label}: {s.uid}" for label, s in zip(labels, tag_stacks, strict=True)
            ),
            "dicom_caveats": "; ".join(c for s in stacks for c in s.caveats),
        },
    )
