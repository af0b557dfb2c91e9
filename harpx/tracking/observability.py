"""Which directions of motion the tags can see, and the rigid-body modes they cannot.

A tag with wave vector :math:`k_t` measures only the component :math:`k_t \\cdot u` of the
motion: its phase :math:`\\phi_t(x) = k_t \\cdot X` is unchanged when a material point moves
perpendicular to :math:`k_t`. At a constraint point that lies in the data of the tags
:math:`T(X)`, the *seen* subspace is the span of their directions,

.. math::

    S(X) = \\operatorname{span}\\{\\hat k_t : t \\in T(X)\\}, \\qquad
    P(X) = \\text{orthogonal projector onto } S(X),

so short-axis slices with x and y tags see the plane z = const and nothing along z, and a
region imaged by long-axis slices with a z tag only sees z. Motion along a direction outside
:math:`S(X)` comes from the mechanics alone. The phase force is therefore applied through
:math:`P(X)` (the through-plane component of an in-plane tag's image gradient comes from
interpolation across slices, not from a measurement), and the rigid-body modes
:math:`r(X) = a + \\omega \\times X` for which :math:`P(X)\\, r(X) = 0` at every point (and which
no Dirichlet condition holds) are exact null modes of the tracking problem: the stored energy
and the data are both blind to them. They are removed explicitly, by holding their
mass-weighted amplitude at its reference value of zero, never left to the linear solver's
null space or to round-off.

For x and y tags only, the removed mode is the translation along z; for a single x tag, the
translations along y and z and the rotation about x.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import numpy as np

from harpx._typing import BoolArray, FloatArray, IntArray

if TYPE_CHECKING:
    from harpx.mechanics.body import Body

__all__ = [
    "Observability",
    "UNSEEN_TOLERANCE",
    "describe_direction",
    "observability",
    "rigid_modes",
    "seen_projectors",
]

#: Eigenvalues of the normalised rigid-mode Gram matrix below this count as unseen.
UNSEEN_TOLERANCE = 1e-8


def seen_projectors(directions: FloatArray, valid: np.ndarray) -> tuple[FloatArray, IntArray]:
    """Projector onto the span of the tag directions that have data, per point.

    Parameters
    ----------
    directions : ndarray, shape (ntag, 3)
        Unit tag directions (x, y, z components).
    valid : ndarray of bool, shape (npoint, ntag)
        Which tags have data at each point.

    Returns
    -------
    projectors : ndarray, shape (npoint, 3, 3)
        Orthogonal projector onto the seen subspace at each point (dimensionless).
    rank : ndarray of int, shape (npoint,)
        Number of independent seen directions (0 to 3).

    Examples
    --------
    >>> d = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    >>> P, rank = seen_projectors(d, np.array([[True, True], [True, False]]))
    >>> np.diag(P[0]).tolist(), np.diag(P[1]).tolist(), rank.tolist()
    ([1.0, 1.0, 0.0], [1.0, 0.0, 0.0], [2, 1])
    """
    directions = np.asarray(directions, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool)
    ntag = directions.shape[0]
    # the few distinct valid-tag patterns (at most 2**ntag), one small eigenproblem each
    code = valid.astype(np.int64) @ (1 << np.arange(ntag, dtype=np.int64))
    patterns, inverse = np.unique(code, return_inverse=True)
    table = np.zeros((patterns.size, 3, 3))
    ranks = np.zeros(patterns.size, dtype=np.int64)
    for i, pattern in enumerate(patterns):  # ≤ 2**ntag patterns, not points
        chosen = directions[[(int(pattern) >> t) & 1 == 1 for t in range(ntag)]]
        if chosen.size == 0:
            continue
        w, v = np.linalg.eigh(chosen.T @ chosen)
        keep = w > 1e-6 * max(float(w.max()), 1e-300)
        table[i] = v[:, keep] @ v[:, keep].T
        ranks[i] = int(keep.sum())
    return table[inverse.ravel()], ranks[inverse.ravel()]


def rigid_modes(points: FloatArray) -> tuple[FloatArray, float]:
    """The six rigid-body modes evaluated at points, rotations about the centroid.

    Parameters
    ----------
    points : ndarray, shape (npoint, 3)
        Positions, mm.

    Returns
    -------
    modes : ndarray, shape (6, npoint, 3)
        Translations along x, y, z (mm per mm), then rotations about x, y, z through the
        centroid, scaled by 1/radius so every mode has a displacement of order 1.
    radius : float
        Root-mean-square distance of the points from their centroid, mm.
    """
    centre = points.mean(axis=0)
    radius = float(np.sqrt(((points - centre) ** 2).sum(axis=1).mean())) or 1.0
    return _rigid_about(points, centre, radius).reshape(6, -1, 3), radius


@dataclass(frozen=True)
class Observability:
    """What the tags see of a body (see the module notes).

    Attributes
    ----------
    projectors : ndarray, shape (nq, 3, 3)
        Projector onto the seen subspace at each constraint point.
    point_rank : ndarray of int, shape (nq,)
        Seen directions at each constraint point (0 to 3).
    cell_rank : ndarray of int, shape (ncell,)
        Seen directions in each cell: the span of the tags with data at any of its points.
    cell_seen : ndarray, shape (ncell, 3)
        Fraction of each axis (x, y, z) that the cell's tags see, :math:`|P e_a|^2` (0 to 1).
    unseen_modes : ndarray, shape (m, ndof)
        Rigid-body modes that neither the tags nor a Dirichlet condition hold (m = 0 to 6),
        mass-orthonormal, mm per unit amplitude.
    mode_weights : ndarray, shape (ndof,)
        Lumped nodal volumes as fractions of the body's volume (summing to 1 over the nodes,
        repeated for each node's three dofs) that weigh the mode amplitudes, dimensionless.
    pinned_dofs : ndarray of int, shape (m,)
        One dof per unseen mode held in each linear solve (its value restored afterwards
        by the mode shift), so that the solve is never singular.
    unseen_directions : list of str
        Human-readable unseen rigid motions that were removed (e.g. ``"translation along z
        (0, 0, 1)"``).
    body_rank : int
        Seen directions of the body as a whole.
    unseen_axes : ndarray, shape (3 - body_rank, 3)
        Unit vectors spanning the directions that no tag sees anywhere in the body.
    """

    projectors: FloatArray
    point_rank: IntArray
    cell_rank: IntArray
    cell_seen: FloatArray
    unseen_modes: FloatArray
    mode_weights: FloatArray
    pinned_dofs: IntArray
    unseen_directions: list[str]
    body_rank: int
    unseen_axes: FloatArray

    def remove_unseen(self, u: FloatArray) -> FloatArray:
        """``u`` with the amplitude of every unseen rigid mode set to zero.

        Parameters
        ----------
        u : ndarray, shape (ndof,)
            Displacement, mm.

        Returns
        -------
        ndarray, shape (ndof,)
            The displacement without its unseen rigid motion, mm: a new array, or ``u``
            itself when there is no unseen mode.
        """
        if not self.unseen_modes.shape[0]:
            return u
        amplitude = self.unseen_amplitude(u)
        # einsum, not BLAS: OpenBLAS threads these long products (see harpx._blas)
        return u - np.einsum("m,md->d", amplitude, self.unseen_modes)

    def unseen_amplitude(self, u: FloatArray) -> FloatArray:
        """Amplitudes of the unseen rigid modes in ``u``.

        Parameters
        ----------
        u : ndarray, shape (ndof,)
            Displacement, mm.

        Returns
        -------
        ndarray, shape (m,)
            Mass-weighted amplitude of each of :attr:`unseen_modes` in ``u``, mm.
        """
        out: FloatArray = np.einsum("md,d->m", self.unseen_modes, self.mode_weights * u)
        return out


def describe_direction(v: FloatArray, unnamed: str = "") -> str:
    """A unit 3-vector as text, e.g. ``"z (0, 0, 1)"``, for messages.

    The sign is chosen so that the largest component is positive; the axis name is given
    when ``v`` lies within 0.999 of a coordinate axis, else ``unnamed`` (nothing if empty).

    Parameters
    ----------
    v : ndarray, shape (3,)
        Unit vector (x, y, z components).
    unnamed : str, default ""
        Name to give a direction that is not a coordinate axis.

    Returns
    -------
    str
        The name (if any) followed by the components to two significant digits.

    Examples
    --------
    >>> describe_direction(np.array([0.0, 0.0, 1.0]))
    'z (0, 0, 1)'
    >>> describe_direction(np.array([0.6, 0.8, 0.0]), unnamed="the axis")
    'the axis (0.6, 0.8, 0)'
    """
    v = v * np.sign(v[np.argmax(np.abs(v))])
    name = "xyz"[int(np.argmax(np.abs(v)))] if np.abs(v).max() > 0.999 else unnamed
    prefix = f"{name} " if name else ""
    return f"{prefix}({v[0]:.2g}, {v[1]:.2g}, {v[2]:.2g})"


def _describe(mode: FloatArray) -> str:
    """Name of a rigid mode given as 6 coefficients (3 translations, 3 rotations)."""
    t, w = mode[:3], mode[3:]
    kind, vec = ("translation along", t) if np.linalg.norm(t) >= np.linalg.norm(w) else (
        "rotation about", w)  # fmt: skip
    return f"{kind} {describe_direction(vec / np.linalg.norm(vec), unnamed='the axis')}"


def observability(
    body: Body,
    points: FloatArray,
    volume: FloatArray,
    shape_values: FloatArray,
    cell_dofs: IntArray,
    directions: FloatArray,
    valid: np.ndarray,
    fixed_dofs: IntArray,
) -> Observability:
    """Seen subspaces, per-cell observability and the unseen rigid-body modes of a body.

    Parameters
    ----------
    body : Body
        The finite-element body (``ndof``, ``dof_points``, ``ncell``).
    points : ndarray, shape (nq, 3)
        Reference positions of the constraint points, mm (cell-major).
    volume : ndarray, shape (nq,)
        Their quadrature volumes, mm³.
    shape_values : ndarray, shape (ncell, npc, nb)
        Shape functions of each cell's dof nodes at its constraint points.
    cell_dofs : ndarray of int, shape (ncell, nb, 3)
        Dofs of each cell.
    directions : ndarray, shape (ntag, 3)
        Unit tag directions.
    valid : ndarray of bool, shape (nq, ntag)
        Which tags have data at each constraint point in the reference frame.
    fixed_dofs : ndarray of int
        Dofs held by Dirichlet conditions (they fix the modes they touch).

    Returns
    -------
    Observability
        The seen projectors and ranks of the points and cells, and the unseen rigid-body
        modes (mass-orthonormal, with a pinned dof each) and axes of the body.
    """
    ndof = int(body.ndof)
    ncell, npc, nb = shape_values.shape
    projectors, point_rank = seen_projectors(directions, valid)
    cell_valid = cast(BoolArray, valid.reshape(ncell, npc, -1).any(axis=1))
    cell_projectors, cell_rank = seen_projectors(directions, cell_valid)
    cell_seen = np.einsum("caa->ca", cell_projectors)
    # lumped nodal volumes (row sums of N² weighted: positive for serendipity elements too)
    # numpy's stub types every bincount as int; with float weights it is float64
    weights: FloatArray = np.bincount(  # type: ignore[assignment]
        cell_dofs[:, :, 0].ravel() // 3,
        weights=np.einsum("cqa,cq->ca", shape_values**2, volume.reshape(ncell, npc)).ravel(),
        minlength=ndof // 3,
    )
    weights = np.repeat(weights / weights.sum(), 3)
    # Gram matrix of the six rigid modes under the data's seen projectors …
    modes_q, radius = rigid_modes(points)
    projected = np.einsum("qij,mqj->mqi", projectors, modes_q)
    gram = np.einsum("mqi,nqi,q->mn", projected, projected, volume) / volume.sum()
    # … and under the Dirichlet conditions (a held dof holds every mode it moves)
    dof_points = np.asarray(body.dof_points, dtype=np.float64)
    centroid = points.mean(axis=0)
    modes_dof = _rigid_about(dof_points, centroid, radius)
    if fixed_dofs.size:
        held = modes_dof[:, fixed_dofs]
        gram = gram + held @ held.T / max(1, fixed_dofs.size)
    w, v = np.linalg.eigh(gram / max(float(np.trace(gram)), 1e-300))
    unseen = _canonical(v[:, w < UNSEEN_TOLERANCE])
    modes = unseen.T @ modes_dof  # (m, ndof)
    if modes.shape[0]:
        # mass-orthonormalise so that remove_unseen is a projection
        gram_m = modes @ (weights[None, :] * modes).T
        L = np.linalg.cholesky(gram_m)
        modes = np.linalg.solve(L, modes)
    pinned = _pin_dofs(modes) if modes.shape[0] else np.zeros(0, dtype=np.int64)
    body_projector, body_seen = seen_projectors(
        directions, cast(BoolArray, valid.any(axis=0))[None]
    )
    w_axes, v_axes = np.linalg.eigh(np.eye(3) - body_projector[0])
    unseen_axes = v_axes[:, w_axes > 0.5].T
    return Observability(
        projectors=projectors,
        point_rank=point_rank,
        cell_rank=cell_rank,
        cell_seen=cell_seen,
        unseen_modes=modes,
        mode_weights=weights,
        pinned_dofs=pinned,
        unseen_directions=[_describe(c) for c in unseen.T],
        body_rank=int(body_seen[0]),
        unseen_axes=unseen_axes,
    )


def _rigid_about(points: FloatArray, centre: FloatArray, radius: float) -> FloatArray:
    """Rigid modes (6, ndof) at dof points, rotations about ``centre`` scaled by 1/radius."""
    centred = points - centre
    modes = np.zeros((6, points.shape[0], 3))
    for a in range(3):
        modes[a, :, a] = 1.0
        axis = np.zeros(3)
        axis[a] = 1.0
        modes[3 + a] = np.cross(axis, centred) / radius
    return modes.reshape(6, -1)


def _canonical(basis: FloatArray) -> FloatArray:
    """The same span of rigid modes (6, m) in reduced echelon form: axis-aligned when it can.

    A null space from an eigensolver is any orthonormal basis of it (e.g. a mix of the y and
    z translations); naming the modes needs the basis that has one pure mode per pivot.
    """
    if not basis.shape[1]:
        return basis
    from scipy.linalg import qr

    _, _, pivots = qr(basis.T, pivoting=True, mode="economic")
    chosen = np.sort(pivots[: basis.shape[1]])
    coeffs = np.linalg.solve(basis[chosen].T, basis.T)  # (m, 6) with identity on ``chosen``
    coeffs[np.abs(coeffs) < 1e-9] = 0.0
    return coeffs.T


def _pin_dofs(modes: FloatArray) -> IntArray:
    """One dof per mode such that the modes restricted to them are well conditioned."""
    from scipy.linalg import qr

    _, _, pivots = qr(modes, pivoting=True, mode="economic")
    return np.sort(pivots[: modes.shape[0]].astype(np.int64))
