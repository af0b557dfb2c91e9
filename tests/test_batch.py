"""Tests of harpx.batch.track_many: a cohort on a dask cluster, resume, and failures."""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Iterator
from pathlib import Path

import distributed  # the test extra provides it; a missing one must fail, not skip
import numpy as np
import pytest
import xarray as xr

from harpx.batch import (
    CohortError,
    local_cluster,
    output_path,
    settings_fingerprint,
    track_many,
    track_subject,
)
from harpx.errors import HarpxError
from harpx.imaging.harp import extract_phase
from harpx.io.netcdf import open_dataset, to_netcdf
from harpx.mechanics.body import Body
from harpx.mechanics.loads import Fixed
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import cylinder
from harpx.physiology.cut import NodeFixed
from harpx.scenes._motion import RotationalImpact
from harpx.tracking.track import track
from tests._ideal import ideal_phase

RADIUS, HEIGHT = 12.0, 6.0
# SuperLU is single-threaded and deterministic, so worker and serial runs do the same
# floating-point operations (PARDISO's results depend on its thread count)
TRACK_KWARGS = {"epsilon": 0.05, "linear_solver": "superlu"}


def _inside(X: np.ndarray) -> np.ndarray:
    return ((np.hypot(X[:, 0], X[:, 1]) <= RADIUS) & (np.abs(X[:, 2]) <= HEIGHT / 2)).astype(float)


def body_factory(ds: xr.Dataset) -> Body:
    """The subjects' body: a coarse cylinder (so the test is fast), the same for everyone."""
    mesh = cylinder(
        RADIUS, HEIGHT, n_radial=1, n_circumferential=8, n_axial=1, center=(0.0, 0.0, -HEIGHT / 2)
    )
    return Body(mesh, NeoHookean(c1=1.0, kappa=120.0))


def _subject(angle_mm: float, *, shift: float = 0.0) -> xr.Dataset:
    """Ideal phase of a lagged rotation (edge turns ``angle_mm``), 3 frames, 4x20x20 voxels."""
    motion = RotationalImpact(
        radius=RADIUS, base=-HEIGHT / 2, height=HEIGHT, angle=angle_mm / RADIUS
    )
    ds = ideal_phase(
        motion, shape=(4, 20, 20), spacing=(2.0, 1.5, 1.5), times=np.arange(3) * 18.0, body=_inside
    )
    if shift:  # the image grid moved away: the mesh lies outside the field of view
        ds = ds.assign_coords(x=ds.x + shift)
        ds["x"].attrs.update({"units": "mm", "long_name": "x position of voxel centre"})
    return ds


@pytest.fixture(scope="module")
def cohort(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("cohort")
    return [to_netcdf(_subject(a), folder / f"s{k}.nc") for k, a in enumerate((2.0, 3.0, 4.0))]


@pytest.fixture(scope="module")
def client() -> Iterator[object]:
    with local_cluster(2) as cluster, distributed.Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def serial(cohort: list[Path]) -> list[xr.Dataset]:
    """Reference: a plain loop over track() in this process."""
    return [track(open_dataset(p), body_factory(None), **TRACK_KWARGS) for p in cohort]


def _mtimes(paths: list[Path]) -> list[int]:
    return [p.stat().st_mtime_ns for p in paths]


def test_cohort_on_a_local_cluster_matches_a_serial_loop(
    cohort: list[Path], serial: list[xr.Dataset], tmp_path: Path
) -> None:
    # the default path: a LocalCluster with 2 worker processes started and closed here
    outputs = track_many(
        cohort,
        body_factory,
        output_dir=tmp_path / "out",
        n_workers=2,
        track_kwargs=TRACK_KWARGS,
        progress=False,
    )
    assert outputs == [tmp_path / "out" / f"s{k}_tracked.nc" for k in range(3)]
    for path, source, expected in zip(outputs, cohort, serial, strict=True):
        actual = open_dataset(path)
        # same code, same single-threaded solver, same inputs: agreement to rounding
        xr.testing.assert_allclose(actual.displacement, expected.displacement, rtol=1e-10)
        assert actual.attrs["source_file"] == source.name
        assert len(actual.attrs["source_sha256"]) == 64
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [p.name for p in outputs]


def test_resume_redoes_only_missing_and_corrupt_subjects(
    cohort: list[Path], client: object, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    outputs = track_many(
        cohort,
        body_factory,
        output_dir=out,
        client=client,
        track_kwargs=TRACK_KWARGS,
        progress=False,
    )
    first = [open_dataset(p) for p in outputs]
    outputs[0].unlink()  # an interrupted cohort: one subject never written...
    data = outputs[1].read_bytes()
    outputs[1].write_bytes(data[: len(data) // 2])  # ...and one archive damaged afterwards
    untouched = _mtimes(outputs[2:])
    # through the scheduler address this time (an existing cluster)
    again = track_many(
        cohort,
        body_factory,
        output_dir=out,
        address=client.scheduler.address,  # type: ignore[attr-defined]
        track_kwargs=TRACK_KWARGS,
        progress=False,
    )
    assert again == outputs
    assert _mtimes(outputs[2:]) == untouched  # the finished subject was skipped
    for path, before in zip(outputs, first, strict=True):
        # recomputed subjects: same inputs, same deterministic solver: same result to rounding
        xr.testing.assert_allclose(open_dataset(path).displacement, before.displacement, rtol=1e-10)


def test_complete_cohort_needs_no_cluster(
    cohort: list[Path], client: object, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    outputs = track_many(
        cohort,
        body_factory,
        output_dir=tmp_path,
        client=client,
        track_kwargs=TRACK_KWARGS,
        progress=False,
    )
    stamps = _mtimes(outputs)

    def no_cluster(*args: object, **kwargs: object) -> None:
        raise AssertionError("a complete cohort must not start a cluster")

    monkeypatch.setattr(distributed, "LocalCluster", no_cluster)
    again = track_many(
        cohort, body_factory, output_dir=tmp_path, track_kwargs=TRACK_KWARGS, progress=False
    )
    assert again == outputs
    assert _mtimes(outputs) == stamps


def test_changed_input_or_overwrite_recomputes(
    cohort: list[Path], client: object, tmp_path: Path
) -> None:
    inputs = [tmp_path / p.name for p in cohort[:2]]
    for src, dst in zip(cohort, inputs, strict=False):
        dst.write_bytes(src.read_bytes())
    outputs = track_many(
        inputs,
        body_factory,
        output_dir=tmp_path / "out",
        client=client,
        track_kwargs=TRACK_KWARGS,
        progress=False,
    )
    stamps = _mtimes(outputs)
    to_netcdf(_subject(1.0), inputs[0])  # subject 0 re-exported with other images: stale
    track_many(
        inputs,
        body_factory,
        output_dir=tmp_path / "out",
        client=client,
        track_kwargs=TRACK_KWARGS,
        progress=False,
    )
    after = _mtimes(outputs)
    assert after[0] > stamps[0] and after[1] == stamps[1]
    track_many(
        inputs,
        body_factory,
        output_dir=tmp_path / "out",
        client=client,
        track_kwargs=TRACK_KWARGS,
        overwrite=True,
        progress=False,
    )
    assert all(a > b for a, b in zip(_mtimes(outputs), after, strict=True))
    # other tracking settings: every subject is stale, without overwrite=True
    after = _mtimes(outputs)
    changed = {**TRACK_KWARGS, "epsilon": 0.04}
    track_many(
        inputs,
        body_factory,
        output_dir=tmp_path / "out",
        client=client,
        track_kwargs=changed,
        progress=False,
    )
    assert all(a > b for a, b in zip(_mtimes(outputs), after, strict=True))
    ds = open_dataset(outputs[0])
    assert ds.attrs["settings_sha256"] == settings_fingerprint(body_factory, changed)[0]
    assert '"epsilon": 0.04' in ds.attrs["settings_fingerprint"]


def _other_body_factory(ds: xr.Dataset, c1: float = 1.0) -> Body:
    return Body(cylinder(RADIUS, HEIGHT, n_radial=1, n_axial=1), NeoHookean(c1=c1, kappa=120.0))


@pytest.mark.parametrize(
    ("a", "b"),
    [
        pytest.param((body_factory, {}), (_other_body_factory, {}), id="other-function"),
        pytest.param(
            (functools.partial(_other_body_factory, c1=1.0), {}),
            (functools.partial(_other_body_factory, c1=2.0), {}),
            id="partial-arguments",
        ),
        pytest.param(
            (body_factory, {"dirichlet": [Fixed("bottom")]}),
            (body_factory, {"dirichlet": [Fixed("bottom", (2,))]}),
            id="fixed-components",
        ),
        pytest.param(
            (body_factory, {"dirichlet": [NodeFixed(np.zeros((2000, 3)), (0,) * 2000)]}),
            (body_factory, {"dirichlet": [NodeFixed(np.eye(2000, 3), (0,) * 2000)]}),
            id="large-arrays",  # their repr would be elided and equal
        ),
    ],
)
def test_settings_fingerprint_changes_with_the_settings(a, b) -> None:
    assert settings_fingerprint(*a) == settings_fingerprint(*a)  # deterministic
    assert settings_fingerprint(*a)[0] != settings_fingerprint(*b)[0]


def test_failing_subjects_are_reported_after_the_others_are_written(
    cohort: list[Path], client: object, tmp_path: Path
) -> None:
    far = to_netcdf(_subject(2.0, shift=500.0), tmp_path / "far.nc")  # mesh outside the FOV
    missing = tmp_path / "missing.nc"
    inputs = [cohort[0], far, missing, cohort[1]]
    with pytest.raises(CohortError, match="2 of 4 subjects failed") as info:
        track_many(
            inputs,
            body_factory,
            output_dir=tmp_path / "out",
            client=client,
            track_kwargs=TRACK_KWARGS,
            progress=False,
        )
    err = info.value
    assert isinstance(err, HarpxError)
    message = str(err)
    assert "far.nc': SchemaError: mesh nodes" in message
    assert "missing.nc': ArchiveError: cannot read input" in message
    assert set(err.failures) == {far, missing}
    assert err.outputs == [output_path(p, tmp_path / "out") for p in inputs]
    # the good subjects are complete archives; the failed ones left nothing behind
    names = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert names == ["s0_tracked.nc", "s1_tracked.nc"]
    for path in (err.outputs[0], err.outputs[3]):
        assert open_dataset(path).attrs["harpx_schema"] == "tracked/1"


def _lambda_holder() -> object:
    import threading

    lock = threading.Lock()
    return lambda ds: lock  # closes over a lock: not picklable


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        pytest.param(
            {"client": object(), "address": "tcp://x:1"},
            ValueError,
            "either client= or address=",
            id="client-and-address",
        ),
        pytest.param({"n_workers": 0}, ValueError, "n_workers=0", id="n-workers"),
        pytest.param(
            {"track_kwargs": {"epsilon": 0.1, "espilon": 1}},
            TypeError,
            r"track_kwargs has \['espilon'\]",
            id="track-kwargs",
        ),
        pytest.param(
            {"body_factory": _lambda_holder()},
            TypeError,
            "cannot be pickled for the dask workers",
            id="unpicklable-factory",
        ),
        pytest.param(
            {"body_factory": 3}, TypeError, "body_factory must be callable", id="not-callable"
        ),
    ],
)
def test_bad_arguments_fail_before_any_work(
    cohort: list[Path], tmp_path: Path, kwargs: dict, error: type, match: str
) -> None:
    factory = kwargs.pop("body_factory", body_factory)
    with pytest.raises(error, match=match):
        track_many(cohort, factory, output_dir=tmp_path / "out", progress=False, **kwargs)
    assert not (tmp_path / "out").exists()


def test_duplicate_stems_are_refused(cohort: list[Path], tmp_path: Path) -> None:
    other = tmp_path / "elsewhere"
    other.mkdir()
    twin = other / cohort[0].name
    twin.write_bytes(cohort[0].read_bytes())
    with pytest.raises(ValueError, match="inputs share file stems.*'s0'"):
        track_many([cohort[0], twin], body_factory, output_dir=tmp_path / "out")


def test_track_subject_refuses_a_tracked_archive(
    cohort: list[Path], serial: list[xr.Dataset], tmp_path: Path
) -> None:
    tracked = to_netcdf(serial[0], tmp_path / "t.nc")
    with pytest.raises(HarpxError, match="has harpx_schema 'tracked/1'; track_many needs"):
        track_subject(tracked, tmp_path / "o.nc", body_factory)
    assert not (tmp_path / "o.nc").exists()


def _environment() -> dict[str, str | None]:
    keys = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "MALLOC_TRIM_THRESHOLD_")
    return {k: os.environ.get(k) for k in keys}


def test_local_cluster_workers_are_single_threaded_without_malloc_trim(client: object) -> None:
    info = client.scheduler_info()  # type: ignore[attr-defined]
    assert [w["nthreads"] for w in info["workers"].values()] == [1, 1]
    environments = client.run(_environment)  # type: ignore[attr-defined]
    expected = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MALLOC_TRIM_THRESHOLD_": None}
    assert list(environments.values()) == [expected, expected]
    with pytest.raises(ValueError, match="n_workers=0"):
        local_cluster(0)


def test_missing_distributed_gives_an_install_hint(
    cohort: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    with pytest.raises(ImportError, match=r"pip install harpx\[distributed\]"):
        track_many(cohort, body_factory, output_dir=tmp_path, progress=False)
    assert list(tmp_path.iterdir()) == []


def test_output_path() -> None:
    assert output_path(os.path.join("a", "b.c.nc"), "out") == Path("out") / "b.c_tracked.nc"


def test_phase_extraction_is_lazy_on_dask_inputs() -> None:
    from tests._helpers import raise_if_dask_computes
    from tests.test_schema import make_tagged

    eager_in = make_tagged(nt=3)
    # only the image is chunked (ds.chunk() would make the small coordinates dask arrays
    # too, and validate() loads coordinates by design)
    lazy_in = eager_in.assign(image=eager_in.image.chunk({"time": 1}))
    with raise_if_dask_computes():
        lazy = extract_phase(lazy_in)
    assert lazy.phase.chunks is not None  # still a dask array
    eager = extract_phase(eager_in)
    # same kernel on the same slices, blocked differently: floating-point identity
    xr.testing.assert_allclose(lazy.compute(), eager, rtol=1e-12)
