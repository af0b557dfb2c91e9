"""Tests of harpx.io.dicom: DICOM geometry, resampling onto one grid, clear errors.

Small synthetic series are written with pydicom: an axial short-axis stack and a doubly
oblique long-axis stack (rotated 30° about z, then 15° about x), three cine frames each. Pixel
values are a linear function of patient position (plus a per-frame offset), stored as uint16
with RescaleSlope/RescaleIntercept, so trilinear resampling is exact up to the uint16 rounding
of the stored values (at most slope/2).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

pydicom = pytest.importorskip("pydicom")

from pydicom.dataset import Dataset, FileDataset, FileMetaDataset  # noqa: E402
from pydicom.sequence import Sequence  # noqa: E402
from pydicom.uid import (  # noqa: E402
    EnhancedMRImageStorage,
    ExplicitVRLittleEndian,
    ImplicitVRLittleEndian,
    MRImageStorage,
    generate_uid,
)

from harpx.errors import HarpxError, HarpxWarning  # noqa: E402
from harpx.io.dicom import read_tagged, voxel_positions  # noqa: E402
from harpx.schema import validate  # noqa: E402

SLOPE = 0.02
INTERCEPT = -100.0
# Stored values are rint((f - INTERCEPT) / SLOPE): rescaled values are within SLOPE/2 of f, and
# linear interpolation (a convex combination) keeps that bound; 1e-9 absorbs float round-off.
ROUNDING_BOUND = 0.5 * SLOPE + 1e-9


def intensity(points: np.ndarray, frame: int) -> np.ndarray:
    """Analytic image: linear in patient position (mm), shifted per frame."""
    return 400.0 + 4.0 * points[..., 0] - 3.0 * points[..., 1] + 2.5 * points[..., 2] + 20 * frame


def rotation(axis: int, degrees: float) -> np.ndarray:
    a = np.deg2rad(degrees)
    c, s = np.cos(a), np.sin(a)
    i, j = [k for k in range(3) if k != axis]
    out = np.eye(3)
    out[i, i], out[i, j], out[j, i], out[j, j] = c, -s, s, c
    return out


def ds_str(value: float) -> str:
    """A DICOM decimal string (at most 16 characters)."""
    return f"{value:.10g}"


@dataclass(frozen=True)
class StackSpec:
    """Ground-truth geometry of a synthetic stack (columns of ``frame``: r, c, n)."""

    description: str
    frame: np.ndarray
    origin: np.ndarray
    pixel_spacing: tuple[float, float]  # (between rows, between columns) as DICOM orders it
    rows: int
    columns: int
    offsets: tuple[float, ...]
    thickness: float
    times: tuple[float, ...]
    uid: str = field(default="")

    def positions(self, k: int) -> np.ndarray:
        """Centres (rows, columns, 3) of slice k, from the construction (not the reader)."""
        i, j = np.meshgrid(np.arange(self.rows), np.arange(self.columns), indexing="ij")
        local = np.stack(
            [j * self.pixel_spacing[1], i * self.pixel_spacing[0], np.full(i.shape, 0.0)], -1
        )
        local[..., 2] = self.offsets[k]
        return self.origin + local @ self.frame.T

    def stored(self, k: int, t: int) -> np.ndarray:
        values = np.rint((intensity(self.positions(k), t) - INTERCEPT) / SLOPE)
        assert values.min() >= 0 and values.max() <= 65535, "test intensity out of uint16 range"
        return values.astype(np.uint16)


SA = StackSpec(
    description="SA tagged",
    frame=np.eye(3),
    origin=np.array([-5.0, -7.0, 0.0]),
    pixel_spacing=(1.25, 1.0),
    rows=12,
    columns=10,
    offsets=(0.0, 5.0, 10.0),
    thickness=5.0,
    times=(0.0, 40.0, 80.0),
    uid="1.2.826.0.1.3680043.8.498.1",
)
_BASE_LA = np.column_stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # r, c, n = r x c
LA = StackSpec(
    description="LA tagged",
    frame=rotation(0, 15.0) @ rotation(2, 30.0) @ _BASE_LA,
    origin=np.array([-6.0, -1.0, 11.0]),
    pixel_spacing=(1.5, 1.25),
    rows=9,
    columns=8,
    offsets=(0.0, 6.0),
    thickness=6.0,
    times=(0.3, 40.4, 79.6),
    uid="1.2.826.0.1.3680043.8.498.2",
)


def _file_dataset(path: Path, sop_class: str, syntax: str) -> FileDataset:
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = sop_class
    meta.MediaStorageSOPInstanceUID = generate_uid(entropy_srcs=[str(path)])
    meta.TransferSyntaxUID = syntax
    ds = FileDataset(str(path), {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID = sop_class
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.Modality = "MR"
    ds.StudyInstanceUID = "1.2.826.0.1.3680043.8.498.9"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit = 16, 16, 15
    ds.PixelRepresentation, ds.SamplesPerPixel = 0, 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    return ds


def _save(ds: FileDataset, path: Path) -> None:
    ds.save_as(path, enforce_file_format=True)


def edit_attribute(name: str, value: object, where=lambda k, t: True):
    """An ``edit`` for :func:`write_classic`: set DICOM attribute ``name`` to ``value`` (or
    delete it for None) in the files of slice ``k``, frame ``t`` where ``where(k, t)``."""

    def edit(ds, k: int, t: int) -> None:
        if where(k, t):
            if value is None:
                delattr(ds, name)
            else:
                setattr(ds, name, value)

    return edit


def write_classic(
    folder: Path,
    spec: StackSpec,
    *,
    syntax: str = ExplicitVRLittleEndian,
    sequence_name: str | None = None,
    edit=None,
) -> dict[Path, tuple[int, int]]:
    """One MR Image Storage file per (slice, frame); returns path -> (slice, frame)."""
    folder.mkdir(parents=True, exist_ok=True)
    n = len(spec.offsets) * len(spec.times)
    written = {}
    for index in range(n):
        k, t = divmod(index, len(spec.times))
        # Scramble file names so that file order is neither slice nor time order.
        path = folder / f"{spec.description.replace(' ', '_')}_{(7 * index + 3) % n:03d}.dcm"
        ds = _file_dataset(path, MRImageStorage, syntax)
        ds.SeriesInstanceUID = spec.uid
        ds.SeriesDescription = spec.description
        ds.SeriesNumber = 1 if spec is SA else 2
        ds.InstanceNumber = index + 1
        if sequence_name is not None:
            ds.SequenceName = sequence_name
        position = spec.positions(k)[0, 0]
        ds.ImagePositionPatient = [ds_str(v) for v in position]
        ds.ImageOrientationPatient = [ds_str(v) for v in (*spec.frame[:, 0], *spec.frame[:, 1])]
        ds.PixelSpacing = [ds_str(v) for v in spec.pixel_spacing]
        ds.SliceThickness = ds_str(spec.thickness)
        ds.TriggerTime = ds_str(spec.times[t])
        ds.RescaleSlope, ds.RescaleIntercept = ds_str(SLOPE), ds_str(INTERCEPT)
        ds.Rows, ds.Columns = spec.rows, spec.columns
        ds.PixelData = spec.stored(k, t).astype("<u2").tobytes()
        if edit is not None:
            edit(ds, k, t)
        _save(ds, path)
        written[path] = (k, t)
    return written


def write_enhanced(folder: Path, spec: StackSpec, *, timing: str = "trigger") -> Path:
    """One Enhanced MR Image Storage file holding every (slice, frame), time-major order.

    ``timing="trigger"`` writes NominalCardiacTriggerDelayTime; ``"datetime"`` writes only
    FrameAcquisitionDateTime (FrameContentSequence).
    """
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{spec.description.replace(' ', '_')}_enhanced.dcm"
    ds = _file_dataset(path, EnhancedMRImageStorage, ExplicitVRLittleEndian)
    ds.SeriesInstanceUID = spec.uid
    ds.SeriesDescription = spec.description
    ds.SeriesNumber = 3
    ds.Rows, ds.Columns = spec.rows, spec.columns
    order = [(k, t) for t in range(len(spec.times)) for k in range(len(spec.offsets))]
    ds.NumberOfFrames = len(order)

    def item(**values) -> Sequence:
        entry = Dataset()
        for key, value in values.items():
            setattr(entry, key, value)
        return Sequence([entry])

    shared = Dataset()
    shared.PixelMeasuresSequence = item(
        PixelSpacing=[ds_str(v) for v in spec.pixel_spacing], SliceThickness=ds_str(spec.thickness)
    )
    shared.PlaneOrientationSequence = item(
        ImageOrientationPatient=[ds_str(v) for v in (*spec.frame[:, 0], *spec.frame[:, 1])]
    )
    shared.PixelValueTransformationSequence = item(
        RescaleSlope=ds_str(SLOPE), RescaleIntercept=ds_str(INTERCEPT), RescaleType="US"
    )
    ds.SharedFunctionalGroupsSequence = Sequence([shared])
    frames = []
    for k, t in order:
        per = Dataset()
        per.PlanePositionSequence = item(
            ImagePositionPatient=[ds_str(v) for v in spec.positions(k)[0, 0]]
        )
        if timing == "trigger":
            per.CardiacSynchronizationSequence = item(
                NominalCardiacTriggerDelayTime=float(spec.times[t])
            )
            per.FrameContentSequence = item(TemporalPositionIndex=t + 1)
        else:
            when = datetime(2024, 6, 11, 12, 0, 5) + timedelta(milliseconds=spec.times[t])
            stamp = when.strftime("%Y%m%d%H%M%S.%f")
            per.FrameContentSequence = item(
                TemporalPositionIndex=t + 1, FrameAcquisitionDateTime=stamp
            )
        frames.append(per)
    ds.PerFrameFunctionalGroupsSequence = Sequence(frames)
    pixels = np.stack([spec.stored(k, t) for k, t in order])
    ds.PixelData = pixels.astype("<u2").tobytes()
    _save(ds, path)
    return path


TAGS = {
    "SA tagged": [("x", "row"), ("y", "column")],
    "LA tagged": ("l", "column"),
}
READ = {"tag_period": 8.0, "tag_directions": TAGS, "sequence": "CSPAMM"}


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("study")
    write_classic(folder / "sa", SA)
    write_classic(folder / "la", LA, syntax=ImplicitVRLittleEndian)
    (folder / "notes.txt").write_text("not a DICOM file; a folder scan skips it\n")
    return folder


@pytest.fixture(scope="module")
def tagged(study: Path) -> xr.Dataset:
    return read_tagged(study, **READ)


def grid_points(ds: xr.Dataset) -> np.ndarray:
    z, y, x = np.meshgrid(ds.z.values, ds.y.values, ds.x.values, indexing="ij")
    return np.stack([x, y, z], axis=-1)


def local_coords(spec: StackSpec, points: np.ndarray) -> np.ndarray:
    """(column index, row index, offset along n in mm) of points, from the construction."""
    local = (points - spec.origin) @ spec.frame  # frame is orthonormal
    return local / [spec.pixel_spacing[1], spec.pixel_spacing[0], 1.0]


# ---------------------------------------------------------------------------------------------
# geometry


def test_voxel_positions_of_oblique_series_match_construction(study: Path) -> None:
    files = sorted((study / "la").glob("*.dcm"))
    lookup = {}
    for k in range(len(LA.offsets)):
        lookup[tuple(np.round(LA.positions(k)[0, 0], 6))] = k
    worst = 0.0
    for path in files:
        image = pydicom.dcmread(path)
        k = lookup[tuple(np.round(np.asarray(image.ImagePositionPatient, float), 6))]
        actual = voxel_positions(image)
        assert actual.shape == (LA.rows, LA.columns, 3)
        worst = max(worst, float(np.abs(actual - LA.positions(k)).max()))
    # Exact geometry up to the 10-significant-digit decimal strings written (~1e-9 mm).
    assert worst < 1e-6, f"max position error {worst:.3g} mm"


def test_voxel_positions_follow_dicom_row_column_order(study: Path) -> None:
    # SA: rows advance along +y by PixelSpacing[0] = 1.25 mm, columns along +x by 1.0 mm.
    image = pydicom.dcmread(sorted((study / "sa").glob("*.dcm"))[0])
    origin = np.asarray(image.ImagePositionPatient, float)
    actual = voxel_positions(image)
    np.testing.assert_allclose(actual[2, 3], origin + [3 * 1.0, 2 * 1.25, 0.0], atol=1e-12)
    np.testing.assert_allclose(actual[11, 9], origin + [9.0, 13.75, 0.0], atol=1e-12)


def test_voxel_positions_of_multiframe_image(tmp_path: Path) -> None:
    image = pydicom.dcmread(write_enhanced(tmp_path, LA))
    actual = voxel_positions(image)
    assert actual.shape == (len(LA.offsets) * len(LA.times), LA.rows, LA.columns, 3)
    # Frames are written time-major: frame 1 is slice 1 at time 0.
    assert np.abs(actual[1] - LA.positions(1)).max() < 1e-6  # decimal-string precision


def test_voxel_positions_names_missing_attribute() -> None:
    image = Dataset()
    image.Rows, image.Columns = 2, 2
    image.ImagePositionPatient = [0, 0, 0]
    image.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
    with pytest.raises(HarpxError, match="'PixelSpacing' is missing"):
        voxel_positions(image)


# ---------------------------------------------------------------------------------------------
# read_tagged


def test_read_tagged_layout_and_schema(tagged: xr.Dataset) -> None:
    validate(tagged, "tagged")
    assert tagged.image.dims == ("tag", "time", "z", "y", "x")
    assert list(tagged.tag.values) == ["x", "y", "l"]
    assert list(tagged.slice_axis.values) == ["z", "z", "y"]
    assert tagged.attrs["sequence"] == "CSPAMM"
    np.testing.assert_allclose(tagged.tag_frequency, 1 / 8.0, rtol=1e-15)
    # Directions: SA row/column are x and y; LA "column" is its c vector (decimal strings).
    np.testing.assert_allclose(tagged.tag_direction.sel(tag="x"), [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(tagged.tag_direction.sel(tag="y"), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(tagged.tag_direction.sel(tag="l"), LA.frame[:, 1], atol=1e-9)
    # Default spacing: finest in-plane pixel spacing (SA columns, 1.0 mm), isotropic.
    for dim in "xyz":
        np.testing.assert_allclose(np.diff(tagged[dim]), 1.0, rtol=1e-12)
    assert tagged.mask.dtype == bool
    assert tagged.attrs["dicom_series"] == f"x: {SA.uid}; y: {SA.uid}; l: {LA.uid}"


def test_time_is_mean_trigger_time(tagged: xr.Dataset) -> None:
    expected = (np.array(SA.times) + np.array(LA.times)) / 2
    np.testing.assert_allclose(tagged.time, expected, rtol=1e-12)  # float identity
    assert tagged.time.attrs["units"] == "ms"


def test_masks_match_geometry(tagged: xr.Dataset) -> None:
    points = grid_points(tagged)
    # SA is axis aligned: its mask is a box (pixel-centre hull in plane, slab through plane).
    x, y, z = (points[..., a] for a in range(3))
    eps = 1e-6  # mm; grid points on the box faces count as inside
    box = (
        (x >= -5 - eps)
        & (x <= -5 + 9 * 1.0 + eps)
        & (y >= -7 - eps)
        & (y <= -7 + 11 * 1.25 + eps)
        & (z >= -2.5 - eps)
        & (z <= 12.5 + eps)
    )
    assert box.sum() > 100
    np.testing.assert_array_equal(tagged.mask.sel(tag="x"), box)
    np.testing.assert_array_equal(tagged.mask.sel(tag="y"), box)
    # LA is oblique: compare where points are clearly inside or outside (1e-3 from any face;
    # the written decimal strings move faces by ~1e-9 mm).
    j, i, o = np.moveaxis(local_coords(LA, points), -1, 0)
    margin = np.minimum.reduce(
        [j * 1.25, (LA.columns - 1 - j) * 1.25, i * 1.5, (LA.rows - 1 - i) * 1.5, o + 3.0, 9.0 - o]
    )
    mask = tagged.mask.sel(tag="l").values
    assert np.all(mask[margin > 1e-3]) and not np.any(mask[margin < -1e-3])
    assert (margin > 1e-3).sum() > 100


def test_resampled_image_equals_linear_function(tagged: xr.Dataset) -> None:
    points = grid_points(tagged)
    for spec, tag in ((SA, "x"), (SA, "y"), (LA, "l")):
        mask = tagged.mask.sel(tag=tag).values
        local = local_coords(spec, points[mask])
        # Beyond the outermost slice centres (inside the slab) the nearest slice is used.
        clamped = np.clip(local[:, 2], spec.offsets[0], spec.offsets[-1])
        where = points[mask] - (local[:, 2] - clamped)[:, None] * spec.frame[:, 2]
        for t in range(3):
            actual = tagged.image.sel(tag=tag).values[t][mask]
            error = np.abs(actual - intensity(where, t)).max()
            assert error <= ROUNDING_BOUND, f"tag {tag}, frame {t}: max error {error:.3g}"
        assert np.all(tagged.image.sel(tag=tag).values[:, ~mask] == 0)


def test_axis_aligned_stack_on_its_own_grid_is_not_interpolated(tmp_path: Path) -> None:
    spec = StackSpec(
        description="SA square",
        frame=np.eye(3),
        origin=np.array([1.0, 2.0, 3.0]),
        pixel_spacing=(1.5, 1.5),
        rows=5,
        columns=4,
        offsets=(0.0, 1.5, 3.0),
        thickness=1.5,
        times=(10.0, 50.0),
        uid="1.2.826.0.1.3680043.8.498.3",
    )
    write_classic(tmp_path, spec)
    ds = read_tagged(
        tmp_path, tag_period=6.0, tag_directions=[("SA square", "x", "row")], sequence="SPAMM"
    )
    assert ds.sizes == {"tag": 1, "time": 2, "z": 3, "y": 5, "x": 4, "axis": 3, "slice": 3}
    np.testing.assert_allclose(ds.x, 1 + 1.5 * np.arange(4), rtol=1e-15)
    # the slice geometry: SliceThickness and the slice centres, which here are the grid planes
    assert ds.slice_thickness.values.tolist() == [1.5]
    np.testing.assert_allclose(ds.slice_position.values[0], ds.z.values, rtol=1e-15)
    expected = np.stack(
        [np.stack([spec.stored(k, t) for k in range(3)]) * SLOPE + INTERCEPT for t in range(2)]
    )
    # Grid points fall on pixel centres: only float round-off in the index computation.
    np.testing.assert_allclose(ds.image.values[0], expected, rtol=1e-12)
    assert ds.mask.all()
    np.testing.assert_allclose(ds.time, [10.0, 50.0], rtol=1e-15)


def test_enhanced_multiframe_matches_classic(tmp_path: Path, tagged: xr.Dataset) -> None:
    write_classic(tmp_path / "sa", SA)
    write_enhanced(tmp_path / "la", LA)
    ds = read_tagged(tmp_path, **READ)
    xr.testing.assert_allclose(ds.image, tagged.image, rtol=1e-12)  # same samples, same maths
    xr.testing.assert_equal(ds.mask, tagged.mask)


def test_multiframe_timing_from_frame_acquisition_datetime(tmp_path: Path) -> None:
    write_enhanced(tmp_path, LA, timing="datetime")
    # Acquisition clock times are not trigger delays (a segmented acquisition spans many
    # beats): the fallback is warned about and recorded.
    with pytest.warns(HarpxWarning, match="FrameAcquisitionDateTime since the file's first"):
        ds = read_tagged(
            tmp_path, tag_period=8.0, tag_directions={"LA tagged": ("l", "row")}, sequence="SPAMM"
        )
    assert "frame times from FrameAcquisitionDateTime" in ds.attrs["dicom_caveats"]
    # Without trigger delays, time counts from the file's first acquired frame.
    np.testing.assert_allclose(ds.time, np.array(LA.times) - LA.times[0], atol=1e-6)


def test_explicit_spacing_and_tag_list(study: Path) -> None:
    one_file = next((study / "sa").glob("*.dcm"))  # also inside a folder given: read once
    ds = read_tagged(
        [study / "la", study / "sa", one_file],
        spacing=2.0,
        tag_period={"l": 10.0, "x": 8.0},
        tag_directions=[(LA.uid, "l", LA.frame[:, 0]), ("1", "x", (2.0, 0.0, 0.0))],
        sequence="SPAMM",
    )
    np.testing.assert_allclose(np.diff(ds.z), 2.0, rtol=1e-12)
    np.testing.assert_allclose(ds.tag_frequency, [0.1, 0.125], rtol=1e-15)
    np.testing.assert_allclose(ds.tag_direction.sel(tag="x"), [1, 0, 0], atol=0)
    assert list(ds.slice_axis.values) == ["y", "z"]


def test_sequence_read_from_header(tmp_path: Path) -> None:
    write_classic(tmp_path, SA, sequence_name="*tfl2d1_CSPAMM")
    ds = read_tagged(tmp_path, tag_period=8.0, tag_directions={"SA tagged": ("x", "row")})
    assert ds.attrs["sequence"] == "CSPAMM"


# ---------------------------------------------------------------------------------------------
# errors


def test_missing_pydicom_gives_install_hint(monkeypatch: pytest.MonkeyPatch, study: Path) -> None:
    monkeypatch.setitem(sys.modules, "pydicom", None)
    with pytest.raises(ImportError, match=r"pip install harpx\[dicom\]"):
        read_tagged(study, **READ)


def test_empty_folder_is_named(tmp_path: Path) -> None:
    (tmp_path / "readme.txt").write_text("nothing here")
    with pytest.raises(HarpxError, match=f"no DICOM images found in '{tmp_path}'"):
        read_tagged(tmp_path, **READ)


def test_unreadable_file_is_named(tmp_path: Path) -> None:
    junk = tmp_path / "junk.dcm"
    junk.write_bytes(b"definitely not DICOM" * 20)
    with pytest.raises(HarpxError, match=r"cannot read '.*junk\.dcm' as DICOM"):
        read_tagged([junk], **READ)


def test_truncated_file_is_named(tmp_path: Path) -> None:
    write_classic(tmp_path, SA)
    victim = sorted(tmp_path.glob("*.dcm"))[4]
    victim.write_bytes(victim.read_bytes()[:-100])
    with pytest.raises(HarpxError, match=rf"{victim.name}.*truncated"):
        read_tagged(
            tmp_path, tag_period=8.0, tag_directions={"SA tagged": ("x", "row")}, sequence="CSPAMM"
        )


def _drop(keyword: str):
    def edit(ds, k, t):
        if (k, t) == (1, 2):
            delattr(ds, keyword)

    return edit


@pytest.mark.parametrize(
    "keyword", ["ImagePositionPatient", "ImageOrientationPatient", "PixelSpacing", "TriggerTime"]
)
def test_missing_geometry_attribute_names_it_and_the_file(tmp_path: Path, keyword: str) -> None:
    written = write_classic(tmp_path, SA, edit=_drop(keyword))
    victim = next(p for p, kt in written.items() if kt == (1, 2))
    with pytest.raises(HarpxError, match=rf"'{keyword}' is missing in .*{victim.name}"):
        read_tagged(tmp_path, **{**READ, "tag_directions": {"SA tagged": ("x", "row")}})


def test_single_slice_without_thickness(tmp_path: Path) -> None:
    spec = StackSpec(**{**SA.__dict__, "offsets": (0.0,)})

    def edit(ds, k, t):
        del ds.SliceThickness

    write_classic(tmp_path, spec, edit=edit)
    with pytest.raises(HarpxError, match="'SliceThickness' is missing or not positive"):
        read_tagged(tmp_path, **{**READ, "tag_directions": {"SA tagged": ("x", "row")}})


def test_non_parallel_slices_in_a_series(tmp_path: Path) -> None:
    def edit(ds, k, t):
        if k == 2:
            ds.ImageOrientationPatient = [ds_str(v) for v in (1, 0, 0, 0, 0.8, 0.6)]

    write_classic(tmp_path, SA, edit=edit)
    with pytest.raises(HarpxError, match="slices of series 'SA tagged' .* are not parallel"):
        read_tagged(tmp_path, **{**READ, "tag_directions": {"SA tagged": ("x", "row")}})


def test_in_plane_shifted_slices(tmp_path: Path) -> None:
    def edit(ds, k, t):
        if k == 1:
            ds.ImagePositionPatient = [ds_str(v) for v in SA.positions(1)[0, 0] + [0.5, 0, 0]]

    write_classic(tmp_path, SA, edit=edit)
    match = r"shifted in plane by 0\.5 mm \(offset \[0\.5, 0\.0, 0\.0\] in x, y, z"
    with pytest.raises(HarpxError, match=match):
        read_tagged(tmp_path, **{**READ, "tag_directions": {"SA tagged": ("x", "row")}})


def test_inconsistent_frame_counts_across_series(tmp_path: Path) -> None:
    write_classic(tmp_path / "sa", SA)
    write_classic(tmp_path / "la", StackSpec(**{**LA.__dict__, "times": (0.0, 40.0)}))
    with pytest.raises(HarpxError, match=r"different numbers of frames .*'LA tagged'.*: 2"):
        read_tagged(tmp_path, **READ)


def test_inconsistent_frame_counts_across_slices(tmp_path: Path) -> None:
    written = write_classic(tmp_path, SA)
    next(p for p, kt in written.items() if kt == (2, 1)).unlink()
    with pytest.raises(HarpxError, match=r"different numbers of frames \[3, 3, 2\]"):
        read_tagged(tmp_path, **{**READ, "tag_directions": {"SA tagged": ("x", "row")}})


def test_trigger_times_across_slices_beyond_tolerance(tmp_path: Path) -> None:
    def edit(ds, k, t):
        if (k, t) == (2, 1):
            ds.TriggerTime = ds_str(42.0)

    write_classic(tmp_path, SA, edit=edit)
    match = r"slices of series 'SA tagged' .* differ by up to 2 ms at frame 1"
    with pytest.raises(HarpxError, match=match):
        read_tagged(tmp_path, **{**READ, "tag_directions": {"SA tagged": ("x", "row")}})


def test_duplicate_images_are_reported(tmp_path: Path) -> None:
    written = write_classic(tmp_path, SA)
    source = next(p for p, kt in written.items() if kt == (0, 0))
    (tmp_path / "copy.dcm").write_bytes(source.read_bytes())
    with pytest.raises(HarpxError, match=r"copy\.dcm .*are the same image twice|same image twice"):
        read_tagged(tmp_path, **{**READ, "tag_directions": {"SA tagged": ("x", "row")}})


def test_trigger_times_beyond_tolerance(tmp_path: Path) -> None:
    write_classic(tmp_path / "sa", SA)
    write_classic(tmp_path / "la", StackSpec(**{**LA.__dict__, "times": (0.0, 45.0, 80.0)}))
    match = r"'LA tagged' .* differs from series 'SA tagged' .* by up to 5 ms at frame 1"
    with pytest.raises(HarpxError, match=match):
        read_tagged(tmp_path, **READ)
    # The same data read with a looser tolerance.
    assert read_tagged(tmp_path, **READ, time_tolerance=6.0).sizes["time"] == 3


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        pytest.param({"tag_period": None}, "tag_period is required", id="no-period"),
        pytest.param({"tag_period": -2.0}, "tag_period for tag 'x' is -2.0", id="bad-period"),
        pytest.param({"sequence": None}, "sequence is required", id="no-sequence"),
        pytest.param({"sequence": "HARP"}, "sequence is 'HARP'", id="bad-sequence"),
        pytest.param(
            {"tag_directions": None},
            r"tag_directions is required(.|\n)*'LA tagged'",
            id="no-tags",
        ),
        pytest.param(
            {"tag_directions": {"4CH": ("x", "row")}},
            "names series '4CH', which matches no",
            id="unknown-series",
        ),
        pytest.param(
            {"tag_directions": {"SA tagged": ("x", "diagonal")}},
            "direction 'diagonal'",
            id="unknown-direction",
        ),
        pytest.param(
            {"tag_directions": {"SA tagged": ("x", (0, 0, 1))}},
            "mostly through the slices",
            id="through-plane",
        ),
        pytest.param(
            {"tag_directions": [("SA tagged", "x", "row"), ("LA tagged", "x", "row")]},
            "unique tag labels",
            id="duplicate-label",
        ),
        pytest.param({"spacing": 0.0}, "spacing is 0.0", id="bad-spacing"),
    ],
)
def test_bad_arguments(study: Path, changes: dict, match: str) -> None:
    with pytest.raises(HarpxError, match=match):
        read_tagged(study, **{**READ, **changes})


# ---------------------------------------------------------------------------------------------
# slice geometry


def test_slice_geometry_from_the_headers(tagged: xr.Dataset) -> None:
    # the axis-aligned SA stack: SliceThickness and the slice centres along z (origin z = 0,
    # offsets 0, 5, 10); both tags of the series share them
    np.testing.assert_array_equal(tagged.slice_thickness.sel(tag=["x", "y"]), [5.0, 5.0])
    for tag in ("x", "y"):
        np.testing.assert_allclose(tagged.slice_position.sel(tag=tag), SA.offsets, atol=1e-12)
    # the doubly oblique LA stack's slices are no planes of the grid: nothing is guessed
    assert np.isnan(tagged.slice_thickness.sel(tag="l"))
    assert np.isnan(tagged.slice_position.sel(tag="l")).all()
    # the phase carries them to the tracker's blur correction, which models the slice
    # profile of the SA tags only (the SA slab is 5 mm on a 1 mm grid)
    from harpx.imaging.harp import extract_phase
    from harpx.tracking.blur import blur_models

    phase = extract_phase(tagged, upsample=1)
    np.testing.assert_array_equal(phase.slice_position, tagged.slice_position)
    assert blur_models(phase) == ["slice-profile", "slice-profile", "in-plane"]


def test_slice_geometry_of_a_stack_whose_normal_points_down(tmp_path: Path) -> None:
    # r x c = -z: the offsets grow downwards from z = 20, so the centres are 10, 15, 20
    frame = np.column_stack([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    spec = StackSpec(**{**SA.__dict__, "frame": frame, "origin": np.array([-5.0, 7.0, 20.0])})
    write_classic(tmp_path, spec)
    ds = read_tagged(tmp_path, **{**READ, "tag_directions": {"SA tagged": ("x", "row")}})
    np.testing.assert_allclose(ds.slice_position.values, [[10.0, 15.0, 20.0]], atol=1e-12)
    # the slab is 7.5 .. 22.5 mm and the grid samples it
    assert ds.z.values.min() >= 7.5 and ds.z.values.max() <= 22.5


def test_slice_positions_without_slice_thickness(tmp_path: Path) -> None:
    def edit(ds, k, t):
        del ds.SliceThickness

    write_classic(tmp_path, SA, edit=edit)
    ds = read_tagged(tmp_path, **{**READ, "tag_directions": {"SA tagged": ("x", "row")}})
    validate(ds, "tagged")
    # the centres are known, the thickness is not (the slab then reaches half a slice gap)
    assert np.isnan(ds.slice_thickness.values).all()
    np.testing.assert_allclose(ds.slice_position.values, [SA.offsets], atol=1e-12)


def test_only_oblique_series_give_no_slice_geometry(tmp_path: Path) -> None:
    write_classic(tmp_path, LA)
    ds = read_tagged(tmp_path, **{**READ, "tag_directions": {"LA tagged": ("l", "column")}})
    assert "slice_thickness" not in ds.variables and "slice_position" not in ds.variables
