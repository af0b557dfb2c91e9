"""The inputs of a :class:`~harpx.mechanics.body.Body` checked and put in its terms.

:class:`~harpx.mechanics.body.Body` builds on what these helpers return: the scikit-fem
mesh, element and volumetric treatment of its arguments (a :class:`MeshSpec` brings its
regions, boundaries and fibres), the checked vertices of the cells, the named cell and facet
sets, and the unit fibres at the quadrature points. Each refuses what the body cannot be
built from with a ``TypeError`` or ``ValueError`` naming the argument and what to pass.
Units: mm.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from typing import Any

import meshio
import numpy as np
import skfem
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray
from harpx.errors import CoincidentNodesWarning, HarpxWarning, user_stacklevel
from harpx.mechanics import kinematics
from harpx.mechanics.cells import (
    _HEX20_MESHES,
    _VOLUMETRIC,
    ELEMENTS,
    ElementKind,
    ElementName,
    Volumetric,
    _check_cells,
    _orient_tets,
    default_element,
)
from harpx.mechanics.meshspec import MeshSpec, check_nodes, check_unused_nodes, coincident_nodes

__all__ = [
    "t_max_per_cell",
    "check_fibers_given",
    "check_vertices",
    "facet_ids",
    "growth_needs_fibers",
    "growth_tensors",
    "index_array",
    "named_sets",
    "quadrature_fibers",
    "resolve_mesh",
]


def resolve_mesh(
    mesh: Any, fibers: Any, element: ElementName | None, volumetric: Volumetric | None
) -> tuple[
    Any, Any, ElementName, ElementKind, Volumetric, Mapping[str, ArrayLike], Mapping[str, ArrayLike]
]:
    """The scikit-fem mesh, element and volumetric treatment of the arguments of a Body.

    Parameters
    ----------
    mesh : skfem.MeshHex1, skfem.MeshHex2, skfem.MeshTet1, skfem.MeshTet2 or MeshSpec
        The reference configuration (mm), as given to :class:`~harpx.mechanics.body.Body`.
    fibers : array_like, callable or None
        The fibres as given to :class:`~harpx.mechanics.body.Body` (passed through).
    element : {"hex8", "hex20", "tet4", "tet10"} or None
        The element, or None for what the mesh implies.
    volumetric : {"mean-dilatation", "linear-dilatation", "nodal-dilatation", "pointwise"} or None
        The volumetric treatment, or None for the element's first.

    Returns
    -------
    mesh : skfem.Mesh
        The hexahedral or tetrahedral mesh (a MeshSpec's mesh; tetrahedra oriented).
    fibers : object
        ``fibers``, or the MeshSpec's fibres when ``fibers`` is None.
    element : str
        The element (default: what the mesh implies).
    kind : ElementKind
        Its description (``ELEMENTS[element]``).
    volumetric : str
        The volumetric treatment (default: the element's first).
    spec_regions, spec_boundaries : mapping of str to array of int
        A MeshSpec's named cells and facets ({} for a plain mesh).

    Raises
    ------
    TypeError
        If ``mesh`` is a path, a meshio.Mesh or not a hexahedral or tetrahedral skfem mesh.
    ValueError
        If ``element`` or ``volumetric`` is unknown or does not fit the mesh or element.
    """
    spec_regions: Mapping[str, ArrayLike] = {}
    spec_boundaries: Mapping[str, ArrayLike] = {}
    if isinstance(mesh, MeshSpec):
        spec_regions, spec_boundaries = mesh.regions, mesh.boundaries
        if fibers is None:
            fibers = mesh.fibers
        mesh = mesh.mesh
    elif isinstance(mesh, str | os.PathLike):
        raise TypeError(
            f"mesh is a file path ({os.fspath(mesh)!r}); read it with "
            "harpx.io.mesh.read_body(path, material, ...), which returns the Body"
        )
    elif isinstance(mesh, meshio.Mesh):
        raise TypeError("mesh is a meshio.Mesh; build the body with Body.from_meshio(mesh)")
    if isinstance(mesh, skfem.MeshTet1):
        mesh = _orient_tets(mesh)
    if not isinstance(mesh, (skfem.MeshHex1, skfem.MeshTet1)) or (
        isinstance(mesh, skfem.MeshHex1) and type(mesh) not in _HEX20_MESHES
    ):
        raise TypeError(
            f"mesh must be a skfem.MeshHex1, MeshHex2, MeshTet1 or MeshTet2 or a MeshSpec, got "
            f"{type(mesh).__name__!r}; build one with harpx.mechanics.mesh.box/cylinder "
            "(and tetrahedralize for tetrahedra), or read a mesh file with "
            "harpx.io.mesh.read_body"
        )
    if element is None:
        element = default_element(mesh)
    if element not in ELEMENTS:
        raise ValueError(f"element={element!r} is not one of {sorted(ELEMENTS)!r}")
    kind = ELEMENTS[element]
    if not isinstance(mesh, kind.meshes) or (
        isinstance(mesh, skfem.MeshHex2) and element != "hex20"
    ):
        raise ValueError(
            f"element={element!r} needs a {' or '.join(m.__name__ for m in kind.meshes)} "
            f"mesh, got {type(mesh).__name__!r}; pick the element that matches the cells "
            f"(or omit element= to use {default_element(mesh)!r})"
        )
    if volumetric is None:
        volumetric = kind.volumetric[0]
    if volumetric not in _VOLUMETRIC:
        raise ValueError(f"volumetric={volumetric!r} must be one of {list(_VOLUMETRIC)!r}")
    if volumetric not in kind.volumetric:
        raise ValueError(
            f"volumetric={volumetric!r} is not available for element={element!r}; "
            f"choose one of {list(kind.volumetric)!r} (Q1/P1 and P1/P0 are not inf-sup "
            "stable and lock, tet10 P2/P1-disc too; linear dilatation needs hex20, nodal "
            "dilatation tetrahedra)"
        )
    return mesh, fibers, element, kind, volumetric, spec_regions, spec_boundaries


def check_vertices(mesh: Any) -> FloatArray:
    """The vertices of the cells, checked (finite, used, valid cells; coincident ones warn).

    Parameters
    ----------
    mesh : skfem.Mesh
        A MeshTet2 / MeshHex2 also holds its geometry nodes in ``mesh.p``.

    Returns
    -------
    ndarray, shape (3, nvertex)
        The cells' vertices, mm.

    Raises
    ------
    ValueError
        From :func:`~harpx.mechanics.meshspec.check_nodes`, the cell checks and
        :func:`~harpx.mechanics.meshspec.check_unused_nodes`.

    Warns
    -----
    CoincidentNodesWarning
        If vertices coincide (the cells on either side are not connected).
    """
    curved = isinstance(mesh, (skfem.MeshTet2, skfem.MeshHex2))
    nvert = int(mesh.nvertices) if curved else mesh.p.shape[1]
    vertices = np.asarray(mesh.p)[:, :nvert]
    check_nodes(vertices.T, np.asarray(mesh.t).T, nvertex=int(mesh.t.shape[0]))
    pairs = coincident_nodes(vertices.T)
    if pairs.size:
        warnings.warn(
            f"mesh has {pairs.shape[0]} pairs of coincident nodes, e.g. nodes "
            f"{pairs[0].tolist()} at {vertices[:, pairs[0, 0]].tolist()} mm: the "
            "cells on either side are not connected and move independently; if that is "
            "not a deliberate cut, merge them (mesh = mesh.remove_duplicate_nodes())",
            CoincidentNodesWarning,
            stacklevel=user_stacklevel(),
        )
    _check_cells(mesh)
    check_unused_nodes(vertices.shape[1], np.asarray(mesh.t).T)
    return vertices


def named_sets(
    mesh: Any,
    ncell: int,
    regions: Mapping[str, ArrayLike] | None,
    boundaries: Mapping[str, ArrayLike] | None,
    spec_regions: Mapping[str, ArrayLike],
    spec_boundaries: Mapping[str, ArrayLike],
) -> tuple[dict[str, IntArray], dict[str, IntArray]]:
    """Named cell sets (``{"body": all}`` by default) and facet sets of a body.

    Parameters
    ----------
    mesh : skfem.Mesh
        Its ``subdomains`` and ``boundaries`` are the last defaults.
    ncell : int
        Number of cells.
    regions, boundaries : mapping of str to array_like of int or of bool, optional
        As given to :class:`~harpx.mechanics.body.Body`: cell / facet ids, or boolean masks
        with one entry per cell / facet (checked by :func:`index_array`).
    spec_regions, spec_boundaries : mapping of str to array_like of int or of bool
        Those of a MeshSpec, the defaults before the mesh's own.

    Returns
    -------
    regions, boundaries : dict of str to ndarray of int
        Named cell ids (the given ones, else the MeshSpec's, else the mesh's subdomains,
        else ``{"body": all cells}``) and named facet ids (given, MeshSpec's, mesh's, or
        none).

    Raises
    ------
    ValueError
        If a region or boundary is not a 1-D array of integer ids in ``[0, ncell)`` /
        ``[0, nfacet)`` nor a boolean mask of one entry per cell / facet (the message names
        it).
    """
    if regions is None:
        regions = spec_regions or (mesh.subdomains or {})
    named_regions: dict[str, IntArray] = {
        k: index_array(v, ncell, f"region {k!r}", "cell") for k, v in regions.items()
    } or {"body": np.arange(ncell)}
    if boundaries is None:
        boundaries = spec_boundaries or (mesh.boundaries or {})
    nfacet = int(mesh.facets.shape[1])
    named_boundaries: dict[str, IntArray] = {
        k: index_array(v, nfacet, f"boundary {k!r}", "facet") for k, v in boundaries.items()
    }
    return named_regions, named_boundaries


def index_array(values: ArrayLike, n: int, what: str, unit: str) -> IntArray:
    """Ids in ``[0, n)`` from integer ids or a boolean mask of ``n`` entries, checked.

    Parameters
    ----------
    values : array_like of int or of bool
        Ids (integers, or floats with integer values), or a boolean mask with one entry
        per cell or facet of the mesh (``np.flatnonzero(mask)`` are the ids).
    n : int
        Number of cells or facets of the mesh.
    what : str
        What ``values`` is, for the messages (e.g. ``"region 'apex'"``).
    unit : {"cell", "facet"}
        What the ids count.

    Returns
    -------
    ndarray of int64, shape (nid,)
        The ids.

    Raises
    ------
    ValueError
        If ``values`` is a mask of another length than ``n``, not 1-D, not integer
        (e.g. ``2.5``), a 0/1 integer array of length ``n`` (a mask given as integers), or
        holds an id outside ``[0, n)``; the message names ``what`` and the length expected.
    """
    arr = np.asarray(values)
    if arr.dtype == np.bool_:
        if arr.shape != (n,):
            raise ValueError(
                f"{what} is a boolean mask of shape {arr.shape!r}; a mask needs one entry per "
                f"{unit} of the mesh, shape ({n},), or pass the {unit} ids instead"
            )
        return np.flatnonzero(arr)
    if arr.ndim > 1 or arr.dtype.kind not in "iuf":
        raise ValueError(
            f"{what} has shape {arr.shape!r} and dtype {arr.dtype.name!r}; expected a 1-D "
            f"array of integer {unit} ids in [0, {n}) or a boolean mask of shape ({n},)"
        )
    arr = np.atleast_1d(arr)
    if arr.dtype.kind == "f":
        bad = ~np.isfinite(arr) | (arr != np.round(arr))
        if bad.any():
            raise ValueError(
                f"{what} holds {unit} id {arr[bad][0].item()!r}, which is not an integer; "
                f"pass integer {unit} ids in [0, {n}) or a boolean mask of shape ({n},)"
            )
    ids = arr.astype(np.int64)
    outside = (ids < 0) | (ids >= n)
    if outside.any():
        raise ValueError(
            f"{what} holds {unit} id {ids[outside][0].item()!r}, outside [0, {n}) (the mesh "
            f"has {n} {unit}s); check the ids, or the mesh they were made for"
        )
    if n > 2 and ids.size == n and ids.max() <= 1:
        raise ValueError(
            f"{what} is {n} integer ids that are all 0 or 1: a mask given as integers "
            f"would select {unit}s 0 and 1 only; pass it as a boolean mask "
            "(mask.astype(bool)) or as ids (np.flatnonzero(mask))"
        )
    return ids


def quadrature_fibers(
    fibers: Any, basis: Any, cells: IntArray
) -> tuple[FloatArray | None, FloatArray | None, str | None]:
    """Unit fibres as given (per cell, node or point) and at every quadrature point.

    Parameters
    ----------
    fibers : array_like of shape (ncell, 3), (nnode, 3) or (ncell, nqp, 3), callable or None
        As given to :class:`~harpx.mechanics.body.Body` (any non-zero length; a fibre and
        its opposite are the same fibre):

        * ``(ncell, 3)``: one direction per cell;
        * ``(nnode, 3)``: one direction per dof node (rows of ``Body.dof_points``) or per
          vertex (rows of ``Body.nodes`` for hex20 on a ``MeshHex2`` or tet10 on a
          ``MeshTet1``), interpolated to the quadrature points with the element's shape
          functions (per vertex: the trilinear / linear ones) and normalised; within each
          cell the node directions are first turned to the side of its first node's, so
          that ``f`` and ``-f`` do not cancel;
        * ``(ncell, nqp, 3)``: one direction per quadrature point, in the order of
          ``Body.quadrature_points``;
        * a callable ``fibers(X) -> (n, 3)``, evaluated at the reference quadrature points
          ``X`` (n, 3), mm.

        When the mesh has as many nodes as cells, ``(ncell, 3)`` is read per cell (a
        warning says so if the directions are not all equal). On hex8, whose 8 Gauss points
        are as many as its corners but not at them (Gauss point k is not near corner k), an
        ``(ncell, 8, 3)`` array whose values agree at every node shared by cells (as
        ``nodal[body.cells]`` does) is refused: pass the per-node array itself.
    basis : skfem.CellBasis
        The scalar basis of the body (cells, quadrature points, shape functions).
    cells : ndarray of int, shape (ncell, ncorner)
        Node ids per cell in VTK order (``Body.cells``).

    Returns
    -------
    fibers : ndarray, shape (ncell, 3), (nnode, 3) or (ncell, nqp, 3), or None
        Normalised fibres as given (a callable's at the quadrature points).
    fibers_qp : ndarray, shape (ncell, nqp, 3), or None
        The unit fibres at every quadrature point.
    per : {"cell", "node", "quadrature point", "cell or node", "quadrature point or corner"}
        How ``fibers`` was read (None without fibres); the two-way values flag a reading
        that rests on a default (a warning was given).

    Raises
    ------
    ValueError
        If the fibres (or the callable's result) have another shape or a zero direction,
        an ``(ncell, 8, 3)`` hex8 array holds per-corner values, or per-node fibres cancel
        inside a cell.

    Warns
    -----
    HarpxWarning
        If the reading of ``fibers`` is ambiguous and matters (``per`` says which).
    """
    ncell, nqp = int(basis.nelems), int(basis.X.shape[1])
    nvertex, ndofnode = int(basis.mesh.nvertices), int(basis.N)
    if fibers is None:
        return None, None, None
    given_per_point = callable(fibers)
    if given_per_point:
        X = np.asarray(basis.global_coordinates()).transpose(1, 2, 0).reshape(-1, 3)
        fibers = np.asarray(fibers(np.ascontiguousarray(X)), dtype=np.float64)
        if fibers.shape != (ncell * nqp, 3):
            raise ValueError(
                f"the fibers function returned shape {fibers.shape!r} for "
                f"{ncell * nqp} points; expected ({ncell * nqp}, 3), one "
                "direction per reference point"
            )
        fibers = fibers.reshape(ncell, nqp, 3)
    f = kinematics.unit_fibers(fibers)
    per = "cell"
    if f.shape == (ncell, 3):
        fq = np.broadcast_to(f[:, None, :], (ncell, nqp, 3))
        if ncell in (nvertex, ndofnode) and _varies(f[None]):
            per = "cell or node"
            _warn(
                f"fibers has shape {f.shape!r}: the mesh has as many nodes as cells, so "
                "the directions could be per node; they are read per cell. For per-node "
                "fibres pass them per quadrature point: np.einsum('aq,eai->eqi', "
                "body.basis_values, nodal[body.cell_scalar_dofs])"
            )
    elif f.shape == (ncell, nqp, 3):
        fq, per = f, "quadrature point"
        if nqp == cells.shape[1] and not given_per_point and _varies(f):
            orders = (cells, np.asarray(basis.element_dofs).T)
            shared = [_node_copies_agree(f, c) for c in orders]
            if any(s is True for s in shared):
                raise ValueError(
                    f"fibers has shape {f.shape!r}, one direction per hex8 Gauss point, but "
                    "its values agree at every node shared by cells, as per-corner values "
                    "(nodal[body.cells]) do; the Gauss points are not at the corners. Pass "
                    f"the per-node directions themselves, shape ({nvertex}, 3), which are "
                    "interpolated to the Gauss points; per-point values in the order of "
                    "body.quadrature_points go through a callable: fibers=lambda X: "
                    "values.reshape(-1, 3)"
                )
            if shared[0] is None:
                per = "quadrature point or corner"
                _warn(
                    f"fibers has shape {f.shape!r}: on hex8 that is one direction per "
                    "Gauss point or per corner, and no node is shared by two cells to "
                    "tell; it is read per Gauss point (order of body.quadrature_points). "
                    "For per-corner directions pass the per-node array, shape "
                    f"({nvertex}, 3)"
                )
    elif f.ndim == 2 and f.shape[0] in (nvertex, ndofnode):
        fq, per = _nodal_to_quadrature(f, basis, vertices=f.shape[0] != ndofnode), "node"
    else:
        nodes = f"({ndofnode}, 3)" + (f" or ({nvertex}, 3)" if nvertex != ndofnode else "")
        raise ValueError(
            f"fibers has shape {f.shape!r}; expected ({ncell}, 3) per cell, {nodes} per "
            f"node or ({ncell}, {nqp}, 3) per quadrature point"
        )
    return f, np.ascontiguousarray(fq), per


def _warn(message: str) -> None:
    warnings.warn(message, HarpxWarning, stacklevel=user_stacklevel())


def _varies(f: FloatArray) -> bool:
    """Whether unit fibres ``(ncell, k, 3)`` are not all the same direction in each cell
    (the reading of an ambiguous shape then matters; ``f[None]`` compares all cells)."""
    return bool(np.abs(np.abs(np.einsum("eki,ei->ek", f, f[:, 0])) - 1.0).max() > 1e-12)


def _node_copies_agree(f: FloatArray, cell_nodes: IntArray) -> bool | None:
    """Whether the values ``f[e, k]`` agree wherever ``cell_nodes[e, k]`` is the same node
    (None if no node is in two cells)."""
    ids = cell_nodes.ravel()
    if np.unique(ids).size == ids.size:
        return None
    first = np.empty((int(ids.max()) + 1, 3))
    first[ids[::-1]] = f.reshape(-1, 3)[::-1]
    return bool(np.abs(first[ids] - f.reshape(-1, 3)).max() <= 1e-12)


def _nodal_to_quadrature(f: FloatArray, basis: Any, *, vertices: bool) -> FloatArray:
    """Unit fibres ``(ncell, nqp, 3)`` interpolated from unit fibres per dof node (the
    element's shape functions) or per vertex (the linear / trilinear ones)."""
    if vertices:
        hexa = isinstance(basis.mesh, skfem.MeshHex1)
        element = skfem.ElementHex1() if hexa else skfem.ElementTetP1()
        nb = 8 if hexa else 4
    else:
        element, nb = basis.elem, int(basis.Nbfun)
    N = np.stack([element.lbasis(basis.X, j)[0] for j in range(nb)])  # (nb, nqp)
    g = f[np.asarray(basis.element_dofs)[:nb].T]  # (ncell, nb, 3)
    g = g * np.where(np.einsum("eai,ei->ea", g, g[:, 0]) < 0.0, -1.0, 1.0)[..., None]
    fq = np.einsum("aq,eai->eqi", N, g)
    norm = np.linalg.norm(fq, axis=-1)
    if norm.min() < 1e-3:
        cell = int(np.argmin(norm.min(axis=1)))
        raise ValueError(
            f"the per-node fibres of cell {cell} nearly cancel at a quadrature point "
            f"(interpolated length {norm.min():.2g}): they turn by about 90 degrees across "
            "the cell; refine the mesh there, or give the fibres per cell or per point"
        )
    return fq / norm[..., None]


def check_fibers_given(material: Any, active: Any, growth: Any, fibers_qp: Any) -> None:
    """Refuse a fibre material, active contraction or fibre growth without fibres.

    Parameters
    ----------
    material : object
        The body's material; it needs fibres if its ``needs_fibers`` is true.
    active : ActiveContraction or None
        The active fibre stress law, if any.
    growth : FiberGrowth, GrowthField, array_like or None
        The growth, if any.
    fibers_qp : ndarray, shape (ncell, nqp, 3), or None
        The fibres at the quadrature points (from :func:`quadrature_fibers`).

    Raises
    ------
    ValueError
        Naming what needs the fibres.
    """
    needs = bool(getattr(material, "needs_fibers", False))
    for what, needed in (
        (f"material {type(material).__name__}", needs),
        ("active contraction", active is not None),
        ("fibre growth", growth is not None and growth_needs_fibers(growth)),
    ):
        if needed and fibers_qp is None:
            raise ValueError(
                f"{what} needs 'fibers' but none were given; pass fibers=(ncell, 3) "
                "unit vectors (or use a mesh builder that provides them)"
            )


def growth_tensors(growth: Any, fibers_qp: FloatArray | None, ncell: int, nqp: int) -> FloatArray:
    """Growth tensor ``Fg`` at every quadrature point (``F = Fe Fg``).

    Parameters
    ----------
    growth : object or array_like of shape (ncell,)
        A law or field with ``tensor(fibers_qp) -> Fg`` (e.g.
        :class:`~harpx.mechanics.fiber_laws.FiberGrowth`), or one fibre stretch θ per cell
        (``Fg = I + (θ - 1) f0 ⊗ f0``, dimensionless, > 0).
    fibers_qp : ndarray, shape (ncell, nqp, 3), or None
        Unit fibres at the quadrature points.
    ncell, nqp : int
        Number of cells and of quadrature points per cell.

    Returns
    -------
    ndarray, shape (ncell, nqp, 3, 3)
        ``Fg`` (dimensionless; may be a broadcast view).

    Raises
    ------
    ValueError
        If there are no fibres and the growth needs them (:func:`growth_needs_fibers`), or
        the stretch array is not ``ncell`` positive values.
    """
    fibers = fibers_qp
    if fibers is None:
        if growth_needs_fibers(growth):
            raise ValueError(
                "fibre growth needs 'fibers' but none were given; pass fibers=(ncell, 3) "
                "unit vectors (or use a mesh builder that provides them)"
            )
        fibers = np.zeros((ncell, nqp, 3))  # a tensor field needs no fibres
    if hasattr(growth, "tensor"):
        Fg = np.asarray(growth.tensor(fibers), dtype=np.float64)
        return np.broadcast_to(Fg, (ncell, nqp, 3, 3))
    theta = np.asarray(growth, dtype=np.float64)
    if theta.shape != (ncell,) or np.any(theta <= 0):
        raise ValueError(
            f"growth stretch array has shape {theta.shape!r}; expected "
            f"({ncell},) positive values, or a FiberGrowth"
        )
    return kinematics.growth_tensor(fibers, theta[:, None])


def facet_ids(boundaries: Mapping[str, IntArray], nfacet: int, name: str | ArrayLike) -> IntArray:
    """Facet ids of a named boundary, or given facet ids checked.

    Parameters
    ----------
    boundaries : dict of str to ndarray of int
        The body's named facet sets.
    nfacet : int
        Number of facets of the mesh (columns of ``mesh.facets``).
    name : str, array_like of int or array_like of bool
        A boundary name, facet ids, or a boolean mask with one entry per facet.

    Returns
    -------
    ndarray of int, shape (n,)
        The facet ids.

    Raises
    ------
    KeyError
        If ``name`` is a string that names no boundary (the message lists them).
    ValueError
        If the ids are not a 1-D array of integer indices in ``[0, nfacet)`` nor a boolean
        mask of shape ``(nfacet,)`` with at least one True (see :func:`index_array`).
    """
    if isinstance(name, str):
        if name not in boundaries:
            raise KeyError(f"no boundary named {name!r}; this body has {sorted(boundaries)!r}")
        return boundaries[name]
    ids = index_array(name, nfacet, "the facet ids", "facet")
    if ids.size == 0 and np.asarray(name).dtype == np.bool_:
        raise ValueError(
            "the facet mask selects no facet (all False): a condition or load on it would "
            "act on nothing; check how the mask was built"
        )
    return ids


def t_max_per_cell(values: float | Mapping[str, float] | ArrayLike, regions: Mapping[str, IntArray],
                ncell: int) -> FloatArray:  # fmt: skip
    """One value per cell from a uniform value, values per region, or values per cell.

    Parameters
    ----------
    values : float, dict of str to float, or array_like of shape (ncell,)
        Uniform, per named region (cells outside every named region get 0), or per cell.
    regions : dict of str to ndarray of int
        The body's named cell sets.
    ncell : int
        Number of cells.

    Returns
    -------
    ndarray, shape (ncell,)
        The values per cell (a new array).

    Raises
    ------
    ValueError
        If a region name is not one of ``regions`` (the message lists them), or an array
        is neither one value nor one per cell.
    """
    if not isinstance(values, Mapping):
        array = np.asarray(values, dtype=np.float64)
        if array.shape not in ((), (1,), (ncell,)):
            raise ValueError(
                f"t_max has shape {array.shape!r}; expected one value (kPa), a dict of "
                f"region -> kPa, or one value per cell ({ncell},)"
            )
        return np.broadcast_to(array, (ncell,)).copy()
    out = np.zeros(ncell)
    for name, value in values.items():
        if name not in regions:
            raise ValueError(
                f"t_max names region {name!r}, which is not one of {sorted(regions)!r}"
            )
        out[regions[name]] = float(value)
    return out


def growth_needs_fibers(growth: Any) -> bool:
    """Whether a growth needs the body's fibres.

    Parameters
    ----------
    growth : object or array_like
        A growth law or field (its ``needs_fibers`` says; a tensor field such as
        :class:`~harpx.physiology.growth.GrowthField` needs none), or one fibre stretch
        per cell (needs them).

    Returns
    -------
    bool
        True unless ``growth`` declares ``needs_fibers = False``.
    """
    return bool(getattr(growth, "needs_fibers", True))
