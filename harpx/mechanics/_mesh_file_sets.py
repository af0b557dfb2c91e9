"""Named cell regions and boundary facets of a mesh read from a file (meshio).

One reader for every way a mesh file names parts of the body, used by
:meth:`Body.from_meshio <harpx.mechanics.body.Body.from_meshio>` (so
:func:`harpx.io.mesh.read_body`) and :func:`harpx.io.mesh.read_body_mesh`:

``cell_sets``
    meshio's named sets (gmsh 4 physical groups, Abaqus/Exodus sets, ...): members in the
    volume blocks become a region, members in face blocks (``quad``/``triangle`` and their
    quadratic forms) a boundary.
``gmsh:physical`` cell data
    named by ``field_data`` (``{name: [tag, dim]}``, gmsh 2.2 files); read only when the
    file has no named cell sets (gmsh 4 files carry the same groups as both).
``region`` cell data
    integer labels of a harpx tracked export, named by ``field_data`` ``region:<name>``
    (else ``region<label>``); negative labels belong to no region.
``skfem:s:<name>`` / ``skfem:b:<name>`` cell data
    scikit-fem's encoding (:meth:`Body.to_meshio <harpx.mechanics.body.Body.to_meshio>`):
    a 0/1 flag per cell, or a bit per local face of the cell (scikit-fem's local order).

Boundaries are matched to the mesh's facets by their corner nodes. Whatever names a set
that cannot be mapped (a set on line or vertex cells, an unnamed gmsh tag, a face that is
not a face of the volume cells, other integer labels) is named in one ``HarpxWarning``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping

import meshio
import numpy as np
from skfem.io.meshio import INV_HEX_MAPPING
from skfem.refdom import RefHex, RefTet

from harpx._typing import IntArray
from harpx.errors import HarpxWarning, user_stacklevel

__all__: list[str] = []

REGION_FIELD = "region:"
# meshio face cell types of each volume kind, the corners first
_FACE_TYPES = {
    "hexahedron": ("quad", "quad8", "quad9"),
    "tetra": ("triangle", "triangle6", "triangle7"),
}
# cell data read elsewhere or carrying no names (gmsh's geometric entity ids)
_KNOWN_DATA = ("region", "fiber", "gmsh:physical", "gmsh:geometrical")


def read_named_sets(
    m: meshio.Mesh,
    kind: str,
    vertex_of: IntArray,
    facets: IntArray,
    source: str,
    region_names: Mapping[str, int] | None = None,
) -> tuple[dict[str, IntArray], dict[str, IntArray]]:
    """Named regions (cell ids) and boundaries (facet ids) a meshio mesh carries.

    ``kind`` is the meshio type of the body's cells (its blocks merged in block order give
    the cell ids); ``vertex_of`` (npoint,) the mesh vertex of every file node (-1 for
    other nodes); ``facets`` (nfacet, nface_vertex) the mesh's facets as vertex ids
    (``mesh.facets.T``); ``region_names`` the names of the ``region`` labels (default:
    ``field_data`` ``region:<name>``). Warns (HarpxWarning) about names it cannot map.
    """
    reader = _SetReader(m, kind, vertex_of, facets, source)
    named = reader.cell_sets()
    if "gmsh:physical" in m.cell_data and not named:
        reader.gmsh_groups()
    if "region" in m.cell_data:
        reader.region_labels(region_names)
    reader.skfem_data()
    reader.warn_ignored()
    return reader.regions, reader.boundaries


class _SetReader:
    """The named sets of one meshio mesh, read source by source into regions and
    boundaries; what cannot be mapped is collected in ``ignored``."""

    def __init__(
        self, m: meshio.Mesh, kind: str, vertex_of: IntArray, facets: IntArray, source: str
    ) -> None:
        self.m, self.kind, self.source = m, kind, source
        self.blocks = [i for i, c in enumerate(m.cells) if c.type == kind and len(c.data)]
        self.cells = np.concatenate(
            [np.asarray(m.cells[i].data, dtype=np.int64) for i in self.blocks]
        )
        starts = np.cumsum([0] + [len(m.cells[i].data) for i in self.blocks])
        self.offset = dict(zip(self.blocks, starts[:-1].tolist(), strict=True))
        self.base = "hexahedron" if kind.startswith("hexahedron") else "tetra"
        self.nface = 4 if self.base == "hexahedron" else 3
        self.faces = [
            i for i, c in enumerate(m.cells) if c.type in _FACE_TYPES[self.base] and len(c.data)
        ]
        self.facet_key = _Facets(np.asarray(facets, dtype=np.int64), np.asarray(vertex_of), source)
        self.regions: dict[str, IntArray] = {}
        self.boundaries: dict[str, IntArray] = {}
        self.ignored: list[str] = []

    def add_boundary(self, name: str, rows: IntArray) -> None:
        """Boundary ``name`` from faces given by their corner nodes (file node ids)."""
        ids = self.facet_key.ids(rows)
        if np.any(ids < 0):
            self.ignored.append(
                f"{np.count_nonzero(ids < 0)} faces of boundary {name!r} that are not faces "
                f"of the {self.kind!r} cells"
            )
        if np.any(ids >= 0):
            self.boundaries[name] = np.unique(ids[ids >= 0])

    def merged(self, name: str) -> np.ndarray:
        """Cell data ``name`` of the body's cells, blocks merged."""
        return np.concatenate([np.asarray(self.m.cell_data[name][i]) for i in self.blocks])

    def cell_sets(self) -> list[str]:
        """Regions and boundaries from meshio cell sets (not gmsh's); their names."""
        m = self.m
        named_sets = [k for k in m.cell_sets if not k.startswith("gmsh:")]
        for name in named_sets:  # loop over the few named sets
            cell_ids: list[IntArray] = []
            face_parts: list[IntArray] = []
            other: dict[str, int] = {}
            for i, members in enumerate(m.cell_sets[name][: len(m.cells)]):
                if members is None or not len(members):
                    continue
                ids = np.asarray(members, dtype=np.int64).ravel()
                block = m.cells[i]
                if ids.min() < 0 or ids.max() >= len(block.data):
                    raise ValueError(
                        f"{self.source}: cell set {name!r} names cell {int(ids.max())} of cell "
                        f"block {i} ({block.type!r}), which has {len(block.data)} cells; the "
                        "file's sets and cells do not belong together"
                    )
                if i in self.offset:
                    cell_ids.append(self.offset[i] + ids)
                elif i in self.faces:
                    face_parts.append(np.asarray(block.data, dtype=np.int64)[ids, : self.nface])
                else:
                    other[block.type] = other.get(block.type, 0) + ids.size
            if cell_ids:
                self.regions[name] = np.unique(np.concatenate(cell_ids))
            if face_parts:
                self.add_boundary(name, np.concatenate(face_parts))
            if other:
                self.ignored.append(f"cell set {name!r} on cells {other!r}")
        return named_sets

    def gmsh_groups(self) -> None:
        """Regions and boundaries from gmsh physical groups named in ``field_data``."""
        tags = self.merged("gmsh:physical").astype(np.int64).ravel()
        physical, face_rows, unnamed = _gmsh_physical(self.m, tags, self.faces, self.nface)
        self.regions.update(physical)
        for name, rows in face_rows.items():  # loop over the few named groups
            self.add_boundary(name, rows)
        if unnamed:
            self.ignored.append(f"gmsh:physical tags {unnamed} with no name in field_data")

    def region_labels(self, region_names: Mapping[str, int] | None) -> None:
        """Regions from the ``region`` labels of a tracked export."""
        if region_names is None:
            region_names = {
                key[len(REGION_FIELD) :]: int(np.ravel(value)[0])
                for key, value in self.m.field_data.items()
                if key.startswith(REGION_FIELD)
            }
        by_code = {code: name for name, code in region_names.items()}
        label = self.merged("region").astype(np.int64).ravel()
        for code in np.unique(label[label >= 0]):  # loop over the few region labels
            name = by_code.get(int(code), f"region{int(code)}")
            self.regions[name] = np.flatnonzero(label == code)

    def skfem_data(self) -> None:
        """Regions and boundaries from scikit-fem's ``skfem:s:``/``skfem:b:`` cell data;
        other integer cell data is noted as ignored."""
        refdom = RefHex if self.base == "hexahedron" else RefTet
        local = np.asarray(refdom.facets, dtype=np.int64)  # (nlocal, nface) local vertices
        cells = self.cells
        t_skfem = cells[:, INV_HEX_MAPPING[:8]] if self.base == "hexahedron" else cells[:, :4]
        unknown = []
        for name in self.m.cell_data:  # loop over the few cell data fields
            parts = name.split(":", 2)
            if len(parts) == 3 and parts[0] == "skfem" and parts[1] == "s":
                self.regions[parts[2]] = np.flatnonzero(self.merged(name).ravel())
            elif len(parts) == 3 and parts[0] == "skfem" and parts[1] == "b":
                bits = self.merged(name).astype(np.int64).ravel()
                if np.any(bits >> len(local)):
                    self.ignored.append(
                        f"face bits beyond the {len(local)} faces of a cell in {name!r}"
                    )
                cell, face = np.nonzero((bits[:, None] >> np.arange(len(local))) & 1)
                self.add_boundary(parts[2], t_skfem[cell[:, None], local[face]])
            elif name not in _KNOWN_DATA and any(
                np.issubdtype(np.asarray(v).dtype, np.integer) for v in self.m.cell_data[name]
            ):
                unknown.append(name)
        if unknown:
            self.ignored.append(f"integer cell data {unknown!r} (labels without names)")

    def warn_ignored(self) -> None:
        """One HarpxWarning naming everything that could not be mapped."""
        if self.ignored:
            warnings.warn(
                f"{self.source}: named regions or boundaries were ignored: "
                f"{'; '.join(self.ignored)}. harpx reads regions and boundaries from cell "
                "sets, named gmsh physical groups, 'region' labels and skfem:s:/skfem:b: cell "
                "data; name the missing ones with Body(..., regions=..., boundaries=...)",
                HarpxWarning,
                stacklevel=user_stacklevel(),
            )


def _gmsh_physical(
    m: meshio.Mesh, tags: IntArray, faces: list[int], nface: int
) -> tuple[dict[str, IntArray], dict[str, IntArray], list[int]]:
    """Regions (cell ids), boundary faces (file node ids) and unnamed tags of gmsh physical
    groups named by ``field_data``; ``tags`` are those of the volume cells."""
    names: dict[tuple[int, int], str] = {}
    for name, value in m.field_data.items():
        v = np.ravel(value)
        if v.size >= 2 and not name.startswith(REGION_FIELD):
            names[(int(v[0]), int(v[1]))] = name
    unnamed: set[int] = set()
    regions: dict[str, IntArray] = {}
    for tag in np.unique(tags):  # loop over the few tags
        if (int(tag), 3) in names:
            regions[names[(int(tag), 3)]] = np.flatnonzero(tags == tag)
        else:
            unnamed.add(int(tag))
    face_rows: dict[str, IntArray] = {}
    if faces:
        physical = m.cell_data["gmsh:physical"]
        ftags = np.concatenate([np.asarray(physical[i]).astype(np.int64).ravel() for i in faces])
        rows = np.concatenate([np.asarray(m.cells[i].data, np.int64)[:, :nface] for i in faces])
        for tag in np.unique(ftags):  # loop over the few tags
            if (int(tag), 2) in names:
                face_rows[names[(int(tag), 2)]] = rows[ftags == tag]
            else:
                unnamed.add(int(tag))
    return regions, face_rows, sorted(unnamed)


class _Facets:
    """Facet ids of faces given by their corner nodes (file node ids)."""

    def __init__(self, facets: IntArray, vertex_of: IntArray, source: str) -> None:
        self.sorted = np.sort(facets, axis=1)
        self.vertex_of = vertex_of
        self.source = source

    def ids(self, rows: IntArray) -> IntArray:
        """Facet id of each row of file node ids; -1 where no facet has those corners."""
        rows = np.asarray(rows, dtype=np.int64)
        if rows.size and (rows.min() < 0 or rows.max() >= self.vertex_of.size):
            raise ValueError(
                f"{self.source} has a face that names a node it does not have (node ids "
                f"must lie in [0, {self.vertex_of.size - 1}])"
            )
        query = np.sort(self.vertex_of[rows], axis=1)
        n = len(self.sorted)
        _, inverse = np.unique(np.concatenate([self.sorted, query]), axis=0, return_inverse=True)
        inverse = inverse.ravel()
        lookup = np.full(inverse.max() + 1, -1, dtype=np.int64)
        lookup[inverse[:n]] = np.arange(n)
        return lookup[inverse[n:]]
