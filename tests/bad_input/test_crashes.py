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
