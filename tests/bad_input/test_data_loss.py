"""Nothing is lost, nothing is exposed: writes never replace what they must not, stray
temporary files of killed writes are cleaned, the dashboard stays on loopback."""

from __future__ import annotations

import os
import socket
import stat
from pathlib import Path

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
