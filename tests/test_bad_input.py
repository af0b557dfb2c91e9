"""Bad input, nothing lost: malformed datasets, meshes and files raise clear errors and
never leave a partial or corrupted output file behind.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

import meshio
import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harpx.batch import track_subject
from harpx.errors import ArchiveError, SchemaError
from harpx.io.mesh import read_body_mesh, to_meshio
from harpx.io.netcdf import open_dataset, to_netcdf
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box, cylinder, hex_mesh
from harpx.schema import standard_attrs, validate
from harpx.tracking.track import track
from tests.test_schema import make_phase, make_tagged, make_tracked

MAT = NeoHookean(c1=1.0, kappa=120.0)
_HYPOTHESIS = settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def _names(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def _refused(ds: xr.Dataset, directory: Path, match: str) -> None:
    """validate() names the problem, and to_netcdf() writes nothing."""
    with pytest.raises(SchemaError, match=match):
        validate(ds)
    target = directory / "out.nc"
    with pytest.raises(SchemaError, match=match):
        to_netcdf(ds, target)
    assert not target.exists()
    assert [n for n in _names(directory) if n.startswith(".out.nc")] == []  # no temp file


# --- malformed tagged datasets -------------------------------------------------------------


def _set(name: str, values: Callable[[xr.Dataset], object]) -> Callable[[xr.Dataset], xr.Dataset]:
    def change(ds: xr.Dataset) -> xr.Dataset:
        out = ds.copy()
        var = out[name]
        new = xr.Variable(var.dims, values(ds), var.attrs)
        if name in out.coords:
            return out.assign_coords({name: new})
        return out.assign({name: new})

    return change


def _drop(name: str) -> Callable[[xr.Dataset], xr.Dataset]:
    return lambda ds: ds.drop_vars(name)


def _drop_attr(name: str) -> Callable[[xr.Dataset], xr.Dataset]:
    def change(ds: xr.Dataset) -> xr.Dataset:
        out = ds.copy()
        out.attrs = {k: v for k, v in ds.attrs.items() if k != name}
        return out

    return change


BAD_TAGGED = [
    pytest.param(
        lambda ds: ds.assign(image=ds.image.transpose("time", "tag", "z", "y", "x")),
        r"'image' has dims \('time', 'tag', .*expected order",
        id="transposed-dims",
    ),
    pytest.param(
        lambda ds: ds.assign(image=ds.image.isel(z=0)),
        r"'image' has dims .*missing \['z'\]",
        id="missing-dim",
    ),
    pytest.param(
        lambda ds: ds.assign(image=ds.image.expand_dims(echo=2)),
        r"unexpected \['echo'\]",
        id="extra-dim",
    ),
    pytest.param(
        _set("x", lambda ds: ds.x.values.astype(str)), "coordinate 'x' has dtype", id="str-x"
    ),
    pytest.param(
        _set("time", lambda ds: np.array([0, 1], "datetime64[ms]")),
        "coordinate 'time' has dtype 'datetime64",
        id="datetime-time",
    ),
    pytest.param(
        _set("mask", lambda ds: ds.mask.values.astype(np.int8)),
        "'mask' has dtype 'int8'; expected bool",
        id="int-mask",
    ),
    pytest.param(
        _set("image", lambda ds: np.where(ds.image > 1.5, np.inf, ds.image)),
        "'image' has .* non-finite values",
        id="inf-image",
    ),
    pytest.param(
        _set("x", lambda ds: ds.x.values**1.1), "coordinate 'x' is not evenly spaced", id="uneven-x"
    ),
    pytest.param(
        _set("y", lambda ds: ds.y.values[::-1]),
        "coordinate 'y' is not increasing",
        id="decreasing-y",
    ),
    pytest.param(
        _drop("tag_direction"), "missing coordinate 'tag_direction'", id="no-tag-direction"
    ),
    pytest.param(
        _drop("tag_frequency"), "missing coordinate 'tag_frequency'", id="no-tag-frequency"
    ),
    pytest.param(_drop("slice_axis"), "missing coordinate 'slice_axis'", id="no-slice-axis"),
    pytest.param(_drop_attr("sequence"), "missing dataset attribute 'sequence'", id="no-sequence"),
    pytest.param(
        _set("tag_direction", lambda ds: 2.0 * ds.tag_direction.values),
        "tag_direction of tag 'x' has norm 2",
        id="non-unit-direction",
    ),
    pytest.param(
        _set("tag_frequency", lambda ds: [0.4, 0.125]),
        "tag_frequency of tag 'x' is above the Nyquist limit",
        id="aliased-tags",
    ),
    pytest.param(
        _set("tag_frequency", lambda ds: [0.0, 0.125]),
        "tag_frequency of tag 'x' is .*0.0.*; expected a positive",
        id="zero-frequency",
    ),
    pytest.param(
        _set("slice_axis", lambda ds: ["x", "z"]),
        "tag 'x' has direction .* mostly along its slice_axis 'x'",
        id="tag-along-slice",
    ),
    pytest.param(
        lambda ds: ds.assign(image=ds.image.assign_attrs(units=None).drop_attrs()),
        "'image' has no 'long_name' attribute",
        id="no-attrs",
    ),
    pytest.param(
        _set("image", lambda ds: ds.image.values.astype(str)), "'image' has dtype", id="str-image"
    ),
    pytest.param(
        _set("image", lambda ds: ds.image.values.astype(complex)),
        "'image' has dtype",
        id="complex-image",
    ),
    pytest.param(
        _set("image", lambda ds: ds.image.values > 1), "'image' has dtype", id="bool-image"
    ),
    pytest.param(
        _set("tag_frequency", lambda ds: ds.tag_frequency.values.astype(str)),
        "'tag_frequency' has dtype",
        id="str-frequency",
    ),
]


@pytest.mark.parametrize(("change", "match"), BAD_TAGGED)
def test_malformed_tagged_is_named_and_never_written(
    change: Callable[[xr.Dataset], xr.Dataset], match: str, tmp_path: Path
) -> None:
    _refused(change(make_tagged()), tmp_path, match)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        pytest.param(
            _set("phase", lambda ds: ds.phase.values + np.pi),
            r"'phase' has values in .*expected the wrapped range",
            id="unwrapped",
        ),
        pytest.param(
            _set("magnitude", lambda ds: -ds.magnitude.values),
            "'magnitude' has .* negative values",
            id="negative-magnitude",
        ),
        pytest.param(
            _set("phase", lambda ds: np.where(ds.x.values > 8, np.nan, ds.phase)),
            "'phase' has .* non-finite values",
            id="nan-phase",
        ),
        pytest.param(
            _set("phase", lambda ds: ds.phase.values * np.nan),
            "'phase' has .* non-finite values",
            id="all-nan-phase",
        ),
        pytest.param(
            _drop_attr("upsample"), "missing dataset attribute 'upsample'", id="no-filter-settings"
        ),
    ],
)
def test_malformed_phase_is_named_never_written_nor_tracked(
    change: Callable[[xr.Dataset], xr.Dataset], match: str, tmp_path: Path
) -> None:
    bad = change(make_phase())
    _refused(bad, tmp_path, match)
    body = Body(box((4.0, 4.0, 2.0), (1, 1, 1)), MAT)
    with pytest.raises(SchemaError, match=match):
        track(bad, body)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        pytest.param(
            _set("cells", lambda ds: ds.cells.values + 5),
            r"'cells' refers to node ids in \[5, 12\] but there are 8 nodes",
            id="cells-beyond-nodes",
        ),
        pytest.param(
            _set("cells", lambda ds: ds.cells.values.astype(float)),
            "'cells' has dtype 'float64'",
            id="float-cells",
        ),
        pytest.param(
            _set("points", lambda ds: np.where(ds.points > 0, np.nan, 0.0)),
            "'points' has .* non-finite values",
            id="nan-points",
        ),
        pytest.param(
            lambda ds: ds.assign(displacement=ds.displacement.transpose()),
            "'displacement' has dims",
            id="transposed-displacement",
        ),
    ],
)
def test_malformed_tracked_is_named_never_written_nor_exported(
    change: Callable[[xr.Dataset], xr.Dataset], match: str, tmp_path: Path
) -> None:
    bad = change(make_tracked())
    _refused(bad, tmp_path, match)
    for series in ("xdmf", "vtu"):
        with pytest.raises(SchemaError, match=match):
            to_meshio(bad, tmp_path / "export", series=series)  # type: ignore[arg-type]
    assert _names(tmp_path) == []


def test_dataset_without_schema_is_refused_by_validate(tmp_path: Path) -> None:
    ds = _drop_attr("harpx_schema")(make_tagged())
    with pytest.raises(SchemaError, match="has no attribute 'harpx_schema'.*pass kind="):
        validate(ds)
    # to_netcdf stores any dataset; without a declared schema it is not a harpx input
    with pytest.raises(SchemaError, match="missing dataset attribute 'harpx_schema'"):
        track(ds, Body(box((4.0, 4.0, 2.0), (1, 1, 1)), MAT))


# --- property tests: NaN/inf anywhere, any uneven coordinate ------------------------------


@_HYPOTHESIS
@given(
    index=st.tuples(
        st.integers(0, 1),
        st.integers(0, 1),
        st.integers(0, 2),
        st.integers(0, 7),
        st.integers(0, 7),
    ),
    value=st.sampled_from([np.nan, np.inf, -np.inf]),
)
def test_non_finite_image_is_never_written(
    tmp_path: Path, index: tuple[int, ...], value: float
) -> None:
    ds = make_tagged(nz=3)
    ds["image"].values[index] = value
    where = re.escape(
        "{"
        + ", ".join(f"{d}={i}" for d, i in zip("tag time z y x".split(), index, strict=True))
        + "}"
    )
    _refused(ds, tmp_path, rf"'image' has 1 non-finite values \(NaN/inf\), first at index {where}")


@_HYPOTHESIS
@given(
    dim=st.sampled_from(["z", "y", "x"]),
    position=st.integers(0, 7),
    fraction=st.floats(5e-3, 0.4).flatmap(lambda f: st.sampled_from([f, -f])),
)
def test_uneven_coordinate_is_never_written(
    tmp_path: Path, dim: str, position: int, fraction: float
) -> None:
    ds = make_tagged(nz=3)
    values = ds[dim].values.copy()
    step = values[1] - values[0]
    # a shift of 0.5 % to 40 % of a voxel: an end value shifted by f moves the fitted line by
    # f/2 at the middle, so the deviation stays above validate's 0.1 % tolerance
    values[position % values.size] += fraction * step
    ds = ds.assign_coords({dim: (dim, values, standard_attrs(dim))})
    _refused(ds, tmp_path, f"coordinate '{dim}' is not evenly spaced")


# --- truncated and foreign files -----------------------------------------------------------


@pytest.fixture(scope="module")
def archive_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    return to_netcdf(make_tagged(), tmp_path_factory.mktemp("a") / "a.nc").read_bytes()


@_HYPOTHESIS
@given(fraction=st.floats(0.0, 0.98))
def test_truncated_archive_is_an_archive_error_naming_the_path(
    tmp_path: Path, archive_bytes: bytes, fraction: float
) -> None:
    path = tmp_path / "cut.nc"
    path.write_bytes(archive_bytes[: int(fraction * len(archive_bytes))])
    with pytest.raises(ArchiveError, match=rf"cannot read '{path}' as a NetCDF archive"):
        open_dataset(path)


def test_truncated_input_is_refused_and_nothing_is_written(
    tmp_path: Path, archive_bytes: bytes
) -> None:
    source = tmp_path / "subject.nc"
    source.write_bytes(archive_bytes[: len(archive_bytes) // 2])
    target = tmp_path / "subject_tracked.nc"
    with pytest.raises(ArchiveError, match=r"cannot read '.*subject\.nc'"):
        track_subject(source, target, lambda ds: Body(box((1.0, 1.0, 1.0), (1, 1, 1)), MAT))
    assert _names(tmp_path) == ["subject.nc"]


@pytest.mark.parametrize(
    ("name", "content"),
    [
        pytest.param("notes.vtu", b"not a mesh", id="text-as-vtu"),
        pytest.param("cut.vtu", "truncated-vtu", id="truncated-vtu"),
        pytest.param("cut.xdmf", "truncated-xdmf", id="truncated-xdmf"),
        pytest.param("cut.pvd", b"<VTKFile><Collection><DataSet", id="truncated-pvd"),
    ],
)
def test_unreadable_mesh_file_is_an_archive_error_naming_it(
    tmp_path: Path, name: str, content: str | bytes
) -> None:
    path = tmp_path / name
    if isinstance(content, str):  # a real export, cut in half
        series = "vtu" if content.endswith("vtu") else "xdmf"
        files = to_meshio(make_tracked(), tmp_path / "whole", series=series)  # type: ignore[arg-type]
        data = files[-1 if series == "vtu" else 0].read_bytes()
        content = data[: len(data) // 2]
    path.write_bytes(content)
    # meshio alone would print and call sys.exit(1) here
    with pytest.raises(ArchiveError, match=rf"cannot read .*'{path}'"):
        read_body_mesh(path)


# --- meshes: inverted, degenerate, outside the image ---------------------------------------


def _box_vtk() -> tuple[np.ndarray, np.ndarray]:
    body = Body(box((2.0, 1.0, 1.0), (2, 1, 1)), MAT)
    return body.nodes, body.cells


BAD_CELLS = [
    pytest.param(
        lambda c: np.concatenate([c[:1, [4, 5, 6, 7, 0, 1, 2, 3]], c[1:]]), "0", id="inverted"
    ),
    pytest.param(
        lambda c: np.concatenate([c[:1], c[1:, [0, 1, 3, 2, 4, 5, 6, 7]]]), "1", id="bow-tie"
    ),
    pytest.param(
        lambda c: np.concatenate([c[:1, [0, 1, 2, 3, 0, 1, 2, 3]], c[1:]]), "0", id="collapsed"
    ),
]


@pytest.mark.parametrize(("corrupt", "cells"), BAD_CELLS)
def test_bad_cells_in_a_mesh_file_are_named(tmp_path: Path, corrupt, cells: str) -> None:
    points, vtk = _box_vtk()
    path = tmp_path / "bad.vtu"
    meshio.write(path, meshio.Mesh(points, [("hexahedron", corrupt(vtk))]))
    with pytest.raises(SchemaError, match=rf"inverted or degenerate hexahedra .*cells \[{cells}\]"):
        read_body_mesh(path)


@pytest.mark.parametrize(("corrupt", "cells"), BAD_CELLS)
def test_bad_cells_given_to_body_are_named(corrupt, cells: str) -> None:
    points, vtk = _box_vtk()
    with pytest.raises(ValueError, match=rf"cells? \[?{cells}"):
        Body(hex_mesh(points, corrupt(vtk)), MAT)


def test_mesh_outside_the_image_is_refused_and_nothing_is_written(tmp_path: Path) -> None:
    source = to_netcdf(make_phase(), tmp_path / "subject.nc")
    far = cylinder(5.0, 5.0, n_radial=1, n_circumferential=8, n_axial=1, center=(500.0, 0.0, 0.0))
    with pytest.raises(SchemaError, match="outside the image field of view"):
        track(make_phase(), Body(far, MAT))
    target = tmp_path / "subject_tracked.nc"
    with pytest.raises(SchemaError, match="outside the image field of view"):
        track_subject(source, target, lambda ds: Body(far, MAT))
    assert _names(tmp_path) == ["subject.nc"]


# --- interrupted writes (SIGKILL mid-write) ------------------------------------------------

_SLOW_NETCDF = textwrap.dedent(
    """
    import sys, time
    import dask, dask.array as da, xarray as xr
    from harpx.io.netcdf import to_netcdf

    def slow(block):
        print("writing", flush=True)
        time.sleep(0.2)
        return block

    data = da.ones((50, 32, 32), chunks=(1, 32, 32)).map_blocks(slow, dtype=float)
    ds = xr.Dataset({"a": (("t", "y", "x"), data, {"units": "1", "long_name": "a"})})
    with dask.config.set(scheduler="synchronous"):
        to_netcdf(ds, sys.argv[1])
    """
)

_SLOW_EXPORT = textwrap.dedent(
    """
    import sys, time
    import meshio
    from harpx.io import mesh
    from harpx.schema import standard_attrs
    from tests.test_schema import make_tracked

    real = meshio.write

    def slow(*args, **kwargs):
        print("writing", flush=True)
        time.sleep(0.2)
        real(*args, **kwargs)

    mesh.meshio.write = slow
    ds = make_tracked()
    ds = ds.isel(time=[0, 1] * 25).assign_coords(
        time=("time", [float(t) for t in range(50)], standard_attrs("time")))
    mesh.to_meshio(ds.assign(displacement=ds.displacement + 1.0), sys.argv[1], series="vtu")
    """
)


def _kill_mid_write(script: str, target: Path) -> None:
    child = subprocess.Popen(
        [sys.executable, "-c", script, str(target)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).parents[1],
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "writing"  # the new version is being written
        time.sleep(0.5)  # a few blocks later: mid-write (50 blocks x 0.2 s = 10 s in total)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait(timeout=30)
    assert child.returncode == -signal.SIGKILL


def test_killed_archive_write_keeps_the_previous_archive(tmp_path: Path) -> None:
    target = tmp_path / "a.nc"
    original = make_tracked()
    to_netcdf(original, target)
    before = target.read_bytes()
    _kill_mid_write(_SLOW_NETCDF, target)
    assert target.read_bytes() == before  # byte for byte: never touched
    xr.testing.assert_identical(open_dataset(target), original)  # and readable
    leftovers = [n for n in _names(tmp_path) if n != "a.nc"]
    # SIGKILL skips the cleanup: the partial temp file stays beside (never instead of) it
    assert all(n.startswith(".a.nc.") and n.endswith(".tmp") for n in leftovers), leftovers


def test_killed_export_keeps_the_previous_export(tmp_path: Path) -> None:
    files = to_meshio(make_tracked(), tmp_path / "r", series="vtu")
    before = {f.name: f.read_bytes() for f in files}
    _kill_mid_write(_SLOW_EXPORT, tmp_path / "r.pvd")
    assert {f.name: f.read_bytes() for f in files} == before
    for f in files[1:]:
        back = meshio.read(f)
        np.testing.assert_array_equal(back.point_data["displacement"], 0.0)  # the old frames
    leftovers = [n for n in _names(tmp_path) if n not in before]
    assert all(n.startswith(".r.pvd.") and n.endswith(".tmp") for n in leftovers), leftovers
