r"""Residual stress from growth: general growth fields, release by continuation, radial cut.

Residual stress in a body held in its reference configuration comes from an incompatible
growth (prestrain) field :math:`F_g` (paper §4.2, Rodriguez et al. 1994): the energy is
:math:`J_g W(F F_g^{-1})`, so at :math:`F = I` the tissue is strained by
:math:`F_e = F_g^{-1}` and stressed although no load acts. :class:`GrowthField` carries any
:math:`F_g` per quadrature point (not only growth along the fibres), :func:`release` finds
the equilibrium of a grown body by continuation in the growth, and :func:`opening_angle`
reproduces the classic experiment that reveals residual stress (Omens & Fung 1990): a
ring-like short-axis slab is cut along a radial plane and released; a residually stressed
ring springs open, a stress-free one does not move.

Opening angle
-------------
The cut duplicates the nodes on the radial half-plane :math:`\theta = \theta_c` (cells on
the clockwise side get the copies), so the ring has two coincident free faces. Rigid-body
motions are removed by a statically determinate 3-2-1 support on the radial line opposite
the cut (one node fixed, a second node on the same radial line fixed across that line, a
third node above them fixed against rotation about it), which adds (almost) no reaction
to a self-equilibrated residual stress: only the small tilt of the line from the first to
the second node out of the short-axis plane makes the support slightly redundant. The
*mid-line* of each face is the principal direction of its nodes projected on the
short-axis plane, oriented outwards; the opening angle is the
signed angle from the mid-line of the clockwise face to that of the counter-clockwise face
(positive when the ring opens, 0 for the intact ring).

References
----------
.. [1] Rodriguez EK, Hoger A, McCulloch AD. Stress-dependent finite growth in soft elastic
   tissues. J Biomech 27:455--467, 1994.
.. [2] Omens JH, Fung YC. Residual strain in rat left ventricle. Circ Res 66:37--45, 1990.
.. [3] Maas SA, Erdemir A, Halloran JP, Weiss JA. A general framework for application of
   prestrain to computational models of biological materials. J Mech Behav Biomed Mater
   61:499--510, 2016.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray
from harpx.errors import CoincidentNodesWarning, ConvergenceError
from harpx.mechanics.body import Body
from harpx.mechanics.linsolve import LinearSolver
from harpx.mechanics.mesh import hex_mesh
from harpx.mechanics.newton import SolveResult, equilibrate

__all__ = ["GrowthField", "NodeFixed", "OpeningAngle", "opening_angle", "release", "set_growth"]


@dataclass(frozen=True, eq=False)
class GrowthField:
    """A growth tensor per quadrature point, usable as ``Body(..., growth=GrowthField(Fg))``.

    Parameters
    ----------
    tensors : ndarray, shape (ncell, nqp, 3, 3)
        Growth tensors :math:`F_g` (dimensionless, ``det > 0``) at the body's Gauss points.

    Examples
    --------
    >>> from harpx.mechanics import Body, NeoHookean, box
    >>> from harpx.mechanics.cut import GrowthField
    >>> Fg = np.broadcast_to(np.diag([1.1, 1.0, 1.0]), (1, 8, 3, 3))
    >>> body = Body(box(divisions=(1, 1, 1)), NeoHookean(1.0, 100.0),
    ...             fibers=[[1.0, 0.0, 0.0]], growth=GrowthField(Fg))
    >>> round(float(body.growth_jacobian[0]), 12)
    1.1
    """

    tensors: FloatArray
    needs_fibers: ClassVar[bool] = True

    def __post_init__(self) -> None:
        t = np.ascontiguousarray(np.asarray(self.tensors, dtype=np.float64))
        if t.ndim != 4 or t.shape[-2:] != (3, 3):
            raise ValueError(f"growth tensors have shape {t.shape!r}; expected (ncell, nqp, 3, 3)")
        if not np.all(np.linalg.det(t) > 0):
            raise ValueError("growth tensors must have det Fg > 0 at every point")
        object.__setattr__(self, "tensors", t)

    def tensor(self, fiber: ArrayLike) -> FloatArray:
        """The stored tensors; ``fiber`` (ncell, nqp, 3) only fixes the expected shape."""
        shape = np.shape(fiber)[:-1]
        if tuple(shape) != self.tensors.shape[:2]:
            raise ValueError(
                f"GrowthField has {self.tensors.shape[:2]!r} (cells, points) but the body has "
                f"{tuple(shape)!r}; build the field on the same mesh and element"
            )
        return self.tensors

    def fiber_prestretch(self, fibers: ArrayLike) -> FloatArray:
        r"""In-situ elastic fibre stretch at the reference, :math:`1/|F_g f_0|` (dimensionless).

        Parameters
        ----------
        fibers : array_like, shape (ncell, nqp, 3)
            Unit reference fibres.

        Returns
        -------
        ndarray, shape (ncell, nqp)
            Reference fibre length over its stress-free length (< 1: compressed in situ).
        """
        g = np.einsum("eqij,eqj->eqi", self.tensors, np.asarray(fibers, dtype=np.float64))
        return 1.0 / np.linalg.norm(g, axis=-1)


def set_growth(body: Body, tensors: ArrayLike | None) -> None:
    """Replace a body's growth tensors in place (``None`` removes growth).

    Parameters
    ----------
    body : Body
        The body; its ``growth_tensor`` and ``growth_jacobian`` are updated.
    tensors : array_like, shape (ncell, nqp, 3, 3), or None
        New growth tensors :math:`F_g` (dimensionless).
    """
    if tensors is None:
        body.growth, body.growth_tensor, body.growth_jacobian = None, None, None
        return
    field_ = GrowthField(np.broadcast_to(tensors, (body.ncell, body.nqp, 3, 3)))
    body.growth = field_
    body.growth_tensor = field_.tensors
    body.growth_jacobian = (np.linalg.det(field_.tensors) * body.dV).sum(axis=1) / body.cell_volume


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

    def dofs(self, body: Any) -> IntArray:
        """Constrained dof ids (sorted, unique)."""
        p = np.asarray(self.points, dtype=np.float64).reshape(-1, 3)
        if len(p) != len(self.components):
            raise ValueError(
                f"NodeFixed has {len(p)} points but {len(self.components)} components; give "
                "one component per point"
            )
        d = np.linalg.norm(body.dof_points[:, None, :] - p[None], axis=-1)
        nodes = d.argmin(axis=0)
        return np.unique(3 * nodes + np.asarray(self.components, dtype=np.int64))

    def values(self, body: Any, s: float) -> FloatArray:
        """Zeros (mm)."""
        return np.zeros(self.dofs(body).size)


def release(
    body: Body,
    dirichlet: Sequence[Any],
    *,
    u0: ArrayLike | None = None,
    tol: float = 1e-8,
    max_iterations: int = 12,
    min_step: float = 1e-4,
    linear_solver: str | LinearSolver = "auto",
) -> SolveResult:
    """Equilibrium of a grown body, by continuation from no growth to its growth field.

    The growth is ramped as :math:`F_g(s) = I + s (F_g - I)`, ``s`` from 0 to 1, with
    Newton at each ``s`` (:func:`harpx.mechanics.newton.equilibrate`); a failed step is
    halved, a converged one lets the next step double. The body's growth is left at
    :math:`F_g(1)`. Elasticity is path independent, so the end state does not depend on
    the ramp.

    Parameters
    ----------
    body : Body
        Body with growth (``growth_tensor``); without growth the result is ``u0``.
    dirichlet : sequence
        Dirichlet conditions removing rigid-body motions.
    u0 : array_like, shape (ndof,), optional
        Starting displacement (mm), zeros by default. The first step tries the full growth
        (``s = 1``) directly, which is all a warm start close to equilibrium needs.
    tol : float, default 1e-8
        Newton tolerance (relative residual).
    max_iterations : int, default 12
        Newton iterations per step before halving it.
    min_step : float, default 1e-4
        Smallest continuation step before giving up.
    linear_solver : str or LinearSolver, default "auto"
        Linear solver (one instance is reused over all steps, keeping its symbolic
        analysis); see :mod:`harpx.mechanics.linsolve`.

    Returns
    -------
    SolveResult
        ``u`` (mm), ``iterations`` over all steps and the growth levels in
        ``load_factors``.

    Raises
    ------
    ConvergenceError
        If the step falls below ``min_step``.
    """
    u = np.zeros(body.ndof) if u0 is None else np.array(u0, dtype=np.float64)
    out = SolveResult(u=u, converged=True)
    if body.growth_tensor is None:
        return out
    target = body.growth_tensor.copy()
    done, step = 0.0, 1.0
    eye = np.eye(3)
    solver = (
        linear_solver if isinstance(linear_solver, LinearSolver) else LinearSolver(linear_solver)
    )
    previous: tuple[float, FloatArray] | None = None
    try:
        while done < 1.0 - 1e-12:
            s = min(1.0, done + step)
            set_growth(body, eye + s * (target - eye))
            start = u
            if previous is not None:  # secant predictor along the growth path
                trial = u + (u - previous[1]) * (s - done) / (done - previous[0])
                if body.jacobian(trial).min() > 0.1:
                    start = trial
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                r = equilibrate(
                    body,
                    dirichlet,
                    start,
                    1.0,
                    tol=tol,
                    max_iterations=max_iterations,
                    raise_on_failure=False,
                    linear_solver=solver,
                )
            out.iterations += r.iterations
            if r.converged:
                previous = (done, u)
                u, done = r.u, s
                out.load_factors.append(s)
                out.step_iterations.append(r.iterations)
                out.min_jacobian = r.min_jacobian
                step = min(1.0, 2.0 * step)
            else:
                out.cutbacks += 1
                step *= 0.5
                if step < min_step:
                    raise ConvergenceError(
                        f"releasing the growth stalled at growth level s={done:.4g} (step "
                        f"{step:.2g} < min_step={min_step!r}); check the Dirichlet conditions "
                        "or reduce the growth",
                        [],
                    )
    finally:
        set_growth(body, target)
    out.u = u
    return out


# ---------------------------------------------------------------------------- radial cut


@dataclass
class OpeningAngle:
    """Result of :func:`opening_angle`.

    Attributes
    ----------
    degrees : float
        Opening angle in degrees (positive: the ring springs open).
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

    def plot(self, ax: Any = None, *, scale: float = 1.0) -> Any:
        """Top view of the ring before (grey) and after the cut (black); returns the axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(4, 4))
        ring = self.ring
        p0 = ring.nodes
        p1 = ring.nodes + scale * self.u.reshape(-1, 3)[: len(ring.nodes)]
        edges = ring.cells[:, [0, 1, 1, 2, 2, 3, 3, 0]].reshape(-1, 2)
        for pts, colour, lw in ((p0, "0.7", 0.6), (p1, "k", 0.8)):
            seg = pts[edges][:, :, :2]
            ax.plot(seg[:, :, 0].T, seg[:, :, 1].T, color=colour, lw=lw)
        for nodes, colour in zip(self.faces, ("tab:red", "tab:blue"), strict=True):
            ax.plot(p1[nodes, 0], p1[nodes, 1], ".", color=colour, ms=4)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_title(f"opening angle {self.degrees:.1f}°")
        return ax


def _face_direction(points: FloatArray, centre: FloatArray) -> FloatArray:
    """Outward principal direction (unit, in the x-y plane) of face nodes."""
    q = points[:, :2] - points[:, :2].mean(axis=0)
    _, _, vt = np.linalg.svd(q, full_matrices=False)
    d = vt[0]
    if np.dot(points[:, :2].mean(axis=0) - centre, d) < 0:
        d = -d
    return d


def _signed_angle(a: FloatArray, b: FloatArray) -> float:
    """Angle from 2-D direction ``a`` to ``b`` in degrees, in (-180, 180]."""
    return float(np.degrees(np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)))


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
        hex8 body about the z axis (e.g. on :func:`harpx.mechanics.ventricle.ventricle`),
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
        ``degrees`` (positive when the ring opens), the ring body and its displacement.

    Raises
    ------
    ValueError
        If the body is not hex8, ``cut_angle`` is not a multiple of 90 or the slab is not a
        closed ring.
    """
    if body.element != "hex8":
        raise ValueError(f"opening_angle needs a hex8 body, got element={body.element!r}")
    if not np.isclose(np.mod(cut_angle + 45.0, 90.0), 45.0):
        raise ValueError(f"cut_angle={cut_angle!r} must be a multiple of 90 degrees")
    c0 = np.asarray(centre, dtype=np.float64)
    cells = body.cells
    centroid = body.nodes[cells].mean(axis=1)
    if slab is None:
        lo, hi = float(body.nodes[:, 2].min()), float(body.nodes[:, 2].max())
        mid, half = lo + 0.6 * (hi - lo), 0.06 * (hi - lo)
        slab = (mid - half, mid + half)
    keep = np.nonzero((centroid[:, 2] >= slab[0]) & (centroid[:, 2] <= slab[1]))[0]
    if keep.size == 0:
        raise ValueError(f"slab={slab!r} mm contains no cell centroid")
    # the state that is cut: the reference, or a deformed state carried as prestrain
    nodes = body.nodes.copy()
    Fg = None if body.growth_tensor is None else body.growth_tensor[keep]
    fibers = None if body.fibers_qp is None else body.fibers_qp[keep]
    if u_reference is not None:
        u_ref = np.asarray(u_reference, dtype=np.float64)
        if u_ref.shape != (body.ndof,):
            raise ValueError(f"u_reference has shape {u_ref.shape!r}; expected ({body.ndof},)")
        F_ref = body.deformation_gradient(u_ref)[keep]
        Fg = np.linalg.inv(F_ref) if Fg is None else np.matmul(Fg, np.linalg.inv(F_ref))
        nodes = nodes + u_ref.reshape(-1, 3)[: len(nodes)]
        if fibers is not None:
            fibers = np.einsum("eqij,eqj->eqi", F_ref, fibers)
    sub = cells[keep]
    used, local = np.unique(sub, return_inverse=True)
    local = local.reshape(sub.shape)
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
    pts = np.concatenate([pts, pts[on_cut]])
    faces = (np.nonzero(on_cut)[0], copy[on_cut])

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

    # 3-2-1 support on the radial line opposite the cut
    opposite = -e_r
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
    radial_axis = int(np.argmax(np.abs(opposite)))
    tangential = 1 - radial_axis
    support = NodeFixed(
        np.stack([pts[A]] * 3 + [pts[B]] * 2 + [pts[C]]),
        (0, 1, 2, tangential, 2, tangential),
    )
    result = release(ring, [support], tol=tol)
    u = result.u
    cur = pts + u.reshape(-1, 3)
    ccw, cw = faces
    before = _signed_angle(_face_direction(pts[cw], c0), _face_direction(pts[ccw], c0))
    after = _signed_angle(_face_direction(cur[cw], c0), _face_direction(cur[ccw], c0))
    return OpeningAngle(
        degrees=after - before,
        ring=ring,
        u=u,
        faces=faces,
        iterations=result.iterations,
        info={"slab": tuple(slab), "cells": int(keep.size), "support": (int(A), int(B), int(C))},
    )
