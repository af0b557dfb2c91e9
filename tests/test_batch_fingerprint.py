"""track_many's resume check compares the body the factory builds, not only its source."""

from __future__ import annotations

import sys
from pathlib import Path

import distributed  # the test extra provides it; a missing one must fail, not skip
import pytest

from harpx.batch import output_path, settings_fingerprint, track_many, track_subject
from harpx.io.netcdf import open_dataset, to_netcdf
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import cylinder
from tests.test_batch import HEIGHT, RADIUS, TRACK_KWARGS, _subject

#: The module constant a user edits between two runs of a cohort.
STIFFNESS = 1.0


def constant_body(ds: object) -> Body:
    """A factory whose source never changes but whose body does: it reads STIFFNESS."""
    mesh = cylinder(
        RADIUS, HEIGHT, n_radial=1, n_circumferential=8, n_axial=1, center=(0.0, 0.0, -HEIGHT / 2)
    )
    return Body(mesh, NeoHookean(c1=STIFFNESS, kappa=120.0 * STIFFNESS))


class _ClusterStarted(Exception):
    """Raised instead of starting a cluster: track_many decided to redo a subject."""


def _no_cluster(*args: object, **kwargs: object) -> None:
    raise _ClusterStarted


@pytest.fixture(scope="module")
def tracked(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """One subject tracked with STIFFNESS = 1 (input, archive)."""
    folder = tmp_path_factory.mktemp("subject")
    source = to_netcdf(_subject(2.0), folder / "s0.nc")
    (folder / "out").mkdir()
    target = track_subject(source, output_path(source, folder / "out"), constant_body, TRACK_KWARGS)
    return source, target


def test_archive_records_the_body(tracked: tuple[Path, Path]) -> None:
    body_sha = open_dataset(tracked[1]).attrs["body_sha256"]
    assert len(body_sha) == 64 and int(body_sha, 16) >= 0


def test_unchanged_body_is_skipped(
    tracked: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    source, target = tracked
    stamp = target.stat().st_mtime_ns
    monkeypatch.setattr(distributed, "LocalCluster", _no_cluster)
    outputs = track_many(
        [source], constant_body, output_dir=target.parent, track_kwargs=TRACK_KWARGS,
        progress=False,
    )  # fmt: skip
    assert outputs == [target] and target.stat().st_mtime_ns == stamp


def test_body_changed_by_a_module_constant_is_redone(
    tracked: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    source, target = tracked
    before = settings_fingerprint(constant_body, TRACK_KWARGS)
    monkeypatch.setattr(sys.modules[__name__], "STIFFNESS", 5.0)
    # the factory's source and defaults are the same: the settings fingerprint cannot see it
    assert settings_fingerprint(constant_body, TRACK_KWARGS) == before
    monkeypatch.setattr(distributed, "LocalCluster", _no_cluster)
    with pytest.raises(_ClusterStarted):
        track_many(
            [source], constant_body, output_dir=target.parent, track_kwargs=TRACK_KWARGS,
            progress=False,
        )  # fmt: skip


def test_archive_without_a_body_record_is_redone(
    tracked: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    source, target = tracked
    old = open_dataset(target)
    del old.attrs["body_sha256"]  # as written before the body was recorded
    to_netcdf(old, output_path(source, tmp_path))
    monkeypatch.setattr(distributed, "LocalCluster", _no_cluster)
    with pytest.raises(_ClusterStarted):
        track_many(
            [source], constant_body, output_dir=tmp_path, track_kwargs=TRACK_KWARGS,
            progress=False,
        )  # fmt: skip
