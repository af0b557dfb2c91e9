"""Bad input that used to crash inside harpx (raw numpy/meshio errors, SystemExit) now gets
a named error before any work is done."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest
import skfem

from harpx.errors import ArchiveError, CoincidentNodesWarning
from harpx.io.mesh import read_body
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box, hex_mesh

MAT = NeoHookean(c1=1.0, kappa=120.0)


def _box() -> skfem.MeshHex1:
    return box((3.0, 3.0, 2.0), (3, 3, 2)).mesh  # coarse mesh so the test is fast


def test_unused_node_is_named_not_a_stiffness_pattern_error() -> None:
    m = _box()
    p = np.concatenate([[[9.0, 9.0, 9.0]], m.p.T]).T  # a stray node 0, cells renumbered
    with pytest.raises(ValueError, match=r"1 nodes that no cell uses: nodes \[0\].*remove_unused"):
        Body(skfem.MeshHex1(p, m.t + 1), MAT)


def test_unused_node_of_a_mesh_file_is_dropped(tmp_path: Path) -> None:
    m = meshio.Mesh(
        np.concatenate([[[9.0, 9.0, 9.0]], _box().p.T]),
        [("hexahedron", Body(_box(), MAT).cells + 1)],
    )
    meshio.write(tmp_path / "stray.vtu", m)
    body = read_body(tmp_path / "stray.vtu", MAT)
    assert body.nodes.shape == (48, 3)  # 4 x 4 x 3 box nodes; the stray node is gone
    np.testing.assert_allclose(body.cell_volume.sum(), 18.0, rtol=1e-12)  # 3 x 3 x 2 mm


def test_unmerged_duplicate_nodes_warn_naming_them() -> None:
    left = box((1.0, 1.0, 1.0), (1, 1, 1)).mesh
    right = box((1.0, 1.0, 1.0), (1, 1, 1), origin=(1.0, 0.0, 0.0)).mesh
    p = np.concatenate([left.p, right.p], axis=1)
    t = np.concatenate([left.t, right.t + 8], axis=1)
    with pytest.warns(CoincidentNodesWarning, match=r"4 pairs of coincident nodes.*not connected"):
        Body(skfem.MeshHex1(p, t), MAT)


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_node_is_named(value: float) -> None:
    m = _box()
    p = m.p.copy()
    p[1, 5] = value
    with pytest.raises(ValueError, match=r"1 nodes with a NaN or infinite coordinate: nodes \[5\]"):
        Body(skfem.MeshHex1(p, m.t), MAT)


def test_cell_referring_to_a_missing_node_is_named() -> None:
    body = Body(_box(), MAT)
    cells = body.cells.copy()
    cells[4, 2] = 999
    with pytest.raises(ValueError, match=r"mesh cells \[4\] refer to node ids outside \[0, 48\)"):
        hex_mesh(body.nodes, cells)


def test_garbage_mesh_file_is_an_archive_error_not_system_exit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "garbage.vtu"
    path.write_text("garbage")
    with pytest.raises(ArchiveError, match=rf"cannot read mesh '{path}' \(meshio cannot parse"):
        read_body(path, MAT)
    assert capsys.readouterr().out == ""  # meshio's own print is swallowed


def test_missing_mesh_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"cannot read mesh '.*nothing\.vtu': no such file"):
        read_body(tmp_path / "nothing.vtu", MAT)


def test_directory_as_mesh_is_named(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="is a directory, not a file"):
        read_body(tmp_path, MAT)


# --- round three: raw numpy/skfem/xarray errors found by probing, now named ----------------


def _vtk_box() -> meshio.Mesh:
    return Body(_box(), MAT).to_meshio()  # 18 hexahedra in VTK order


def test_twisted_hexahedra_are_named_not_a_zero_jacobian_exception() -> None:
    # before: scikit-fem's bare "Exception: Zero Jacobian determinant"
    m = _vtk_box()
    twisted = m.cells_dict["hexahedron"][:, [0, 1, 3, 2, 4, 5, 7, 6]]
    with pytest.raises(ValueError, match=r"has 18 twisted or collapsed hexahedra .*cells \[0, 1"):
        Body.from_meshio(meshio.Mesh(m.points, [("hexahedron", twisted)]), MAT)
    mirrored = m.cells_dict["hexahedron"][:, [4, 5, 6, 7, 0, 1, 2, 3]]  # valid, reordered
    assert Body.from_meshio(meshio.Mesh(m.points, [("hexahedron", mirrored)]), MAT).ncell == 18


def test_cells_naming_missing_nodes_are_named_not_an_index_error() -> None:
    m = _vtk_box()
    with pytest.raises(ValueError, match=r"cells that name nodes it does not have .*\[0, 9\]"):
        Body.from_meshio(meshio.Mesh(m.points[:10], m.cells), MAT)


def test_nan_node_in_a_mesh_file_is_named_not_a_runtime_warning(tmp_path: Path) -> None:
    from harpx.errors import SchemaError
    from harpx.io.mesh import read_body_mesh

    m = _vtk_box()
    points = m.points.copy()
    points[3] = np.nan
    meshio.write(tmp_path / "nan.vtu", meshio.Mesh(points, m.cells))
    with pytest.raises(
        SchemaError, match=r"1 nodes with a NaN or infinite coordinate \(nodes \[3\]"
    ):
        read_body_mesh(tmp_path / "nan.vtu")


def _wrong_type_calls() -> list:
    from harpx.io.mesh import to_meshio
    from harpx.io.netcdf import open_dataset, to_netcdf
    from harpx.schema import fill_standard_attrs
    from harpx.tracking.image_fit import check_fits_image
    from tests.test_schema import make_tagged

    body, tagged = Body(_box(), MAT), make_tagged()
    dataset = r"needs an xarray.Dataset"
    return [
        pytest.param(lambda d: to_netcdf(None, d / "a.nc"), dataset, id="to_netcdf"),
        pytest.param(
            lambda d: to_netcdf(tagged.image, d / "a.nc"), r"'DataArray'; convert", id="da"
        ),
        pytest.param(lambda d: to_netcdf(tagged, 5), r"path=5 must be a file path", id="path"),
        pytest.param(lambda d: open_dataset(None), r"path=None must be a file", id="open"),
        pytest.param(lambda d: fill_standard_attrs(None), dataset, id="fill"),
        pytest.param(lambda d: to_meshio(None, d / "a.xdmf"), r"tracked/1 xarray", id="meshio"),
        pytest.param(lambda d: read_body(None, MAT), r"path=None must be a file", id="read_body"),
        pytest.param(
            lambda d: Body.from_meshio("m.vtu", MAT), r"expected a meshio.Mesh .*'str'", id="body"
        ),
        pytest.param(lambda d: check_fits_image(None, tagged), r"must be a harpx Body", id="fit"),
        pytest.param(lambda d: check_fits_image(body, None), r"grid must be a", id="grid"),
    ]


@pytest.mark.parametrize(("call", "match"), _wrong_type_calls())
def test_wrong_types_are_named_not_attribute_errors(call, match: str, tmp_path: Path) -> None:
    with pytest.raises(TypeError, match=match):
        call(tmp_path)
    assert list(tmp_path.iterdir()) == []  # nothing written
