r"""Boundary conditions and loads, and the protocol for additional residual terms.

Two kinds of objects go into the ``loads`` list of :func:`harpx.mechanics.newton.solve`:

* **Dirichlet conditions** (:class:`Fixed`, :class:`Prescribed`) provide
  ``dofs(body) -> ndarray of int`` and ``values(body, s) -> ndarray`` (mm) at load factor
  ``s`` in [0, 1]. The solver applies them by elimination on the fixed sparsity pattern
  (rows and columns zeroed, unit diagonal), moving the prescribed values incrementally.
* **Residual terms** follow :class:`ResidualTerm`: any object with
  ``residual_tangent(body, u, s) -> (r, K)`` where ``r`` (ndof,) is the term's contribution
  to the residual :math:`R(u) = f_{int}(u) - f_{ext}(u)` — i.e. *minus* the external force,
  in mN (kPa·mm²) — and ``K = ∂r/∂u`` is a ``scipy.sparse`` matrix (ndof, ndof) or None
  (dead loads). A term whose tangent lies in the body's stiffness pattern should build it
  with ``harpx.mechanics.assembly.sparsity(body).matrix(data)`` (positions from
  ``sparsity(body).positions(rows, cols)``): the solver then adds it in place, without a
  sparse-matrix merge and without a new symbolic factorisation. The tracking constraint
  plugs in through exactly this protocol.

Follower pressure
-----------------
On a facet with reference outward normal :math:`N`, Nanson's formula gives the deformed
area vector :math:`n\, da = \operatorname{cof}F\, N\, dA`. A pressure :math:`p` (kPa, > 0
pushes against the outward normal) contributes

.. math::

    r_{ai} = p \int_\Gamma N_a (\operatorname{cof}F)_{iJ} N_J\, dA, \qquad
    K_{ai,bk} = p \int_\Gamma N_a\, \epsilon_{ikm}\, (F_{m\cdot} \times N)_L\,
    \partial_L N_b\, dA ,

using :math:`\partial(\operatorname{cof}F)_{iJ}/\partial F_{kL} = \epsilon_{ikm}
\epsilon_{JLM} F_{mM}`; :math:`\operatorname{cof}F\,N` involves only tangential derivatives,
so traces of the cell gradients are exact. The tangent is not symmetric (follower load).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
import skfem
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.sparse import csgraph

from harpx._typing import FloatArray, IntArray
from harpx.errors import HarpxError
from harpx.mechanics import kinematics
from harpx.mechanics.assembly import sparsity
from harpx.mechanics.linsolve import rigid_body_modes

if TYPE_CHECKING:
    from harpx.mechanics.body import Body

__all__ = [
    "BodyForce",
    "Dirichlet",
    "EmptyBoundaryError",
    "Fixed",
    "Prescribed",
    "Pressure",
    "ResidualTerm",
    "dirichlet_values",
    "free_rigid_motions",
    "mesh_pieces",
    "split_loads",
    "unheld_note",
]

_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0


@runtime_checkable
class ResidualTerm(Protocol):
    """Protocol of an additional residual term (pressure, body force, tracking, ...).

    Any object with a matching ``residual_tangent`` method is a residual term
    (``isinstance(obj, ResidualTerm)`` checks for the method); the protocol itself is not
    instantiated.
    """

    def residual_tangent(
        self, body: Body, u: FloatArray, s: float
    ) -> tuple[FloatArray, sparse.spmatrix | None]:
        """Contribution ``r`` to ``R = f_int - f_ext`` and its tangent ``K = ∂r/∂u``.

        Parameters
        ----------
        body : Body
            The body being solved.
        u : ndarray, shape (ndof,)
            Current displacement dofs, mm.
        s : float
            Load factor in [0, 1] (dimensionless).

        Returns
        -------
        r : ndarray, shape (ndof,)
            The term's residual contribution (minus its external force), mN.
        K : scipy.sparse matrix, shape (ndof, ndof), or None
            ``∂r/∂u`` (mN/mm), preferably on the body's stiffness pattern; None if ``r``
            does not depend on ``u`` (dead load).
        """
        ...


@runtime_checkable
class Dirichlet(Protocol):
    """Protocol of a Dirichlet condition.

    Any object with matching ``dofs`` and ``values`` methods is a Dirichlet condition
    (e.g. :class:`Fixed`, :class:`Prescribed`); the protocol itself is not instantiated.
    """

    def dofs(self, body: Body) -> IntArray:
        """Constrained dof ids.

        Parameters
        ----------
        body : Body
            The body the condition applies to.

        Returns
        -------
        ndarray of int
            Ids of the constrained displacement dofs.
        """
        ...

    def values(self, body: Body, s: float) -> FloatArray:
        """Prescribed displacement of ``dofs(body)`` at load factor ``s``.

        Parameters
        ----------
        body : Body
            The body the condition applies to.
        s : float
            Load factor in [0, 1] (dimensionless).

        Returns
        -------
        ndarray, shape (ndofs,)
            Displacement of each dof of ``dofs(body)``, in that order, mm.
        """
        ...


class EmptyBoundaryError(HarpxError, ValueError):
    """A condition or load names a boundary that has no facet: it would act on nothing."""


def _facets(body: Body, facet: Any, what: str) -> IntArray:
    """Facet ids of ``facet``, refusing a named boundary without facets."""
    facets = body.facets(facet)
    if isinstance(facet, str) and facets.size == 0:
        filled = sorted(k for k, v in body.boundaries.items() if len(v))
        empty = sorted(k for k, v in body.boundaries.items() if not len(v))
        raise EmptyBoundaryError(
            f"{what} on boundary {facet!r}, which has no facets (empty boundaries: {empty!r}); "
            f"it would constrain nothing. Non-empty boundaries: {filled!r}; name one of them, "
            "or check how the boundary was built (e.g. a predicate that matched nothing)"
        )
    return facets


def _components(components: Sequence[int]) -> tuple[int, ...]:
    comps = tuple(int(c) for c in components)
    if not comps or any(c not in (0, 1, 2) for c in comps) or len(set(comps)) != len(comps):
        raise ValueError(f"components={components!r} must be distinct values from (0, 1, 2)")
    return comps


class _BoundaryDofs:
    """Some displacement components on a boundary: what :class:`Fixed` and
    :class:`Prescribed` share (their ``facet`` and ``components`` fields)."""

    facet: Any
    components: tuple[int, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "components", _components(self.components))

    def dofs(self, body: Body) -> IntArray:
        """Constrained dof ids.

        Raises
        ------
        EmptyBoundaryError
            If ``facet`` names a boundary without facets.
        """
        facets = _facets(body, self.facet, type(self).__name__)
        return body.facet_dofs(facets, self.components)


@dataclass(frozen=True)
class Fixed(_BoundaryDofs):
    """Zero displacement of some components on a boundary.

    Parameters
    ----------
    facet : str or array_like of int
        Boundary name (``body.boundaries``) or facet ids.
    components : sequence of int, default (0, 1, 2)
        Constrained components (0 = x, 1 = y, 2 = z).
    """

    facet: Any
    components: tuple[int, ...] = (0, 1, 2)

    def values(self, body: Body, s: float) -> FloatArray:
        """Prescribed values of ``dofs(body)``: zeros.

        Parameters
        ----------
        body : Body
            The body the condition applies to.
        s : float
            Load factor in [0, 1] (dimensionless; not used).

        Returns
        -------
        ndarray, shape (ndofs,)
            Zeros, one per dof of ``dofs(body)``, mm.

        Raises
        ------
        EmptyBoundaryError
            If ``facet`` names a boundary without facets.
        """
        return np.zeros(self.dofs(body).size)


@dataclass(frozen=True)
class Prescribed(_BoundaryDofs):
    """Prescribed displacement on a boundary.

    Parameters
    ----------
    facet : str or array_like of int
        Boundary name or facet ids.
    displacement : callable
        ``displacement(X, s) -> (n, 3)`` in mm for reference points ``X`` (n, 3) in mm and
        load factor ``s`` in [0, 1]; it should vanish at ``s = 0`` when starting from rest.
    components : sequence of int, default (0, 1, 2)
        Components taken from ``displacement``.

    Examples
    --------
    >>> from harpx.mechanics.loads import Prescribed
    >>> pull = Prescribed("right", lambda X, s: np.column_stack(
    ...     [0.1 * s * np.ones(len(X)), 0 * X[:, 1], 0 * X[:, 2]]), components=(0,))
    """

    facet: Any
    displacement: Callable[[FloatArray, float], ArrayLike]
    components: tuple[int, ...] = (0, 1, 2)

    def values(self, body: Body, s: float) -> FloatArray:
        """Prescribed values of ``dofs(body)`` at load factor ``s``.

        Parameters
        ----------
        body : Body
            The body the condition applies to.
        s : float
            Load factor in [0, 1] (dimensionless), passed to ``displacement``.

        Returns
        -------
        ndarray, shape (ndofs,)
            The component of ``displacement(X, s)`` at each dof of ``dofs(body)`` (in that
            order), ``X`` the reference position of its dof node, mm.

        Raises
        ------
        EmptyBoundaryError
            If ``facet`` names a boundary without facets.
        ValueError
            If ``displacement`` does not return shape (n, 3).
        """
        dofs = self.dofs(body)
        nodes = dofs // 3
        X = body.dof_points[nodes]
        d = np.asarray(self.displacement(X, float(s)), dtype=np.float64)
        if d.shape != (len(X), 3):
            raise ValueError(
                f"Prescribed displacement returned shape {d.shape!r}; expected ({len(X)}, 3) mm"
            )
        return d[np.arange(len(X)), dofs % 3]


@dataclass(frozen=True)
class _FacetQuadrature:
    phi: FloatArray  # (nf, nq, nb)
    grad: FloatArray  # (nf, nq, nb, 3)
    normal: FloatArray  # (nf, nq, 3) reference outward unit normal
    dA: FloatArray  # (nf, nq) reference area weights, mm²
    dofs: IntArray  # (nf, nb, 3)
    positions: IntArray  # (nf, nb, 3, 3, nb) CSR positions in the body pattern


def _facet_quadrature(body: Body, facet: Any) -> _FacetQuadrature:
    cache = body.__dict__.setdefault("_facet_quadrature", {})
    facets = _facets(body, facet, "Pressure")
    key = facets.tobytes()
    if key in cache:
        return cache[key]
    order = body.kind.facet_intorder
    fb = skfem.FacetBasis(
        body.mesh, body.scalar_element, facets=facets.astype(np.int32), intorder=order
    )
    nb = body.nbasis
    phi = np.stack([np.asarray(fb.basis[j][0]) for j in range(nb)], axis=-1)
    grad = np.stack([fb.basis[j][0].grad for j in range(nb)]).transpose(2, 3, 0, 1)
    normal = np.asarray(fb.normals).transpose(1, 2, 0)
    sd = fb.element_dofs.T.astype(np.int64)  # (nf, nb)
    dofs = 3 * sd[:, :, None] + np.arange(3)
    rows = np.broadcast_to(dofs[:, :, :, None, None], dofs.shape + (3, nb))
    cols = np.broadcast_to(dofs.transpose(0, 2, 1)[:, None, None, :, :], rows.shape)
    pos = sparsity(body).positions(rows, cols)
    q = _FacetQuadrature(
        np.ascontiguousarray(phi),
        np.ascontiguousarray(grad),
        np.ascontiguousarray(normal),
        np.asarray(fb.dx),
        dofs,
        pos,
    )
    cache[key] = q
    return q


@dataclass(frozen=True)
class Pressure:
    """Follower pressure on a boundary (acts on the deformed surface).

    Parameters
    ----------
    facet : str or array_like of int
        Boundary name or facet ids.
    pressure : float or callable
        Pressure in kPa at full load (positive pushes against the outward normal, i.e.
        into the body), scaled by the load factor ``s``; or ``pressure(s) -> kPa``.
    """

    facet: Any
    pressure: float | Callable[[float], float]

    def value(self, s: float) -> float:
        """Pressure at load factor ``s``.

        Parameters
        ----------
        s : float
            Load factor in [0, 1] (dimensionless).

        Returns
        -------
        float
            ``s * pressure``, or ``pressure(s)`` for a callable, kPa.
        """
        if callable(self.pressure):
            return float(self.pressure(s))
        return float(s) * float(self.pressure)

    def residual_tangent(
        self, body: Body, u: FloatArray, s: float
    ) -> tuple[FloatArray, sparse.csr_matrix]:
        """Residual contribution and consistent (non-symmetric) tangent.

        Parameters
        ----------
        body, u, s : see :meth:`ResidualTerm.residual_tangent`
            The body, the current displacement dofs (mm) and the load factor.

        Returns
        -------
        r : ndarray, shape (ndof,)
            Minus the pressure's nodal force on the deformed facets, mN.
        K : scipy.sparse.csr_matrix, shape (ndof, ndof)
            ``∂r/∂u`` on the body's stiffness pattern, mN/mm.

        Raises
        ------
        EmptyBoundaryError
            If ``facet`` names a boundary without facets.
        """
        q = _facet_quadrature(body, self.facet)
        p = self.value(s)
        ue = np.asarray(u)[q.dofs]  # (nf, nb, 3)
        F = np.einsum("fai,fqaJ->fqiJ", ue, q.grad) + np.eye(3)
        cof = kinematics.cofactor(F)
        t = np.einsum("fqiJ,fqJ->fqi", cof, q.normal) * (p * q.dA)[..., None]
        re = np.einsum("fqa,fqi->fai", q.phi, t)
        r = np.asarray(
            np.bincount(q.dofs.ravel(), weights=re.ravel(), minlength=body.ndof), dtype=np.float64
        )
        w = np.cross(F, q.normal[:, :, None, :])  # (nf, nq, m, L) = F_m x N
        T = np.einsum("ikm,fqmL->fqikL", _EPS, w)
        C = np.einsum("fqikL,fqbL->fqikb", T, q.grad)
        Ke = np.einsum("fqa,fqikb->faikb", q.phi * (p * q.dA)[..., None], C)
        pat = sparsity(body)
        data = np.asarray(
            np.bincount(q.positions.ravel(), weights=Ke.ravel(), minlength=pat.nnz),
            dtype=np.float64,
        )
        return r, pat.matrix(data)


@dataclass(frozen=True)
class BodyForce:
    """Dead body force per unit reference volume.

    Parameters
    ----------
    force : array_like of shape (3,) or callable
        Force density in mN/mm³ (= kPa/mm) at full load, scaled by ``s``; or
        ``force(X, s) -> (n, 3)`` for reference points ``X`` (n, 3) in mm.
    """

    force: Any = field(default_factory=lambda: np.zeros(3))

    def residual_tangent(self, body: Body, u: FloatArray, s: float) -> tuple[FloatArray, None]:
        """Residual contribution ``-∫ N_a b dV``; the tangent is zero (None).

        Parameters
        ----------
        body, u, s : see :meth:`ResidualTerm.residual_tangent`
            The body, the displacement dofs (not used: a dead load) and the load factor.

        Returns
        -------
        r : ndarray, shape (ndof,)
            Minus the nodal body force, mN.
        K : None
            The load does not depend on ``u``.
        """
        cache = body.__dict__.setdefault("_body_force_quadrature", {})
        if "X" not in cache:
            cache["X"] = body.quadrature_points
        X = cache["X"]
        if callable(self.force):
            b = np.asarray(self.force(X.reshape(-1, 3), float(s)), dtype=np.float64)
            b = b.reshape(X.shape)
        else:
            b = float(s) * np.broadcast_to(np.asarray(self.force, dtype=np.float64), X.shape)
        re = np.einsum("qa,eqi,eq->eai", body.basis_values.T, b, body.dV)
        r = -np.asarray(
            np.bincount(body.element_dofs.ravel(), weights=re.ravel(), minlength=body.ndof),
            dtype=np.float64,
        )
        return r, None


def split_loads(loads: Iterable[Any]) -> tuple[list[Any], list[Any]]:
    """Split a loads list into Dirichlet conditions and residual terms.

    Parameters
    ----------
    loads : iterable
        Objects with ``dofs``/``values`` (Dirichlet) or ``residual_tangent`` (terms).

    Returns
    -------
    dirichlet, terms : list
        The Dirichlet conditions and the residual terms, each in the order given (an
        object with ``residual_tangent`` is a term even if it also has ``dofs``).

    Raises
    ------
    TypeError
        If an object is neither.
    """
    dirichlet, terms = [], []
    for load in loads:
        if hasattr(load, "residual_tangent"):
            terms.append(load)
        elif hasattr(load, "dofs") and hasattr(load, "values"):
            dirichlet.append(load)
        else:
            raise TypeError(
                f"load {load!r} is neither a Dirichlet condition (dofs/values) nor a residual "
                "term (residual_tangent(body, u, s)); see harpx.mechanics.loads"
            )
    return dirichlet, terms


def dirichlet_values(body: Body, dirichlet: Sequence[Any], s: float) -> FloatArray:
    """Prescribed displacement of every dof at load factor ``s`` (zero where none is).

    Parameters
    ----------
    body : Body
        The body.
    dirichlet : sequence of Dirichlet
        The Dirichlet conditions (``dofs(body)``, ``values(body, s)``).
    s : float
        Load factor in [0, 1].

    Returns
    -------
    ndarray, shape (ndof,)
        Displacement, mm.

    Raises
    ------
    ValueError
        If two conditions prescribe values more than 1e-9 mm (relative to the value) apart
        on a dof they share: which one held would depend on their order in ``loads``. The
        message names both conditions, how many dofs clash and one of them.
    """
    g = np.zeros(body.ndof)
    owner = np.full(body.ndof, -1)
    for k, condition in enumerate(dirichlet):  # a few conditions
        dofs = np.asarray(condition.dofs(body), dtype=np.int64)
        values = np.broadcast_to(np.asarray(condition.values(body, s), np.float64), dofs.shape)
        clash = (owner[dofs] >= 0) & (np.abs(g[dofs] - values) > 1e-9 * (1.0 + np.abs(values)))
        if clash.any():
            i = int(np.flatnonzero(clash)[0])
            dof = int(dofs[i])
            raise ValueError(
                f"the Dirichlet conditions {_label(dirichlet[owner[dof]])} and "
                f"{_label(condition)} prescribe different displacements on "
                f"{int(np.count_nonzero(clash))} dofs they share at load factor {s:g} (dof "
                f"{dof}, node {dof // 3} component {'xyz'[dof % 3]}: {g[dof]:.6g} against "
                f"{values[i]:.6g} mm), so which holds would depend on their order: make them "
                "agree there, or keep them apart (a narrower boundary or fewer components)"
            )
        g[dofs] = values
        owner[dofs] = k
    return g


def _label(condition: Any) -> str:
    """``Fixed('bottom')``, or the class name and facet count of facet ids."""
    facet = getattr(condition, "facet", None)
    if facet is None:
        return repr(condition)
    where = repr(facet) if isinstance(facet, str) else f"{np.size(facet)} facets"
    return f"{type(condition).__name__}({where})"


def free_rigid_motions(body: Body, dofs: ArrayLike) -> int:
    """How many of the six rigid-body motions the fixed ``dofs`` leave free.

    Parameters
    ----------
    body : Body
        The body.
    dofs : array_like of int
        The dofs held by Dirichlet conditions.

    Returns
    -------
    int
        6 minus the rank of the rigid-body modes restricted to ``dofs`` (0: the body is held;
        6: nothing holds it). Without a residual term that holds the body, a free motion
        makes the tangent singular. The body is taken as one piece; see
        :func:`unheld_note` for a mesh in several.
    """
    return _free_motions(body.dof_points, np.asarray(dofs, dtype=np.int64))


def _free_motions(points: FloatArray, held: IntArray) -> int:
    """6 minus the rank of the rigid-body modes of nodes ``points`` at the ``held`` dofs."""
    modes = rigid_body_modes(points)
    extent = float(np.ptp(points, axis=0).max())
    modes[:, 3:] /= max(extent, np.finfo(float).tiny)  # rotations on the translations' scale
    return 6 - (int(np.linalg.matrix_rank(modes[held])) if held.size else 0)


def mesh_pieces(body: Body) -> IntArray:
    """Label of the connected piece of the mesh that every dof belongs to.

    Parameters
    ----------
    body : Body
        The body whose mesh is split into pieces.

    Returns
    -------
    ndarray of int, shape (ndof,)
        0, 1, ... per piece (cells that share a node are connected); a mesh in one piece
        gives zeros.
    """
    cell_dofs = body.element_dofs.reshape(body.element_dofs.shape[0], -1)
    rows = np.repeat(cell_dofs[:, 0], cell_dofs.shape[1])
    links = sparse.coo_matrix(
        (np.ones(rows.size, dtype=np.int8), (rows, cell_dofs.ravel())),
        shape=(body.ndof, body.ndof),
    )
    return np.asarray(csgraph.connected_components(links, directed=False)[1], dtype=np.int64)


def unheld_note(body: Body, dofs: ArrayLike) -> str:
    """For a failure message: the rigid-body motions the held ``dofs`` leave free.

    Parameters
    ----------
    body : Body
        The body, as for :func:`free_rigid_motions`.
    dofs : array_like of int
        The held dofs, as for :func:`free_rigid_motions`.

    Returns
    -------
    str
        ``""`` when every connected piece of the mesh is held; else a clause (starting
        with "; ") that counts the free motions, and for a mesh in several pieces names
        the pieces nothing holds by their first cell.
    """
    held = np.asarray(dofs, dtype=np.int64)
    labels = mesh_pieces(body)
    npiece = int(labels.max()) + 1
    if npiece == 1:
        free = _free_motions(body.dof_points, held)
        return (
            f"; the Dirichlet conditions leave {free} of the 6 rigid-body motions free, so the "
            "tangent is singular: hold the body (e.g. Fixed on a boundary)"
            if free
            else ""
        )
    loose = []
    for k in range(npiece):  # the pieces of the mesh, in a failure message only
        piece = np.flatnonzero(labels == k)  # its dofs, 3 per node in node order
        mine = np.searchsorted(piece, held[labels[held] == k])
        free = _free_motions(body.dof_points[piece[::3] // 3], mine)
        if free:
            first = int(np.flatnonzero(labels[body.element_dofs[:, 0, 0]] == k)[0])
            loose.append(f"the piece with cell {first} ({free} of 6 motions free)")
    if not loose:
        return ""
    return (
        f"; the mesh is in {npiece} disconnected pieces and the Dirichlet conditions do not "
        f"hold {len(loose)} of them, so the tangent is singular: "
        f"{', '.join(loose[:5])}{' …' if len(loose) > 5 else ''}; hold every piece, or "
        "check the mesh (pieces that should share nodes)"
    )
