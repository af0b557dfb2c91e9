"""Nothing is lost, nothing is exposed: writes never replace what they must not, stray
temporary files of killed writes are cleaned, the dashboard stays on loopback."""

from __future__ import annotations

import os
import re
import shutil
import socket
import stat
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from harpx.errors import ArchiveError
from harpx.io.mesh import to_meshio
from harpx.io.netcdf import open_dataset, to_netcdf
from tests.test_schema import make_tagged, make_tracked


def test_symlink_target_is_refused_and_kept(tmp_path: Path) -> None:
    real = to_netcdf(make_tagged(), tmp_path / "real.nc")
    before = real.read_bytes()
    link = tmp_path / "link.nc"
    link.symlink_to(real)
    with pytest.raises(ArchiveError, match=r"'.*link\.nc': it is a symbolic link"):
        to_netcdf(make_tracked(), link)
    assert link.is_symlink() and real.read_bytes() == before


def test_read_only_target_is_refused_and_kept(tmp_path: Path) -> None:
    target = to_netcdf(make_tagged(), tmp_path / "a.nc")
    before = target.read_bytes()
    target.chmod(0o444)
    with pytest.raises(ArchiveError, match=r"refusing to overwrite .*: the file is read-only"):
        to_netcdf(make_tracked(), target)
    assert target.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["a.nc"]


def test_fifo_target_is_refused(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.nc"
    os.mkfifo(fifo)
    with pytest.raises(ArchiveError, match=r"'.*pipe\.nc': it is not a regular file \(mode p"):
        to_netcdf(make_tagged(), fifo)
    assert stat.S_ISFIFO(fifo.stat().st_mode)


def test_device_node_target_is_refused(tmp_path: Path) -> None:
    device = tmp_path / "null.nc"
    try:
        os.mknod(device, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("creating a device node needs privileges")
    with pytest.raises(ArchiveError, match=r"it is not a regular file \(mode c"):
        to_netcdf(make_tagged(), device)
    assert stat.S_ISCHR(device.stat().st_mode)


def test_directory_target_is_refused(tmp_path: Path) -> None:
    (tmp_path / "a.nc").mkdir()
    with pytest.raises(ArchiveError, match=r"it is a directory"):
        to_netcdf(make_tagged(), tmp_path / "a.nc")


def test_export_never_replaces_a_symlinked_frame(tmp_path: Path) -> None:
    keep = tmp_path / "keep.txt"
    keep.write_text("precious")
    (tmp_path / "r_0000.vtu").symlink_to(keep)
    with pytest.raises(ArchiveError, match=r"r_0000\.vtu': it is a symbolic link"):
        to_meshio(make_tracked(), tmp_path / "r.pvd", series="vtu")
    assert keep.read_text() == "precious"
    assert sorted(os.listdir(tmp_path)) == ["keep.txt", "r_0000.vtu"]  # staging removed


def test_unwritable_directory_is_an_archive_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # as root a 0o555 directory is still writable, so the refusal of the OS is simulated
    def refuse(*args: object, **kwargs: object) -> None:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr("harpx.io.netcdf.tempfile.mkstemp", refuse)
    with pytest.raises(ArchiveError, match=r"cannot create a file in .*Permission denied"):
        to_netcdf(make_tagged(), tmp_path / "a.nc")


def test_full_disk_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def hdf_error(self: xr.Dataset, *args: object, **kwargs: object) -> None:
        raise RuntimeError("NetCDF: HDF error")

    class Usage:
        free = 4096

    monkeypatch.setattr(xr.Dataset, "to_netcdf", hdf_error)
    monkeypatch.setattr("harpx.io.netcdf.shutil.disk_usage", lambda path: Usage)
    with pytest.raises(ArchiveError, match=r"HDF error\); the disk holding .* is full .*0.0 MiB"):
        to_netcdf(make_tagged(), tmp_path / "a.nc")
    assert os.listdir(tmp_path) == []


def _dead_pid() -> int:
    pid = 2**22 - 7  # above the default pid_max: no such process
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)
    return pid


def test_stray_temporaries_of_killed_writes_are_removed_others_kept(tmp_path: Path) -> None:
    host = socket.gethostname()
    dead = tmp_path / f".a.nc.harpx-{host}-{_dead_pid()}-x1y2.tmp"
    alive = tmp_path / f".a.nc.harpx-{host}-{os.getppid()}-x3y4.tmp"  # a running writer
    foreign = tmp_path / ".a.nc.other.tmp"  # not made by harpx
    other_host = tmp_path / f".a.nc.harpx-elsewhere-{_dead_pid()}-x5.tmp"
    for p in (dead, alive, foreign, other_host):
        p.write_bytes(b"partial")
    to_netcdf(make_tagged(), tmp_path / "a.nc")
    assert sorted(os.listdir(tmp_path)) == sorted(
        ["a.nc", alive.name, foreign.name, other_host.name]
    )


def test_stray_staging_directory_of_a_killed_export_is_removed(tmp_path: Path) -> None:
    stale = tmp_path / f".r.pvd.harpx-{socket.gethostname()}-{_dead_pid()}-q.tmp"
    stale.mkdir()
    (stale / "r_0000.vtu").write_bytes(b"partial")
    to_meshio(make_tracked(), tmp_path / "r.pvd", series="vtu")
    assert not stale.exists()


def test_eager_load_of_a_huge_declared_archive_is_refused_before_allocation(
    tmp_path: Path,
) -> None:
    # 2e9 float64 declared, one value written: a few kB on disk, 15 GiB in memory
    import netCDF4

    path = tmp_path / "bomb.nc"
    with netCDF4.Dataset(path, "w") as nc:
        nc.createDimension("n", 2_000_000_000)
        var = nc.createVariable("a", "f8", ("n",), zlib=True, chunksizes=(1 << 20,))
        var[0] = 1.0
    assert path.stat().st_size < 100_000
    with pytest.raises(ArchiveError, match=r"declares 14.9 GiB \(largest variable 'a'.*chunks="):
        open_dataset(path, max_bytes=1 << 30)
    lazy = open_dataset(path, chunks={})  # lazily it opens, and one value can be read
    assert float(lazy.a[0]) == 1.0
    lazy.close()


def test_local_cluster_listens_on_loopback_only(monkeypatch: pytest.MonkeyPatch) -> None:
    distributed = pytest.importorskip("distributed")
    from harpx.batch import local_cluster

    seen: dict[str, object] = {}
    monkeypatch.setattr(distributed, "LocalCluster", lambda **kwargs: seen.update(kwargs))
    local_cluster(1)  # the arguments it starts the cluster with, without starting one
    assert seen["host"] == "127.0.0.1"
    assert seen["dashboard_address"] == "127.0.0.1:0"  # was ":0": every interface


# --- DICOM export: never mixed with an older export, never half written --------------------


def _dicom_roundtrip(folder: Path, ds: xr.Dataset) -> xr.Dataset:
    from harpx.io.dicom import read_tagged

    directions = {f"tagged {t}": [(t, tuple(np.eye(3)[i]))] for i, t in enumerate("xyz")}
    return read_tagged(folder, tag_period=8.0, tag_directions=directions)


def _two_exports(rng: np.random.Generator) -> tuple[xr.Dataset, xr.Dataset]:
    from tests.io.test_dicom_write import _tagged

    three = _tagged(rng)
    three = three.isel(time=[0, 1, 1]).assign_coords(time=("time", [0.0, 30.0, 60.0]))
    three["time"].attrs.update(_tagged(rng)["time"].attrs)
    return three, _tagged(rng)  # 3 frames, then 2


def test_dicom_export_into_an_earlier_export_is_refused(tmp_path: Path, rng) -> None:
    pytest.importorskip("pydicom")
    from harpx.io.dicom_write import write_tagged

    old, new = _two_exports(rng)
    write_tagged(old, tmp_path / "dicom")
    before = sorted(p.relative_to(tmp_path) for p in (tmp_path / "dicom").rglob("*"))
    # before: the 2-frame export joined the 3-frame one's series (3 frames read back)
    with pytest.raises(FileExistsError, match=r"'.*dicom' is not empty .*overwrite=True"):
        write_tagged(new, tmp_path / "dicom")
    assert sorted(p.relative_to(tmp_path) for p in (tmp_path / "dicom").rglob("*")) == before
    assert sorted(os.listdir(tmp_path)) == ["dicom"]  # no staging left
    assert _dicom_roundtrip(tmp_path / "dicom", old).sizes["time"] == 3


def test_dicom_overwrite_replaces_the_earlier_export_with_fresh_uids(tmp_path: Path, rng) -> None:
    pydicom = pytest.importorskip("pydicom")
    from harpx.io.dicom_write import write_tagged

    old, new = _two_exports(rng)
    write_tagged(old, tmp_path / "dicom")
    uid = pydicom.dcmread(next((tmp_path / "dicom" / "x").iterdir())).SeriesInstanceUID
    write_tagged(new, tmp_path / "dicom", overwrite=True)
    back = _dicom_roundtrip(tmp_path / "dicom", new)
    assert back.sizes["time"] == 2  # only the new frames
    assert uid not in back.attrs["dicom_series"]  # each export is its own series
    assert sorted(os.listdir(tmp_path)) == ["dicom"]


def test_dicom_overwrite_never_deletes_other_files(tmp_path: Path, rng) -> None:
    pytest.importorskip("pydicom")
    from harpx.io.dicom_write import write_tagged

    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "notes.txt").write_text("precious")
    with pytest.raises(FileExistsError, match=r"'notes.txt' there is not a folder of \.dcm"):
        write_tagged(_two_exports(rng)[1], folder, overwrite=True)
    assert os.listdir(folder) == ["notes.txt"] and sorted(os.listdir(tmp_path)) == ["study"]
    (tmp_path / "file").write_text("x")
    with pytest.raises(FileExistsError, match=r"'.*file' is a file, not a folder"):
        write_tagged(_two_exports(rng)[1], tmp_path / "file")
    (tmp_path / "link").symlink_to(folder)
    with pytest.raises(FileExistsError, match=r"'.*link' is a symbolic link; pass the folder"):
        write_tagged(_two_exports(rng)[1], tmp_path / "link", overwrite=True)
    assert os.listdir(folder) == ["notes.txt"]


def test_interrupted_dicom_export_leaves_nothing_and_keeps_the_old(
    tmp_path: Path, rng, monkeypatch: pytest.MonkeyPatch
) -> None:
    pydicom = pytest.importorskip("pydicom")
    from harpx.io.dicom_write import write_tagged

    old, new = _two_exports(rng)
    write_tagged(old, tmp_path / "dicom")
    calls = {"n": 0}
    save = pydicom.dataset.FileDataset.save_as

    def save_then_fail(self: object, *args: object, **kwargs: object) -> None:
        calls["n"] += 1
        if calls["n"] == 5:
            raise KeyboardInterrupt  # e.g. the user stops the kernel mid-export
        save(self, *args, **kwargs)

    monkeypatch.setattr(pydicom.dataset.FileDataset, "save_as", save_then_fail)
    with pytest.raises(KeyboardInterrupt):
        write_tagged(new, tmp_path / "dicom", overwrite=True)
    calls["n"] = 0
    with pytest.raises(KeyboardInterrupt):
        write_tagged(new, tmp_path / "fresh")
    assert sorted(os.listdir(tmp_path)) == ["dicom"]  # no staging, no half export
    assert _dicom_roundtrip(tmp_path / "dicom", old).sizes["time"] == 3  # the old, intact


def test_dicom_export_refuses_unsafe_labels_and_nan_images(tmp_path: Path, rng) -> None:
    pytest.importorskip("pydicom")
    from harpx.errors import SchemaError
    from harpx.io.dicom_write import write_tagged

    ds = _two_exports(rng)[1]
    bad = ds.assign_coords(tag=("tag", ["x", "..", "z"], ds.tag.attrs))
    with pytest.raises(SchemaError, match=r"tag labels \['\.\.'\] cannot name the series") as err:
        write_tagged(bad, tmp_path / "a")
    # the advice, followed as written, gives labels that export (a plain list of labels
    # dropped the coordinate's attributes, and validation refused the result)
    advice = re.search(r"e\.g\. (ds\.assign_coords\(.*?\]\)\)?)(?:, which|\))", str(err.value))[1]
    fixed = eval(advice, {"ds": bad})  # noqa: S307 (the message's own example)
    write_tagged(fixed, tmp_path / "a")
    shutil.rmtree(tmp_path / "a")
    lazy = ds.copy(deep=True)
    lazy["image"][0, 1, 2, 3, 4] = np.nan
    with pytest.raises(SchemaError, match=r"'image' of tag 'x' has 1 non-finite values"):
        write_tagged(lazy.chunk({"time": 1}), tmp_path / "b")
    assert os.listdir(tmp_path) == []
