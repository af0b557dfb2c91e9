"""A deformable body: mesh, element, material, fibres, regions and quadrature data.

:class:`Body` ties a scikit-fem hexahedral or tetrahedral mesh to a material and precomputes
everything the vectorised assembly (:mod:`harpx.mechanics.assembly`) needs: reference
gradients of the shape functions at every quadrature point, quadrature weights,
element-to-dof maps, per-point fibre directions, active-stress levels and growth tensors.

Elements (``ELEMENTS``): ``hex8``, ``hex20``, ``tet4`` and ``tet10`` (the ``element``
parameter of :class:`Body`). A ``skfem.MeshHex2`` (27-node triquadratic geometry,
:func:`~harpx.mechanics.mesh.curved_hex_mesh`) carries curved hexahedra for hex20: the
displacement is the 20-node serendipity field on the curved cells (its dofs are the
vertices and the edge nodes; the face and cell geometry nodes carry no dofs). Point
location (:func:`~harpx.mechanics.locate.locate`, ``Body.displacement_at``, tracking)
handles straight hexahedra only and refuses curved ones.

Degrees of freedom: scalar dof ``n`` of the scalar element (mesh vertices first, then, for
hex20 and tet10, one node per mesh edge) carries the displacement components ``3n, 3n+1, 3n+2``
(x, y, z). This is the ordering of ``skfem.ElementVector`` on the same mesh (``body.basis``).
Units: mm, kPa.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, TypeVar, cast

import meshio
import numpy as np
import skfem
from numpy.typing import ArrayLike
from scipy import sparse

from harpx._moved import moved_getattr
from harpx._typing import FloatArray, IntArray
from harpx.mechanics import kinematics
from harpx.mechanics.body_inputs import (
    check_fibers_given,
    check_vertices,
    facet_ids,
    growth_tensors,
    named_sets,
    quadrature_fibers,
    resolve_mesh,
    t_max_per_cell,
)
from harpx.mechanics.cells import (
    ELEMENTS,  # noqa: F401  (older code imports it from here)
    ElementName,
    Volumetric,
    _skfem_mesh,
    vtk_cells,
)

__all__ = ["Body"]

if TYPE_CHECKING:
    from harpx.mechanics.quality import MeshQuality

_T = TypeVar("_T")


class Body:
    """A hyperelastic body discretised with hexahedral or tetrahedral finite elements.

    Parameters
    ----------
    mesh : skfem.MeshHex1, skfem.MeshHex2, skfem.MeshTet1, skfem.MeshTet2 or MeshSpec
        The reference configuration (mm): a scikit-fem hexahedral or tetrahedral mesh
        (``MeshHex2``: curved hexahedra for hex20, ``MeshTet2``: curved quadratic
        tetrahedra) or a :class:`~harpx.mechanics.mesh.MeshSpec` from the builders in
        :mod:`harpx.mechanics.mesh`. A :class:`meshio.Mesh` goes through
        :meth:`from_meshio`; a mesh file through :func:`harpx.io.mesh.read_body`.
    material : object
        Material with ``isochoric_response(F, fiber)``, ``volumetric(J)``, ``kappa`` and
        ``needs_fibers`` (e.g. :class:`~harpx.mechanics.materials.NeoHookean`).
    fibers : array_like of shape (ncell, 3), (nnode, 3) or (ncell, nqp, 3), or callable, optional
        Reference fibre directions: per cell, per node (interpolated), per quadrature point,
        or a function ``fibers(X) -> (n, 3)`` of reference positions ``X`` (n, 3) in mm, at
        the quadrature points (rules: :func:`~harpx.mechanics.body_inputs.quadrature_fibers`).
        Needed by fibre materials, active contraction and fibre growth.
    regions : dict of str to array of int or of bool (one per cell), optional
        Named cell sets. Defaults to the mesh's regions/subdomains or ``{"body": all}``.
    element : {"hex8", "hex20", "tet4", "tet10"}, optional
        Trilinear hexahedron (2x2x2 Gauss points), 20-node serendipity hexahedron (3x3x3),
        linear tetrahedron (1 point) or quadratic tetrahedron (14 points). Default: what the
        mesh implies (hex8 for ``MeshHex1``, hex20 for ``MeshHex2``, tet4 for ``MeshTet1``,
        tet10 for ``MeshTet2``).
    active : ActiveContraction, optional
        Active fibre stress law (``response(F, fiber, t_max)``).
    t_max : float or dict of str to float, optional
        Activation level in kPa: a scalar, or per region (cells outside every named
        region get 0). Defaults to ``active.t_max``.
    growth : FiberGrowth or array_like of shape (ncell,), optional
        Growth along the fibres, ``F = Fe Fg`` with ``Fg = I + (θ - 1) f0 ⊗ f0``: a uniform
        law or one stretch θ per cell (dimensionless).
    boundaries : dict of str to array of int or of bool (one per facet), optional
        Named facet sets (columns of ``mesh.facets``). Defaults to the mesh's boundaries.
    volumetric : {"mean-dilatation", "linear-dilatation", "nodal-dilatation", "pointwise"}, optional
        Treatment of the volumetric energy:

        * mean dilatation: element-constant dilatation and pressure (three-field,
          locking-free; Q1/P0, Q2/P0, and P2/P0 for tet10);
        * linear dilatation: element-linear dilatation and pressure (Q2/P1-disc, hex20
          only, locking-free and optimal order). Switch to it for hex20 in bending with
          few cells through the thickness, where Q2/P0 is too soft. Q2/P0 stays the
          default: it is cheaper and the tracking scenes were tuned with it;
        * nodal dilatation (tetrahedra): the volume change averaged over the cells around
          each vertex, weighted by the vertex's linear shape function, with a continuous
          linear pressure: tet4 P1/P1 (Bonet & Burton 1998) and tet10 P2/P1 (Taylor–Hood
          with a lumped pressure mass), locking-free. For tet10 it is the accurate choice in
          bending, where P2/P0 (``"mean-dilatation"``) is first order and too soft. P2/P0
          has fewer stiffness entries (the vertex pressure couples the dofs of all cells
          around a vertex): switch to it only on fine meshes without bending, or for
          compressible materials, where the pressure lumping limits P2/P1 to the same
          L2 rate;
        * pointwise: the plain displacement formulation; locks for nearly incompressible
          materials.

        Default: the element's first locking-free one (nodal dilatation for tet4 and tet10,
        mean dilatation for the hexahedra). The user guide (workflow, step 3) compares
        them on a bending benchmark.

    Attributes
    ----------
    ndof : int
        Number of displacement dofs (3 per dof node).
    ncell, nqp : int
        Number of cells and of quadrature points per cell (8 for hex8, 27 for hex20, 1 for
        tet4, 14 for tet10).
    nodes : ndarray, shape (nvertex, 3)
        Mesh vertices, mm.
    dof_points : ndarray, shape (n_dof_nodes, 3)
        Positions of all dof nodes (vertices, then edge nodes for hex20 and tet10), mm.
    node_dofs : ndarray, shape (n_dof_nodes, 3)
        Dof ids of the x, y, z displacement of each dof node.
    cells : ndarray, shape (ncell, 8), (ncell, 20), (ncell, 4) or (ncell, 10)
        Dof-node ids per cell in VTK/meshio ``hexahedron``/``hexahedron20``/``tetra``/
        ``tetra10`` order.
    element_dofs : ndarray, shape (ncell, nbasis, 3)
        Dof ids per cell, basis function and component (assembly order).
    grad_N : ndarray, shape (ncell, nqp, nbasis, 3)
        Reference gradients ``dN_a/dX_J`` (1/mm).
    dV : ndarray, shape (ncell, nqp)
        Reference volume of each quadrature point, mm³.
    cell_volume : ndarray, shape (ncell,)
        Reference cell volumes, mm³.
    fibers_qp : ndarray, shape (ncell, nqp, 3) or None
        Unit fibres at the quadrature points.
    fibers_per : str or None
        How ``fibers`` was read ("cell", "node", "quadrature point"; two-way if ambiguous).
    t_max : ndarray, shape (ncell,) or None
        Active-stress level per cell, kPa.
    growth_tensor : ndarray, shape (ncell, nqp, 3, 3) or None
        ``Fg`` at the quadrature points.
    growth_jacobian : ndarray, shape (ncell,) or None
        Volume average of ``det Fg`` per cell.
    mesh_quality : MeshQuality or None
        Quality report of a mesh made from a segmentation
        (:func:`~harpx.anatomy.segmentation.body_from_segmentation`), else None.

    Raises
    ------
    TypeError
        If ``mesh`` is not a supported mesh (for a path or a :class:`meshio.Mesh` the
        message says how to read it).
    ValueError
        If ``element`` or ``volumetric`` does not fit the mesh; ``fibers``, ``regions`` or
        ``boundaries`` have the wrong shape or ids; a fibre material, active contraction or
        growth that needs fibres has none; or ``t_max`` is given without ``active``.

    Examples
    --------
    >>> from harpx.mechanics.body import Body
    >>> from harpx.mechanics.mesh import box
    >>> from harpx.mechanics.materials import NeoHookean
    >>> body = Body(box((1.0, 1.0, 1.0), (2, 2, 2)), NeoHookean(c1=1.0, kappa=120.0))
    >>> body.ndof, body.nqp, float(body.cell_volume.sum())
    (81, 8, 1.0)
    """

    def __init__(
        self,
        mesh: Any,
        material: Any,
        *,
        fibers: ArrayLike | Callable[[FloatArray], ArrayLike] | None = None,
        regions: Mapping[str, ArrayLike] | None = None,
        element: ElementName | None = None,
        active: Any = None,
        t_max: float | Mapping[str, float] | None = None,
        growth: Any = None,
        boundaries: Mapping[str, ArrayLike] | None = None,
        volumetric: Volumetric | None = None,
    ) -> None:
        (
            mesh,
            fibers,
            element,
            kind,
            volumetric,
            spec_regions,
            spec_boundaries,
        ) = resolve_mesh(mesh, fibers, element, volumetric)
        mesh = cast(Any, mesh)  # skfem meshes are untyped
        self._caches: dict[str, Any] = {}
        self.mesh_quality: MeshQuality | None = None
        self.mesh = mesh
        self.material = material
        self.element = element
        self.volumetric = volumetric
        self.active = active
        self.ncell = int(mesh.nelements)

        # the cells' vertices (a MeshTet2 / MeshHex2 also holds its geometry nodes in mesh.p)
        vertices = check_vertices(mesh)
        factory, intorder, nqp = kind.factory, kind.intorder, kind.nqp
        self.kind = kind
        self._scalar_element = factory()
        self._intorder = intorder
        sb = skfem.CellBasis(mesh, self._scalar_element, intorder=intorder)
        if sb.X.shape[1] != nqp:  # pragma: no cover - guards the Gauss rule choice
            raise RuntimeError(f"expected {nqp} quadrature points, skfem gave {sb.X.shape[1]}")
        self.scalar_basis = sb
        self.nqp = nqp
        self.nbasis = int(sb.Nbfun)
        grads = np.stack([sb.basis[j][0].grad for j in range(self.nbasis)])  # (nb,3,nel,nq)
        self.grad_N: FloatArray = np.ascontiguousarray(grads.transpose(2, 3, 0, 1))
        self.dV: FloatArray = np.ascontiguousarray(sb.dx)
        self.cell_volume: FloatArray = self.dV.sum(axis=1)
        self._N_values = np.stack(
            [np.asarray(sb.basis[j][0])[0] for j in range(self.nbasis)]
        )  # (nb,nq)
        cell_sdofs = np.ascontiguousarray(sb.element_dofs.T.astype(np.int64))  # (nel, nb)
        self.cell_scalar_dofs: IntArray = cell_sdofs
        self.element_dofs: IntArray = 3 * cell_sdofs[:, :, None] + np.arange(3)
        self.n_dof_nodes = int(sb.N)
        self.ndof = 3 * self.n_dof_nodes
        # a MeshHex2's face and cell geometry nodes carry no dofs: vertices only
        self.nodes: FloatArray = np.ascontiguousarray(
            vertices.T if isinstance(mesh, skfem.MeshHex2) else mesh.p.T
        )
        self.dof_points: FloatArray = np.ascontiguousarray(sb.doflocs.T)
        self.node_dofs: IntArray = 3 * np.arange(self.n_dof_nodes)[:, None] + np.arange(3)
        self.cells: IntArray = vtk_cells(mesh, kind, cell_sdofs, self.nodes, self.dof_points)
        # linear (P1) shape functions of the cell's vertices at the Gauss points: the
        # weights of the nodal dilatation (tetrahedra; skfem's reference vertices 0, e1, e2, e3)
        Xr = np.asarray(sb.X)  # (3, nqp) reference coordinates
        self.vertex_weights: FloatArray = np.ascontiguousarray(
            np.vstack([1.0 - Xr.sum(axis=0), Xr]).T
        )

        # regions and boundaries
        self.regions, self.boundaries = named_sets(
            mesh, self.ncell, regions, boundaries, spec_regions, spec_boundaries
        )

        # fibres
        self.fibers, self.fibers_qp, self.fibers_per = quadrature_fibers(fibers, sb, self.cells)
        check_fibers_given(material, active, growth, self.fibers_qp)

        # active stress level per cell
        self.t_max: FloatArray | None = None
        if active is not None:
            self.set_t_max(getattr(active, "t_max", 0.0) if t_max is None else t_max)
        elif t_max is not None:
            raise ValueError("t_max was given without an active contraction law (active=None)")

        # growth
        self.growth: Any = None
        self.growth_tensor: FloatArray | None = None
        self.growth_jacobian: FloatArray | None = None
        self.set_growth(growth)

    # ------------------------------------------------------------------ set-up helpers
    def set_t_max(self, t_max: float | Mapping[str, float] | ArrayLike) -> None:
        """Set the active-stress level.

        Parameters
        ----------
        t_max : float, dict of str to float, or array_like of shape (ncell,)
            Activation in kPa: uniform, per region (other cells 0), or per cell.

        Raises
        ------
        ValueError
            If the body has no active law, or a region name is not one of the body's.
        """
        if self.active is None:
            raise ValueError("this body has no active contraction law; pass active=... to Body")
        self.t_max = t_max_per_cell(t_max, self.regions, self.ncell)

    def set_growth(self, growth: Any) -> None:
        """Set the growth (``F = Fe Fg``), or remove it with ``None``.

        Parameters
        ----------
        growth : FiberGrowth, GrowthField, array_like of shape (ncell,), or None
            A law or field with ``tensor(fibers_qp) -> Fg`` (e.g.
            :class:`~harpx.mechanics.fiber_laws.FiberGrowth`,
            :class:`~harpx.physiology.growth.GrowthField`), or one fibre stretch θ per cell
            (``Fg = I + (θ - 1) f0 ⊗ f0``, dimensionless, > 0).

        Raises
        ------
        ValueError
            As :func:`~harpx.mechanics.body_inputs.growth_tensors`: no fibres, or a stretch
            array that is not ``ncell`` positive values.

        Notes
        -----
        Sets ``growth``, ``growth_tensor`` (ncell, nqp, 3, 3) and ``growth_jacobian``, the
        volume average of ``det Fg`` per cell (the growth Jacobian is computed here only).
        """
        if growth is None:
            self.growth, self.growth_tensor, self.growth_jacobian = None, None, None
            return
        Fg = growth_tensors(growth, self.fibers_qp, self.ncell, self.nqp)
        self.growth = growth
        self.growth_tensor = np.ascontiguousarray(Fg)
        Jg = np.linalg.det(self.growth_tensor)
        self.growth_jacobian = (Jg * self.dV).sum(axis=1) / self.cell_volume

    # ------------------------------------------------------------ read-only accessors
    @property
    def scalar_element(self) -> skfem.Element:
        """The scalar scikit-fem element (``ElementHex1`` for hex8, ``ElementHexS2`` hex20)."""
        return self._scalar_element

    @property
    def basis_values(self) -> FloatArray:
        """Shape-function values at the reference Gauss points, shape (nbasis, nqp)."""
        return self._N_values

    def cell_average(self, q: FloatArray) -> FloatArray:
        """Volume average per cell of a quadrature-point field.

        Parameters
        ----------
        q : ndarray, shape (ncell, nqp, ...)
            Values at the quadrature points (any trailing shape, e.g. (3, 3) for a tensor).

        Returns
        -------
        ndarray, shape (ncell, ...)
            ``q`` averaged over each cell, weighted by the reference volume ``dV``.
        """
        w = self.dV / self.cell_volume[:, None]
        return np.einsum("eq,eq...->e...", w, q)

    def cached(self, key: str, build: Callable[[], _T]) -> _T:
        """Derived data kept with the body (sparsity pattern, pressure space), built once.

        Parameters
        ----------
        key : str
            Name of the cached item.
        build : callable
            ``build()`` computes it the first time.

        Returns
        -------
        object
            The cached item.
        """
        if key not in self._caches:
            self._caches[key] = build()
        return self._caches[key]

    @functools.cached_property
    def basis(self) -> skfem.CellBasis:
        """``skfem.CellBasis`` of ``ElementVector`` on the body's Gauss rule (built on demand)."""
        return skfem.CellBasis(
            self.mesh, skfem.ElementVector(self._scalar_element), intorder=self._intorder
        )

    @property
    def quadrature_points(self) -> FloatArray:
        """Reference positions of the quadrature points, shape (ncell, nqp, 3), mm."""
        return np.ascontiguousarray(
            np.asarray(self.scalar_basis.global_coordinates()).transpose(1, 2, 0)
        )

    # ------------------------------------------------------------------ field helpers
    def _check_u(self, u: ArrayLike) -> FloatArray:
        u = np.asarray(u, dtype=np.float64)
        if u.shape != (self.ndof,):
            raise ValueError(f"u has shape {u.shape!r}; expected ({self.ndof},) dofs")
        return u

    def nodal_displacement(self, u: ArrayLike) -> FloatArray:
        """Displacement of every dof node.

        Parameters
        ----------
        u : array_like, shape (ndof,)
            Displacement dofs, mm.

        Returns
        -------
        ndarray, shape (n_dof_nodes, 3)
            x, y, z displacement of each dof node (rows as in ``dof_points``), mm.
        """
        return self._check_u(u).reshape(-1, 3)

    def facet_dofs(self, name: str | ArrayLike, components: Sequence[int] = (0, 1, 2)) -> IntArray:
        """Dof ids on a named boundary (or on given facet ids).

        Parameters
        ----------
        name : str, array_like of int or array_like of bool
            Boundary name from ``body.boundaries``, facet ids or a mask over the facets.
        components : sequence of int, default (0, 1, 2)
            Displacement components (0 = x, 1 = y, 2 = z).

        Returns
        -------
        ndarray of int
            Sorted dof ids.

        Raises
        ------
        KeyError, ValueError
            As :meth:`facets`; ValueError also for ``components`` outside (0, 1, 2).
        """
        facets = self.facets(name)
        sd = np.unique(self.scalar_basis.get_dofs(facets=facets).all())
        comps = np.asarray(components, dtype=np.int64)
        if comps.size == 0 or comps.min() < 0 or comps.max() > 2:
            raise ValueError(f"components={components!r} must be a non-empty subset of (0, 1, 2)")
        return np.sort((3 * sd[:, None] + comps[None, :]).ravel())

    def facets(self, name: str | ArrayLike) -> IntArray:
        """Facet ids of a named boundary (or the given ids, checked).

        Parameters
        ----------
        name : str, array_like of int or array_like of bool
            Boundary name from ``body.boundaries``, facet ids (columns of ``mesh.facets``)
            or a boolean mask with one entry per facet.

        Returns
        -------
        ndarray of int, shape (nfacet,)
            The facet ids.

        Raises
        ------
        KeyError
            If ``name`` is a string that names no boundary.
        ValueError
            If the ids are not valid facet indices nor a mask of one entry per facet.
        """
        return facet_ids(self.boundaries, int(self.mesh.facets.shape[1]), name)

    def element_displacement(self, u: ArrayLike) -> FloatArray:
        """Displacement of each cell's dof nodes.

        Parameters
        ----------
        u : array_like, shape (ndof,)
            Displacement dofs, mm.

        Returns
        -------
        ndarray, shape (ncell, nbasis, 3)
            Displacement per cell, basis function and component (order of
            ``element_dofs``), mm.
        """
        return self._check_u(u)[self.element_dofs]

    def deformation_gradient(self, u: ArrayLike) -> FloatArray:
        """Deformation gradient ``F = I + Grad u`` at every quadrature point.

        Parameters
        ----------
        u : array_like, shape (ndof,)
            Displacement dofs, mm.

        Returns
        -------
        ndarray, shape (ncell, nqp, 3, 3)
            ``F[..., i, J] = dx_i/dX_J`` (dimensionless).
        """
        ue = self.element_displacement(u)
        F = np.einsum("eai,eqaJ->eqiJ", ue, self.grad_N, optimize=True)
        F += np.eye(3)
        return F

    def jacobian(self, u: ArrayLike) -> FloatArray:
        """Volume ratio ``J = det F`` at every quadrature point.

        Parameters
        ----------
        u : array_like, shape (ndof,)
            Displacement dofs, mm.

        Returns
        -------
        ndarray, shape (ncell, nqp)
            ``det F`` (dimensionless).
        """
        return np.linalg.det(self.deformation_gradient(u))

    def displacement_at(self, u: ArrayLike, points: ArrayLike) -> FloatArray:
        """Displacement (mm) at arbitrary reference points (mm), NaN outside the mesh.

        Parameters
        ----------
        u, points : see :func:`harpx.mechanics.locate.displacement_at`
            Displacement dofs (one frame or several) and reference positions, mm.

        Returns
        -------
        ndarray
            As :func:`harpx.mechanics.locate.displacement_at` returns it.
        """
        from harpx.mechanics.locate import displacement_at

        return displacement_at(self, u, points)

    def green_strain(self, u: ArrayLike) -> FloatArray:
        """Volume-averaged Green--Lagrange strain per cell.

        Parameters
        ----------
        u : array_like, shape (ndof,)
            Displacement dofs, mm.

        Returns
        -------
        ndarray, shape (ncell, 3, 3)
            ``E = (F^T F - I) / 2`` averaged over each cell (dimensionless).
        """
        return self.cell_average(kinematics.green_strain(self.deformation_gradient(u)))

    def fiber_stretch(self, u: ArrayLike) -> FloatArray:
        """Volume-averaged fibre stretch ``|F f0|`` per cell.

        Parameters
        ----------
        u : array_like, shape (ndof,)
            Displacement dofs, mm.

        Returns
        -------
        ndarray, shape (ncell,)
            Fibre stretch averaged over each cell (dimensionless, 1 undeformed).

        Raises
        ------
        ValueError
            If the body has no fibres.
        """
        if self.fibers_qp is None:
            raise ValueError("fiber_stretch needs 'fibers'; pass fibers=... to Body")
        lam = kinematics.fiber_stretch(self.deformation_gradient(u), self.fibers_qp)
        return self.cell_average(lam)

    def interpolation_operator(
        self, intorder: int
    ) -> tuple[FloatArray, FloatArray, sparse.csr_matrix]:
        """Quadrature points, weights and the displacement interpolation matrix.

        Parameters
        ----------
        intorder : int
            skfem integration order (polynomial degree integrated exactly); Gauss rules
            with ``n`` points per direction have order ``2n - 1``.

        Returns
        -------
        X_q : ndarray, shape (nq, 3)
            Reference positions of the points, cell-major (all points of cell 0 first), mm.
        w_q : ndarray, shape (nq,)
            Reference volume of each point, mm³ (sums to the body volume).
        N : scipy.sparse.csr_matrix, shape (3 nq, ndof)
            ``(N @ u).reshape(nq, 3)`` is the displacement at ``X_q``, mm.
        """
        b = skfem.CellBasis(self.mesh, self._scalar_element, intorder=int(intorder))
        npt = b.X.shape[1]
        X_q = np.asarray(b.global_coordinates()).transpose(1, 2, 0).reshape(-1, 3)
        w_q = np.asarray(b.dx, dtype=np.float64).ravel()
        phi = np.stack(
            [np.asarray(b.basis[j][0]) for j in range(self.nbasis)], axis=-1
        )  # (nel,nq,nb)
        nq = self.ncell * npt
        rows = (
            3 * np.arange(nq).reshape(self.ncell, npt)[:, :, None, None]
            + np.arange(3)[None, None, None, :]
        )
        cols = 3 * self.cell_scalar_dofs[:, None, :, None] + np.arange(3)[None, None, None, :]
        rows, cols = np.broadcast_arrays(rows, cols)
        vals = np.broadcast_to(phi[..., None], rows.shape)
        N = sparse.csr_matrix(
            (vals.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * nq, self.ndof)
        )
        return np.ascontiguousarray(X_q), w_q, N

    # ------------------------------------------------------------------ I/O
    def to_meshio(
        self, u: ArrayLike | None = None, *, point_data: Mapping[str, ArrayLike] | None = None
    ) -> meshio.Mesh:
        """The mesh (hexahedron or tetra cells) as a :class:`meshio.Mesh`.

        Parameters
        ----------
        u : array_like, shape (ndof,), optional
            Displacement (mm), written as point data ``"displacement"`` at the vertices.
        point_data : dict, optional
            Extra point data (one row per vertex).

        Returns
        -------
        meshio.Mesh
            Named boundaries and regions are encoded as skfem cell data; fibres (per cell) as
            cell data ``"fiber"``. Curved hexahedra (``MeshHex2``) are written by their
            vertices (``hexahedron``): the curved geometry is not kept.
        """
        pdata = dict(point_data or {})
        if u is not None:
            pdata["displacement"] = self.nodal_displacement(u)[: self.nodes.shape[0]]
        cdata: dict[str, list[Any]] = {}
        if self.fibers is not None and self.fibers.shape == (self.ncell, 3):
            cdata["fiber"] = [self.fibers]
        mesh = self.mesh
        if isinstance(mesh, skfem.MeshHex2):  # the vertices only: straight hexahedra
            mesh = skfem.MeshHex1(np.ascontiguousarray(self.nodes.T), mesh.t)
        if self.regions or self.boundaries:
            mesh = dataclasses.replace(
                mesh,
                _boundaries={k: v.astype(np.int32) for k, v in self.boundaries.items()} or None,
                _subdomains={k: v.astype(np.int32) for k, v in self.regions.items()} or None,
            )
        return skfem.io.meshio.to_meshio(mesh, point_data=pdata or None, cell_data=cdata)

    @classmethod
    def from_meshio(
        cls, mesh: meshio.Mesh, material: Any, *, source: str = "the meshio mesh", **kwargs: Any
    ) -> Body:
        """Build a body from a :class:`meshio.Mesh` (the inverse of :meth:`to_meshio`).

        Parameters
        ----------
        mesh : meshio.Mesh
            Reference configuration (mm) with ``hexahedron``, ``hexahedron20`` (reduced to
            its corners: straight edges), ``tetra`` or ``tetra10`` (curved edges kept)
            cells, all of one of these kinds; several blocks of that kind are merged in
            block order, while surface and line blocks (boundaries) and points no cell uses
            are dropped. Cell data ``fiber`` (one vector per cell) becomes the fibres
            unless ``fibers=`` is given; named regions and boundaries are kept (those
            :meth:`to_meshio` writes, cell sets, named gmsh physical groups, ``region``
            labels), names that cannot be mapped are warned about (HarpxWarning).
        material : object
            The material (see :class:`Body`).
        source : str, default "the meshio mesh"
            What the mesh is called in error messages (e.g. its file name).
        **kwargs
            Further :class:`Body` parameters (``element``, ``fibers``, ...).

        Returns
        -------
        Body

        Raises
        ------
        ValueError
            If the mesh has no hexahedra or tetrahedra, or volume cells of several kinds
            (e.g. hexahedra and a tetrahedron; the message counts each kind), or inverted
            or collapsed cells (named, with a hint at the node order).

        See Also
        --------
        harpx.io.mesh.read_body : reads a mesh file into a Body.

        Examples
        --------
        >>> from harpx.mechanics.mesh import box
        >>> from harpx.mechanics.materials import NeoHookean
        >>> body = Body(box((1.0, 1.0, 1.0), (2, 2, 2)), NeoHookean(c1=1.0, kappa=120.0))
        >>> back = Body.from_meshio(body.to_meshio(), body.material)
        >>> bool((back.nodes == body.nodes).all()), back.ncell
        (True, 8)
        """
        skmesh, fibers = _skfem_mesh(mesh, source)
        if kwargs.get("fibers") is None:
            kwargs["fibers"] = fibers
        return cls(skmesh, material, **kwargs)

    def __repr__(self) -> str:
        return (
            f"Body({self.element}, ncell={self.ncell}, ndof={self.ndof}, "
            f"material={type(self.material).__name__}, volumetric={self.volumetric!r})"
        )


__getattr__ = moved_getattr(__name__)
