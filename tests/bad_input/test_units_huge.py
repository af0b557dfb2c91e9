"""Input in the wrong units or absurdly large is refused before any large allocation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import skfem
import xarray as xr

from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box
from harpx.tracking.image_fit import check_fits_image

MAT = NeoHookean(c1=1.0, kappa=120.0)
# a 48 x 48 x 16 mm field of view of 2 mm voxels centred on 0, like an 8 x 24 x 24 grid
GRID = xr.Dataset(
    coords={
        "z": -7.0 + 2.0 * np.arange(8),
        "y": -23.0 + 2.0 * np.arange(24),
        "x": -23.0 + 2.0 * np.arange(24),
    }
)


def _body(scale: float = 1.0, divisions: tuple[int, int, int] = (3, 3, 2)) -> Body:
    lengths = (6.0 * scale, 6.0 * scale, 4.0 * scale)
    origin = (-3.0 * scale, -3.0 * scale, -2.0 * scale)
    return Body(box(lengths, divisions, origin=origin), MAT)


def test_a_mesh_in_mm_inside_the_image_passes() -> None:
    check_fits_image(_body(), GRID)


def test_micrometre_mesh_is_named_before_allocation() -> None:
    # before: 147 s and "Unable to allocate 141 GiB"
    with pytest.raises(ValueError, match=r"125 times larger than the image.*micrometres"):
        check_fits_image(_body(1000.0), GRID)


def test_metre_mesh_is_named() -> None:
    with pytest.raises(ValueError, match=r"spans 0.006 mm but one acquired voxel is 2 mm.*metres"):
        check_fits_image(_body(1e-3), GRID)


def test_one_node_far_outside_the_field_of_view_is_named() -> None:
    m = _body().mesh
    p = m.p.copy()
    corner = int(np.argmax(p.sum(axis=0)))  # the (+x, +y, +z) corner: moving it out keeps J > 0
    p[:, corner] += 1e5
    with pytest.raises(
        ValueError,
        match=rf"mesh nodes \[{corner}\] lie up to 9.999e\+04 mm outside.*move or fix those nodes",
    ):
        check_fits_image(Body(skfem.MeshHex1(p, m.t), MAT), GRID)


def test_the_acquired_voxel_sets_the_point_budget() -> None:
    # one 40 mm cell: ceil(40 / 2) x ceil(40 / 2) x ceil(12 / 2) = 2400 points at 2 mm, and
    # 10 x 10 x 3 = 300 when the images were upsampled twice (4 mm acquired voxels)
    coarse = Body(box((40.0, 40.0, 12.0), (1, 1, 1), origin=(-20.0, -20.0, -6.0)), MAT)
    with pytest.raises(ValueError, match=r"place 2.4e\+03 constraint points.*max_points=2e\+03"):
        check_fits_image(coarse, GRID, max_points=2000)
    check_fits_image(coarse, GRID.assign_attrs(upsample=2), max_points=2000)


def test_tetrahedral_point_budget_names_points_per_edge() -> None:
    # the 40 mm box split into 6 tetrahedra: longest edge sqrt(40² + 40² + 12²) = 57.83 mm,
    # ceil(57.8 / 3) = 20 points per edge, 20³ per cell, 6 cells: 4.8e4 points
    from harpx.mechanics.mesh import tetrahedralize

    spec = tetrahedralize(box((40.0, 40.0, 12.0), (1, 1, 1), origin=(-20.0, -20.0, -6.0)))
    with pytest.raises(ValueError, match=r"4.8e\+04 constraint points") as info:
        check_fits_image(Body(spec, MAT), GRID, max_points=2000)
    message = str(info.value)
    assert "longest tetrahedron edge is 57.83 mm, 20 points per edge" in message
    assert "voxels" not in message.split("):")[1].replace("1.5 voxels", "")


def test_cohort_completeness_check_decides_from_attributes_first(tmp_path) -> None:
    # an archive declaring 2e9 float64 (15 GiB) of another input is judged stale at once
    import netCDF4

    from harpx.batch import _is_complete

    path = tmp_path / "s0_tracked.nc"
    with netCDF4.Dataset(path, "w") as nc:
        nc.createDimension("n", 2_000_000_000)
        nc.createVariable("a", "f8", ("n",), zlib=True, chunksizes=(1 << 20,))
        nc.harpx_schema = "tracked/1"
        nc.source_sha256 = "other"
    # digest differs: decided from attributes, before the factory is called
    assert _is_complete(path, "abc", "settings", path, _no_factory) is False


def _no_factory(ds: object) -> None:
    raise AssertionError("the body factory was called although the attributes decide")


def _cohort_body(ds: object) -> Body:
    """The body of the archives below, as a cohort's factory builds it."""
    return Body(box((4.0, 4.0, 4.0), (1, 1, 1)), MAT)


def _source() -> Path:
    import harpx.datasets

    return harpx.datasets.path("phantom-small", "tagged")


def _complete_archive_declaring(path, values: int) -> None:
    """A valid tracked/1 archive of this input and settings, plus ``values`` float64."""
    import shutil

    import netCDF4

    import harpx.datasets
    from harpx.batch import _body_digest

    shutil.copy(harpx.datasets.path("phantom-small", "tracked"), path)
    with netCDF4.Dataset(path, "a") as nc:
        nc.createDimension("extra_n", values)
        var = nc.createVariable(
            "extra", "f8", ("extra_n",), zlib=True, chunksizes=(min(values, 1 << 20),)
        )
        var.units, var.long_name = "1", "unwritten filler"
        nc.source_sha256, nc.settings_sha256 = "abc", "settings"
        nc.body_sha256 = _body_digest(_cohort_body(None))


def test_cohort_completeness_check_streams_a_large_complete_archive(tmp_path) -> None:
    # matching digest and settings: the check must read every block, one chunk at a time
    import tracemalloc

    from harpx.batch import _is_complete

    path = tmp_path / "s0_tracked.nc"
    _complete_archive_declaring(path, 1 << 25)  # 256 MiB of float64 in 8 MiB chunks
    assert _is_complete(path, "abc", "other", _source(), _cohort_body) is False  # warm-up
    tracemalloc.start()
    try:
        assert _is_complete(path, "abc", "settings", _source(), _cohort_body) is True
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20, f"the check held {peak / 2**20:.0f} MiB of a 256 MiB archive"


def test_running_out_of_memory_in_the_check_is_not_an_incomplete_archive(
    tmp_path, monkeypatch
) -> None:
    # before: `except Exception` took the MemoryError for a bad archive and redid the subject
    import harpx.batch

    path = tmp_path / "s0_tracked.nc"
    _complete_archive_declaring(path, 8)

    def no_memory(*args: object, **kwargs: object) -> None:
        raise MemoryError

    monkeypatch.setattr(harpx.batch, "validate", no_memory)
    with pytest.raises(MemoryError, match=r"checking the existing archive '.*s0_tracked\.nc'"):
        harpx.batch._is_complete(path, "abc", "settings", _source(), _cohort_body)
    assert path.stat().st_size > 0  # left as it was


class _Future:
    def __init__(self, error: BaseException | None) -> None:
        self.error = error

    def result(self) -> None:
        if self.error is not None:
            raise self.error

    def done(self) -> bool:
        return False


class _Client:
    """Stands in for a user's dask client: hands out futures, records cancellations."""

    def __init__(self, errors: list[BaseException | None]) -> None:
        self.futures = [_Future(e) for e in errors]
        self._queue = iter(self.futures)
        self.cancelled: list[_Future] = []

    def submit(self, *args: object, **kwargs: object) -> _Future:
        return next(self._queue)

    def cancel(self, futures: list[_Future]) -> None:
        self.cancelled.extend(futures)


def _run_with(client: _Client, monkeypatch, stop_after: int | None = None):
    import harpx.batch

    def as_completed(futures):
        for k, future in enumerate(futures):
            if stop_after is not None and k == stop_after:
                raise KeyboardInterrupt
            yield future

    monkeypatch.setattr(harpx.batch, "_distributed", lambda *names: (None, as_completed))
    inputs = [Path(f"s{k}.nc") for k in range(len(client.futures))]
    failures: dict[int, BaseException] = {}

    class Bar:
        def update(self, n: int) -> None:
            pass

    harpx.batch._run(
        [(k, "digest") for k in range(len(inputs))],
        inputs,
        [Path(f"out/s{k}_tracked.nc") for k in range(len(inputs))],
        len,
        {},
        client,
        None,
        1,
        failures,
        Bar(),
        ("sha", "text"),
    )
    return inputs, failures


def test_a_subject_out_of_memory_is_told_apart_from_bad_input(monkeypatch) -> None:
    from harpx.batch import _cohort_error

    client = _Client([None, MemoryError("Unable to allocate 12 GiB"), ValueError("bad mesh")])
    inputs, failures = _run_with(client, monkeypatch)
    assert sorted(failures) == [1, 2]
    message = str(_cohort_error(inputs, [Path("o")] * 3, failures, Path("out")))
    assert "'s1.nc': MemoryError: Unable to allocate 12 GiB" in message
    assert "1 of them ran out of memory" in message and "fewer workers (n_workers=)" in message
    assert "fix the other subjects first" in message


def test_keyboard_interrupt_stops_the_cohort_and_cancels_the_queued_subjects(
    monkeypatch,
) -> None:
    client = _Client([None, None, None])
    with pytest.raises(KeyboardInterrupt):
        _run_with(client, monkeypatch, stop_after=1)
    assert client.cancelled == client.futures  # none reported done: all cancelled
