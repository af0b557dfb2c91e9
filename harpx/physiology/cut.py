r"""The radial-cut experiment that reveals residual stress, and node-wise supports.

:func:`opening_angle` reproduces the classic experiment (Omens & Fung 1990): a ring-like
short-axis slab of a residually stressed body (growth, :mod:`harpx.physiology.growth`) is
cut along a radial plane and released; a residually stressed ring springs open, a
stress-free one does not move. :class:`NodeFixed` holds components at the dof nodes nearest
to given points (pins).

Opening angle
-------------
The cut duplicates the nodes on the radial half-plane :math:`\theta = \theta_c` (cells on
the clockwise side get the copies), so the ring has two coincident free faces. Rigid-body
motions are removed by a statically determinate 3-2-1 support on the radial line opposite
the cut (one node fixed, a second node on the same radial line fixed across that line, a
third node above them fixed against rotation about it), which adds (almost) no reaction
to a self-equilibrated residual stress: only the small tilt of the line from the first to
the second node out of the short-axis plane makes the support slightly redundant. The
*mid-line* of each face is its transmural direction in the short-axis plane: the
coefficient of the reference radius when the face nodes' in-plane positions are fitted as
linear in their reference radius and height, so it points from the inner to the outer
wall whatever the face's longitudinal spread; the opening angle is the
turn of the counter-clockwise face's mid-line minus that of the clockwise face (positive
when the ring opens, 0 for the intact ring). Each face is measured against its own
reference direction, so openings beyond 180° are reported as they are (up to a turn of
180° per face, an opening of about 360°).

References
----------
.. [1] Omens JH, Fung YC. Residual strain in rat left ventricle. Circ Res 66:37--45, 1990.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray
from harpx.errors import CoincidentNodesWarning, HarpxWarning, user_stacklevel
from harpx.mechanics.body import Body
from harpx.mechanics.mesh import hex_mesh
from harpx.physiology.growth import release, set_growth

__all__ = ["NodeFixed", "OpeningAngle", "opening_angle"]


@dataclass(frozen=True)
class NodeFixed:
    """Zero displacement of some components at the dof nodes nearest to given points.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Positions in mm; each selects its nearest dof node.
    components : sequence of int
        One component (0 = x, 1 = y, 2 = z) per point.
    """

    points: Any
    components: tuple[int, ...]

    def dofs(self, body: Body) -> IntArray:
        """Constrained dof ids (sorted, unique).

        Parameters
        ----------
        body : Body
            The body whose dof nodes (``body.dof_points``) the points select.

        Returns
        -------
        ndarray of int
            ``3 * node + component`` for each point's nearest dof node and its component,
            sorted, duplicates removed.

        Raises
        ------
        ValueError
            If the numbers of points and components differ.
        """
        p = np.asarray(self.points, dtype=np.float64).reshape(-1, 3)
        if len(p) != len(self.components):
            raise ValueError(
                f"NodeFixed has {len(p)} points but {len(self.components)} components; give "
                "one component per point"
            )
        d = np.linalg.norm(body.dof_points[:, None, :] - p[None], axis=-1)
        nodes = d.argmin(axis=0)
        return np.unique(3 * nodes + np.asarray(self.components, dtype=np.int64))

    def values(self, body: Body, s: float) -> FloatArray:
        """Zeros (mm).

        Parameters
        ----------
        body : Body
            The body, as in :meth:`dofs`.
        s : float
            Load factor in [0, 1]; the values do not depend on it.

        Returns
        -------
        ndarray
            Zero displacement (mm) for each dof of :meth:`dofs`, in its order.
        """
        return np.zeros(self.dofs(body).size)


# ---------------------------------------------------------------------------- radial cut


#: A released ring whose faces' centres are further apart along z than this fraction of
#: its height has left its plane (:attr:`OpeningAngle.planar`)
_PLANAR_LIMIT = 0.5


@dataclass
class OpeningAngle:
    """Result of :func:`opening_angle`.

    Attributes
    ----------
    degrees : float
        Opening angle in degrees (positive: the ring springs open): the in-plane turn of
        the faces, meaningful while the released ring stays in its plane (``planar``).
    gap : float
        Mean distance between the two faces' paired nodes after the release, mm (0 for
        the intact ring): the edges' separation, also where the ring leaves its plane.
    planar : bool
        False when the released ring has left its short-axis plane (its faces' centres
        lie further apart along z than half the ring's height, e.g. helical fibre growth
        twisting it into a helix): ``degrees`` then does not describe it, which is warned
        (:class:`~harpx.errors.HarpxWarning`).
    ring : Body
        The cut ring (reference configuration = the slab at ``u_reference``).
    u : ndarray, shape (ring.ndof,)
        Released displacement of the ring, mm (relative to the ring's reference, the
        intact slab in the state that was cut).
    faces : tuple of 2 ndarrays of int
        Dof-node ids of the counter-clockwise and clockwise cut faces.
    iterations : int
        Newton iterations of the release.
    """

    degrees: float
    ring: Body
    u: FloatArray
    faces: tuple[IntArray, IntArray]
    iterations: int = 0
    info: dict = field(default_factory=dict)
    gap: float = 0.0
    planar: bool = True


def _face_direction(points: FloatArray, reference: FloatArray, centre: FloatArray) -> FloatArray:
    """In-plane direction (unit) in which a face runs from the inner to the outer wall.

    The face's in-plane positions are fitted as ``a + b r + c z`` over its nodes' reference
    radius ``r`` and height ``z``; the direction is ``b``: the transmural direction of the
    face, apart from its longitudinal spread (a slab of a cone tilts as it opens) and
    signed by the material (its reference radii), not by a position about a centre, so a
    face that has turned by more than 90° keeps it.
    """
    r = np.hypot(*(reference[:, :2] - centre).T)
    basis = np.column_stack([np.ones(len(r)), r, reference[:, 2]])
    coef, *_ = np.linalg.lstsq(basis, points[:, :2], rcond=None)
    d = coef[1]
    return d / np.linalg.norm(d)


def _signed_angle(a: FloatArray, b: FloatArray) -> float:
    """Angle from 2-D direction ``a`` to ``b`` in degrees, in (-180, 180]."""
    return float(np.degrees(np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)))


def _face_turn(before: FloatArray, after: FloatArray, centre: FloatArray) -> float:
    """Rotation of one cut face about z from ``before`` to ``after`` positions, degrees."""
    return _signed_angle(
        _face_direction(before, before, centre), _face_direction(after, before, centre)
    )


def opening_angle(
    body: Body,
    u_reference: ArrayLike | None = None,
    *,
    slab: tuple[float, float] | None = None,
    cut_angle: float = 0.0,
    centre: tuple[float, float] = (0.0, 0.0),
    tol: float = 1e-8,
) -> OpeningAngle:
    """Cut a short-axis ring out of a body along a radial plane, release it, measure the opening.

    Parameters
    ----------
    body : Body
        hex8 body about the z axis (e.g. on :func:`harpx.anatomy.ventricle.ventricle`),
        with its growth field (residual stress) if any, fibres and material.
    u_reference : array_like, shape (body.ndof,), optional
        Displacement of the intact state that is cut (mm), e.g. a loaded configuration;
        default the reference configuration (``u = 0``). Its deformation gradient
        :math:`F_r` is carried into the ring as prestrain (:math:`F_g F_r^{-1}`) and its
        fibres as :math:`F_r f_0`.
    slab : (float, float), optional
        z range (mm) of the ring: cells whose centroid lies in it. Default: 12 % of the
        body's height centred at 60 % of the way from its lowest to its highest node.
    cut_angle : float, default 0
        Angle of the radial cut half-plane about z, degrees from +x; a multiple of 90 so
        that the 3-2-1 support opposite the cut is axis aligned.
    centre : (float, float), default (0, 0)
        Position of the ring's axis in the x-y plane, mm.
    tol : float, default 1e-8
        Newton tolerance of the release.

    Returns
    -------
    OpeningAngle
        ``degrees`` (positive when the ring opens), ``gap`` (mm), ``planar``, the ring
        body and its displacement.

    Raises
    ------
    ValueError
        If the body is not hex8, ``cut_angle`` is not a multiple of 90 or the slab is not a
        closed ring.

    Warns
    -----
    HarpxWarning
        If the released ring leaves its plane (``planar`` False).

    Examples
    --------
    A tube of 2 × 24 × 1 hexahedra with circumferential fibres, grown uniformly to 0.95
    along them: the stress-free shape is a sector of 0.95 × 360°, so the cut ring opens by
    (1 - 0.95) × 360°:

    >>> from harpx.mechanics.body import Body
    >>> from harpx.mechanics.materials import NeoHookean
    >>> from harpx.mechanics.mesh import tube
    >>> spec = tube(20.0, 26.0, 4.0, n_radial=2, n_circumferential=24, n_axial=1)
    >>> centre = spec.mesh.p[:, spec.mesh.t].mean(axis=1)  # (3, cell), mm
    >>> theta = np.arctan2(centre[1], centre[0])
    >>> fibers = np.column_stack([-np.sin(theta), np.cos(theta), 0.0 * theta])
    >>> body = Body(spec, NeoHookean(c1=1.0, kappa=100.0), fibers=fibers,
    ...             growth=np.full(theta.size, 0.95))
    >>> result = opening_angle(body, slab=(0.0, 4.0))
    >>> round(result.degrees), result.planar
    (18, True)
    """
    if body.element != "hex8":
        raise ValueError(f"opening_angle needs a hex8 body, got element={body.element!r}")
    if not np.isclose(np.mod(cut_angle + 45.0, 90.0), 45.0):
        raise ValueError(f"cut_angle={cut_angle!r} must be a multiple of 90 degrees")
    c0 = np.asarray(centre, dtype=np.float64)
    if slab is None:
        lo, hi = float(body.nodes[:, 2].min()), float(body.nodes[:, 2].max())
        mid, half = lo + 0.6 * (hi - lo), 0.06 * (hi - lo)
        slab = (mid - half, mid + half)
    centroid = body.nodes[body.cells].mean(axis=1)
    keep = np.nonzero((centroid[:, 2] >= slab[0]) & (centroid[:, 2] <= slab[1]))[0]
    if keep.size == 0:
        raise ValueError(f"slab={slab!r} mm contains no cell centroid")
    nodes, Fg, fibers = _state_cut(body, keep, u_reference)
    pts, local, faces = _cut_ring(nodes, body.cells[keep], cut_angle, c0, slab)
    size = float(np.ptp(pts[:, :2], axis=0).max())

    kwargs: dict[str, Any] = {} if fibers is None else {"fibers": fibers}
    with warnings.catch_warnings():  # the cut's nodes coincide on purpose
        warnings.simplefilter("ignore", CoincidentNodesWarning)
        ring = Body(hex_mesh(pts, local), body.material, **kwargs)
    # same cells in the same vertex order: the Gauss points (and so the growth) transfer
    if u_reference is None and not np.allclose(
        ring.quadrature_points, body.quadrature_points[keep], atol=1e-9 * size
    ):
        raise AssertionError("ring Gauss points do not match the body's")  # pragma: no cover
    if Fg is not None:
        set_growth(ring, Fg)
    support, corners = _support_opposite(pts, cut_angle, c0, size)
    result = release(ring, [support], tol=tol)
    u = result.u
    cur = pts + u.reshape(-1, 3)
    # each face's own turn (about half the opening each, the support between them holds
    # still): their difference stays unwrapped past 180°, where the angle between the two
    # faces would wrap to its negative
    ccw, cw = faces
    opening = _face_turn(pts[ccw], cur[ccw], c0) - _face_turn(pts[cw], cur[cw], c0)
    gap = float(np.linalg.norm(cur[ccw] - cur[cw], axis=1).mean())
    height = float(np.ptp(pts[:, 2]))
    apart = abs(float(cur[ccw, 2].mean() - cur[cw, 2].mean()))
    planar = apart <= _PLANAR_LIMIT * height
    if not planar:
        warnings.warn(
            f"the released ring left its plane: its cut faces' centres are {apart:.1f} mm "
            f"apart along z (the ring is {height:.1f} mm high), so the in-plane opening "
            f"angle {opening:.1f}° does not describe it; the faces' gap is {gap:.1f} mm",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    info = {"slab": tuple(slab), "cells": int(keep.size), "faces_apart_z": apart,
            "support": corners}  # fmt: skip
    return OpeningAngle(opening, ring, u, faces, result.iterations, info, gap=gap, planar=planar)


def _state_cut(
    body: Body, keep: IntArray, u_reference: ArrayLike | None
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """The state that is cut: node positions (mm), the growth of the cells ``keep`` (with a
    deformed state's :math:`F_r^{-1}` carried as prestrain) and their fibres."""
    nodes = body.nodes.copy()
    Fg = None if body.growth_tensor is None else body.growth_tensor[keep]
    fibers = None if body.fibers_qp is None else body.fibers_qp[keep]
    if u_reference is None:
        return nodes, Fg, fibers
    u_ref = np.asarray(u_reference, dtype=np.float64)
    if u_ref.shape != (body.ndof,):
        raise ValueError(f"u_reference has shape {u_ref.shape!r}; expected ({body.ndof},)")
    F_ref = body.deformation_gradient(u_ref)[keep]
    inv_ref = np.asarray(np.linalg.inv(F_ref), dtype=np.float64)
    Fg = inv_ref if Fg is None else np.matmul(Fg, inv_ref)
    nodes = nodes + u_ref.reshape(-1, 3)[: len(nodes)]
    if fibers is not None:
        fibers = np.einsum("eqij,eqj->eqi", F_ref, fibers)
    return nodes, Fg, fibers


def _cut_ring(
    nodes: FloatArray,
    cells: IntArray,
    cut_angle: float,
    c0: FloatArray,
    slab: tuple[float, float],
) -> tuple[FloatArray, IntArray, tuple[IntArray, IntArray]]:
    """The ring of ``cells`` cut open along the radial half-plane at ``cut_angle``: its
    points (the nodes on the cut doubled), its cells, and the nodes of the two cut faces
    (counter-clockwise side, clockwise side)."""
    used, local = np.unique(cells, return_inverse=True)
    local = local.reshape(cells.shape)
    pts = nodes[used]
    # radial half-plane of the cut: e_t · (x - c) = 0 with e_r · (x - c) > 0
    a = np.deg2rad(cut_angle)
    e_r, e_t = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
    rel = pts[:, :2] - c0
    size = float(np.ptp(pts[:, :2], axis=0).max())
    on_cut = (np.abs(rel @ e_t) < 1e-9 * size) & (rel @ e_r > 0)
    touches = on_cut[local]
    clockwise = ((pts[local].mean(axis=1)[:, :2] - c0) @ e_t < 0)[:, None]
    if not (np.any(touches & clockwise) and np.any(touches & ~clockwise)):
        raise ValueError(
            f"the slab {slab!r} mm is not a closed ring with a mesh line on the cut half-plane "
            f"at {cut_angle!r}°; move or widen the slab"
        )
    copy = np.full(len(pts), -1, dtype=np.int64)
    copy[on_cut] = len(pts) + np.arange(int(on_cut.sum()))
    local = np.where(touches & clockwise, copy[local], local)
    return np.concatenate([pts, pts[on_cut]]), local, (np.nonzero(on_cut)[0], copy[on_cut])


def _support_opposite(
    pts: FloatArray, cut_angle: float, c0: FloatArray, size: float
) -> tuple[NodeFixed, tuple[int, int, int]]:
    """The 3-2-1 support on the radial line opposite the cut, and its nodes A, B, C: A
    fixed, B (across the wall) held tangentially and along z, C (along z) tangentially."""
    a = np.deg2rad(cut_angle)
    opposite = -np.array([np.cos(a), np.sin(a)])
    rr = pts[:, :2] - c0
    normal = np.array([-opposite[1], opposite[0]])
    line = np.nonzero((np.abs(rr @ normal) < 1e-6 * size) & (rr @ opposite > 0))[0]
    if line.size < 3:
        raise ValueError("no mesh line opposite the cut for the 3-2-1 support")
    radius = rr[line] @ opposite
    zmid = 0.5 * (pts[line, 2].min() + pts[line, 2].max())
    A = line[np.argmin(np.abs(pts[line, 2] - zmid) + np.abs(radius - np.median(radius)))]
    # B: across the wall from A (far radially, close in z); C: far from A along z
    dr = np.abs(radius - rr[A] @ opposite)
    dz = np.abs(pts[line, 2] - pts[A, 2])
    B = line[np.argmax(dr - 3.0 * dz)]
    C = line[np.argmax(dz - 0.5 * dr)]
    if B == A or C == A:
        raise ValueError("the slab needs at least two nodes across and along the support line")
    tangential = 1 - int(np.argmax(np.abs(opposite)))
    support = NodeFixed(
        np.stack([pts[A]] * 3 + [pts[B]] * 2 + [pts[C]]),
        (0, 1, 2, tangential, 2, tangential),
    )
    return support, (int(A), int(B), int(C))
