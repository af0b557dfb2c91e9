"""Tests of harpx.io.mesh: ParaView time series of tracked results and meshio round trips."""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import meshio.xdmf
import numpy as np
import pytest
import xarray as xr

from harpx.errors import SchemaError
from harpx.io import mesh as mesh_io
from harpx.io.mesh import read_body, read_body_mesh, to_meshio
from harpx.io.netcdf import open_dataset, to_netcdf
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box, cylinder, hex_mesh
from harpx.tracking.results import tracked_dataset
from tests.test_schema import make_phase, make_tracked

MAT = NeoHookean(c1=1.0, kappa=120.0)


def _body(element: str) -> Body:
    # coarse mesh so the test is fast; two named regions and per-cell fibres
    spec = cylinder(6.0, 4.0, n_radial=1, n_circumferential=8, n_axial=2, wall_thickness=1.0)
    ncell = spec.mesh.nelements
    angle = np.linspace(0.0, np.pi, ncell)
    fibers = np.stack([np.cos(angle), np.sin(angle), np.zeros(ncell)], axis=1)
    return Body(spec, MAT, fibers=fibers, element=element)


def _tracked(element: str, rng: np.random.Generator) -> xr.Dataset:
    """A tracked/1 dataset with every exported variable (smooth random motion, 3 frames)."""
    body = _body(element)
    phase = make_phase().isel(time=[0, 1, 1]).assign_coords(time=[0.0, 18.0, 36.0])
    X = body.dof_points
    A = 0.02 * rng.standard_normal((3, 3))
    U = np.stack(
        [(s * (X @ A.T + 0.01 * rng.standard_normal(X.shape))).ravel() for s in (0.0, 0.5, 1.0)]
    )
    eps_cell = rng.uniform(0, 0.1, (3, body.ncell))
    eps_cell[:, 0] = np.nan  # a cell without constraint points
    diagnostics = {"epsilon": np.array([0.0, 0.03, 0.04]), "epsilon_cell": eps_cell}
    return tracked_dataset(body, U, phase, diagnostics, {"method": "penalty"})


@pytest.fixture(params=["hex8", "hex20"])
def tracked(request: pytest.FixtureRequest, rng: np.random.Generator) -> xr.Dataset:
    return _tracked(request.param, rng)


def _expected_cell_data(tracked: xr.Dataset, n: int) -> dict[str, np.ndarray]:
    frame = tracked.isel(time=n)
    return {
        "green_strain": frame.green_strain.values.reshape(-1, 9),
        "fiber_stretch": frame.fiber_stretch.values,
        "epsilon_cell": frame.epsilon_cell.values,
        "region": tracked.region.values,
        "fiber": tracked.fiber.values,
    }


def _names(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def test_vtu_series_round_trip_is_exact(tracked: xr.Dataset, tmp_path: Path) -> None:
    files = to_meshio(tracked, tmp_path / "result", series="vtu")
    ntime = tracked.sizes["time"]
    assert [f.name for f in files] == ["result.pvd"] + [f"result_{n:04d}.vtu" for n in range(ntime)]
    assert _names(tmp_path) == sorted(f.name for f in files)  # no temporary files left
    # the PVD lists the frames with their times (ms), as written by repr(float): exact
    sets = ET.parse(files[0]).getroot().findall("./Collection/DataSet")
    assert [s.get("file") for s in sets] == [f.name for f in files[1:]]
    np.testing.assert_array_equal([float(s.get("timestep")) for s in sets], tracked.time.values)
    cell_type = {"hex8": "hexahedron", "hex20": "hexahedron20"}[tracked.cells.attrs["element"]]
    for n, path in enumerate(files[1:]):
        m = meshio.read(path)
        # binary VTU stores float64/int64 verbatim: exact
        np.testing.assert_array_equal(m.points, tracked.points.values)
        assert [c.type for c in m.cells] == [cell_type]
        np.testing.assert_array_equal(m.cells[0].data, tracked.cells.values)
        np.testing.assert_array_equal(
            m.point_data["displacement"], tracked.displacement.isel(time=n).values
        )
        for name, expected in _expected_cell_data(tracked, n).items():
            np.testing.assert_array_equal(m.cell_data[name][0], expected, err_msg=name)


def test_xdmf_series_round_trip_is_exact(tracked: xr.Dataset, tmp_path: Path) -> None:
    files = to_meshio(tracked, tmp_path / "result.xdmf")
    assert files[0] == tmp_path / "result.xdmf"
    assert _names(tmp_path) == sorted(f.name for f in files)
    cell_type = {"hex8": "hexahedron", "hex20": "hexahedron20"}[tracked.cells.attrs["element"]]
    with meshio.xdmf.TimeSeriesReader(files[0]) as reader:
        points, cells = reader.read_points_cells()
        # inline XML holds float64 as %.16e (17 significant digits) and HDF5 is binary: exact
        np.testing.assert_array_equal(points, tracked.points.values)
        assert [c.type for c in cells] == [cell_type]
        np.testing.assert_array_equal(cells[0].data, tracked.cells.values)
        assert reader.num_steps == tracked.sizes["time"]
        for n in range(reader.num_steps):
            t, point_data, cell_data = reader.read_data(n)
            assert t == tracked.time.values[n]
            np.testing.assert_array_equal(
                point_data["displacement"], tracked.displacement.isel(time=n).values
            )
            for name, expected in _expected_cell_data(tracked, n).items():
                np.testing.assert_array_equal(cell_data[name][0], expected, err_msg=name)


@pytest.mark.parametrize("series", ["vtu", "xdmf"])
def test_read_body_mesh_rebuilds_the_same_body(
    tracked: xr.Dataset, tmp_path: Path, series: str
) -> None:
    element = tracked.cells.attrs["element"]
    files = to_meshio(tracked, tmp_path / "result", series=series)  # type: ignore[arg-type]
    for path in (files[0], files[-1]):  # the index file, and the last frame / data file
        if path.suffix == ".h5":
            continue
        spec = read_body_mesh(path)
        body = Body(spec, MAT, element=element)
        # same geometry and connectivity, exactly (positions are copied, never recomputed)
        np.testing.assert_array_equal(body.dof_points, tracked.points.values)
        np.testing.assert_array_equal(body.cells, tracked.cells.values)
        np.testing.assert_array_equal(spec.fibers, tracked.fiber.values)  # stored verbatim
        # Body normalises the (already unit) fibres again: changes of at most an ulp or two
        np.testing.assert_allclose(body.fibers, tracked.fiber.values, rtol=0, atol=4e-16)
        names = tracked.region.attrs["flag_meanings"].split()
        assert sorted(body.regions) == sorted(names)
        for code, name in enumerate(names):
            np.testing.assert_array_equal(
                body.regions[name], np.flatnonzero(tracked.region.values == code)
            )


def test_body_reads_an_exported_frame_directly(tmp_path: Path, rng: np.random.Generator) -> None:
    tracked = _tracked("hex8", rng)
    files = to_meshio(tracked, tmp_path / "result", series="vtu")
    body = read_body(files[1], MAT)  # any meshio-readable file
    np.testing.assert_array_equal(body.dof_points, tracked.points.values)
    np.testing.assert_array_equal(body.cells, tracked.cells.values)


def test_export_of_a_reopened_archive(tmp_path: Path, rng: np.random.Generator) -> None:
    tracked = _tracked("hex20", rng)
    archive = open_dataset(to_netcdf(tracked, tmp_path / "t.nc"), chunks={})  # lazy
    try:
        files = to_meshio(archive, tmp_path / "lazy.xdmf")
    finally:
        archive.close()
    with meshio.xdmf.TimeSeriesReader(files[0]) as reader:
        reader.read_points_cells()
        _, point_data, _ = reader.read_data(2)
    np.testing.assert_array_equal(
        point_data["displacement"], tracked.displacement.isel(time=2).values
    )  # exact


def test_xdmf_with_hdf5_heavy_data(
    tmp_path: Path, rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    # h5py comes with the test extra, so this runs (it used to be skipped without it)
    assert importlib.util.find_spec("h5py") is not None, "install harpx[test] (h5py)"
    tracked = _tracked("hex8", rng)
    monkeypatch.chdir(tmp_path)  # meshio alone would put the .h5 in the working directory
    (tmp_path / "out").mkdir()
    files = to_meshio(tracked, tmp_path / "out" / "result.xdmf")
    assert [f.name for f in files] == ["result.xdmf", "result.h5"]
    assert _names(tmp_path) == ["out"] and _names(tmp_path / "out") == ["result.h5", "result.xdmf"]
    with meshio.xdmf.TimeSeriesReader(files[0]) as reader:
        points, _ = reader.read_points_cells()
        _, point_data, _ = reader.read_data(1)
    np.testing.assert_array_equal(points, tracked.points.values)  # binary: exact
    np.testing.assert_array_equal(
        point_data["displacement"], tracked.displacement.isel(time=1).values
    )


def test_overwrite_replaces_files_and_failure_keeps_them(
    tmp_path: Path, rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    first = _tracked("hex8", rng)
    files = to_meshio(first, tmp_path / "r", series="vtu")
    before = {f.name: f.read_bytes() for f in files}
    second = first.assign(displacement=first.displacement * 2.0)
    calls = {"n": 0}
    real_write = meshio.write

    def failing_write(path: Path, mesh: meshio.Mesh, **kwargs: object) -> None:
        calls["n"] += 1
        if calls["n"] == 2:  # the second frame: the first one is already on disk (in tmp)
            raise OSError("disk full")
        real_write(path, mesh, **kwargs)

    monkeypatch.setattr(mesh_io.meshio, "write", failing_write)
    with pytest.raises(OSError, match="disk full"):
        to_meshio(second, tmp_path / "r", series="vtu")
    monkeypatch.undo()
    assert {f.name: f.read_bytes() for f in files} == before  # previous export untouched
    assert _names(tmp_path) == sorted(before)  # and no temporary directory left behind
    to_meshio(second, tmp_path / "r", series="vtu")
    back = meshio.read(tmp_path / "r_0002.vtu")
    np.testing.assert_array_equal(
        back.point_data["displacement"], second.displacement.isel(time=2).values
    )


def _point_cloud(ds: xr.Dataset) -> xr.Dataset:
    """A tracked/1 point cloud (as conventional HARP tracking gives): no cells."""
    cells = xr.Variable(
        ("cell", "vertex"), np.zeros((0, 0), np.int64), {**ds.cells.attrs, "element": "points"}
    )
    return ds.drop_vars("cells").assign(cells=cells)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        pytest.param(lambda ds: ds.drop_vars("cells"), "has no 'cells'", id="no-cells"),
        pytest.param(_point_cloud, "element 'points'", id="point-cloud"),
        pytest.param(
            lambda ds: ds.assign(cells=ds.cells.assign_attrs(element="pyramid5")),
            "element 'pyramid5'",
            id="unknown-element",
        ),
        pytest.param(
            lambda ds: ds.assign_attrs(harpx_schema="phase/1"),
            "'harpx_schema' is 'phase/1'",
            id="wrong-schema",
        ),
        pytest.param(
            lambda ds: ds.drop_vars("displacement"),
            "missing data variable 'displacement'",
            id="no-displacement",
        ),
    ],
)
def test_bad_dataset_is_named_and_nothing_is_written(tmp_path: Path, change, match) -> None:
    ds = make_tracked()
    with pytest.raises(SchemaError, match=match):
        to_meshio(change(ds), tmp_path / "bad.xdmf")
    assert _names(tmp_path) == []


@pytest.mark.parametrize(
    ("path", "series", "match"),
    [
        pytest.param("r.xdmf", "vtk", "series='vtk' is not supported", id="series"),
        pytest.param(
            "r.vtu",
            "xdmf",
            "ends in '.vtu', which belongs to series='vtu'",
            id="vtu-suffix-for-xdmf",
        ),
        pytest.param(
            "r.xdmf",
            "vtu",
            "ends in '.xdmf', which belongs to series='xdmf'",
            id="xdmf-suffix-for-vtu",
        ),
    ],
)
def test_bad_path_or_series_is_named(tmp_path: Path, path: str, series: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        to_meshio(make_tracked(), tmp_path / path, series=series)  # type: ignore[arg-type]
    assert _names(tmp_path) == []


def test_suffixes(tmp_path: Path) -> None:
    ds = make_tracked()
    assert to_meshio(ds, tmp_path / "a.vtu", series="vtu")[0].name == "a.pvd"
    assert to_meshio(ds, tmp_path / "b.xmf")[0].name == "b.xmf"
    assert to_meshio(ds, tmp_path / "c.v1")[0].name == "c.v1.xdmf"


def test_missing_directory_is_named(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"directory '.*nowhere' does not exist"):
        to_meshio(make_tracked(), tmp_path / "nowhere" / "r.xdmf")


def _vtk_box_cells() -> tuple[np.ndarray, np.ndarray]:
    spec = box((2.0, 1.0, 1.0), (2, 1, 1))
    body = Body(spec, MAT)
    return body.nodes, body.cells


@pytest.mark.parametrize(
    ("corrupt", "bad_cells"),
    [
        pytest.param(lambda c: c[:, [4, 5, 6, 7, 0, 1, 2, 3]], "0, 1", id="inverted"),
        pytest.param(
            lambda c: np.concatenate([c[:1], c[1:, [0, 1, 3, 2, 4, 5, 6, 7]]]), "1", id="bow-tie"
        ),
        pytest.param(
            lambda c: np.concatenate([c[:1, [0, 1, 2, 3, 0, 1, 2, 3]], c[1:]]), "0", id="collapsed"
        ),
    ],
)
def test_read_body_mesh_rejects_bad_hexahedra(tmp_path: Path, corrupt, bad_cells: str) -> None:
    points, cells = _vtk_box_cells()
    path = tmp_path / "bad.vtu"
    meshio.write(path, meshio.Mesh(points, [("hexahedron", corrupt(cells))]))
    match = rf"inverted or degenerate hexahedra .*cells \[{bad_cells}\]"
    with pytest.raises(SchemaError, match=match):
        read_body_mesh(path)


def test_read_body_mesh_accepts_valid_foreign_files(tmp_path: Path) -> None:
    points, cells = _vtk_box_cells()
    path = tmp_path / "ok.vtu"
    meshio.write(path, meshio.Mesh(points, [("hexahedron", cells)]))
    spec = read_body_mesh(path)
    np.testing.assert_array_equal(Body(spec, MAT).cells, cells)
    assert spec.regions == {} and spec.fibers is None
    # the same mesh built directly: identical skfem mesh
    np.testing.assert_array_equal(spec.mesh.t, hex_mesh(points, cells).t)


def test_read_body_mesh_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"cannot read mesh '.*missing\.vtu'"):
        read_body_mesh(tmp_path / "missing.vtu")
    tri = tmp_path / "tri.vtu"
    meshio.write(tri, meshio.Mesh(np.eye(3), [("triangle", [[0, 1, 2]])]))
    with pytest.raises(SchemaError, match=r"tri\.vtu' has no hexahedra \(cell blocks \{'triangle'"):
        read_body_mesh(tri)
    pvd = tmp_path / "lost.pvd"
    pvd.write_text(
        '<VTKFile type="Collection"><Collection><DataSet timestep="0" '
        'file="gone_0000.vtu"/></Collection></VTKFile>'
    )
    with pytest.raises(FileNotFoundError, match=r"lists '.*gone_0000\.vtu', which does not exist"):
        read_body_mesh(pvd)
