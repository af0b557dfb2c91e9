"""Empty input (no cells, no nodes, no frames) is named, never a numpy reduction error."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest
import skfem

from harpx.errors import ArchiveError, SchemaError
from harpx.io.mesh import read_body
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import hex_mesh
from harpx.schema import validate
from tests.test_schema import make_tagged, make_tracked

MAT = NeoHookean(c1=1.0, kappa=120.0)


def test_empty_skfem_mesh_is_named() -> None:
    empty = skfem.MeshHex1(np.zeros((3, 0)), np.zeros((8, 0), dtype=np.int32))
    with pytest.raises(ValueError, match=r"mesh cells have shape \(0, 8\).*empty mesh"):
        Body(empty, MAT)


def test_empty_hex_mesh_is_named() -> None:
    with pytest.raises(ValueError, match="empty mesh cannot be tracked"):
        hex_mesh(np.zeros((0, 3)), np.zeros((0, 8), dtype=np.int64))


def test_empty_vtu_is_named(tmp_path: Path) -> None:
    path = tmp_path / "empty.vtu"
    meshio.write(path, meshio.Mesh(np.zeros((0, 3)), [("hexahedron", np.zeros((0, 8), int))]))
    with pytest.raises(ArchiveError, match=rf"cannot read mesh '{path}'"):
        read_body(path, MAT)


def test_mesh_file_without_hexahedra_is_named(tmp_path: Path) -> None:
    path = tmp_path / "tri.vtu"
    meshio.write(path, meshio.Mesh(np.eye(3), [("triangle", np.array([[0, 1, 2]]))]))
    with pytest.raises(
        ValueError, match=r"has no hexahedra or tetrahedra \(cell blocks \{'triangle': 1\}\)"
    ):
        read_body(path, MAT)


@pytest.mark.parametrize("dim", ["time", "x", "tag"])
def test_a_dataset_with_an_empty_dimension_is_named(dim: str) -> None:
    ds = make_tagged().isel({dim: slice(0, 0)})
    with pytest.raises(SchemaError, match=rf"dimension '{dim}' has length 0"):
        validate(ds)


def test_a_tracked_dataset_without_nodes_is_named() -> None:
    with pytest.raises(SchemaError, match="dimension 'node' has length 0"):
        validate(make_tracked().isel(node=slice(0, 0)))
