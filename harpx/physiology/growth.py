r"""Growth and prestretch: growth fields, release of a grown body, prestretched references.

Residual stress in a body held in its reference configuration comes from an incompatible
growth (prestrain) field :math:`F_g` (paper §4.2, Rodriguez et al. 1994): the energy is
:math:`J_g W(F F_g^{-1})`, so at :math:`F = I` the tissue is strained by
:math:`F_e = F_g^{-1}` and stressed although no load acts.

* :class:`GrowthField` carries any :math:`F_g` per quadrature point (not only growth along
  the fibres); :func:`set_growth` replaces a body's growth in place.
* :func:`release` finds the equilibrium of a grown body by continuation in the growth.
* :func:`prestretch_growth` builds a fibre growth field whose equilibrium is the mesh's own
  geometry (the prestrain update of Maas et al. 2016), so that a reference taken from
  images carries residual stress without moving; :func:`fiber_prestretch` reports the
  in-situ fibre prestretch it leaves.

References
----------
.. [1] Rodriguez EK, Hoger A, McCulloch AD. Stress-dependent finite growth in soft elastic
   tissues. J Biomech 27:455--467, 1994.
.. [2] Maas SA, Erdemir A, Halloran JP, Weiss JA. A general framework for application of
   prestrain to computational models of biological materials. J Mech Behav Biomed Mater
   61:499--510, 2016.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from harpx._typing import FloatArray
from harpx.errors import ConvergenceError
from harpx.mechanics.body import Body
from harpx.mechanics.kinematics import growth_tensor
from harpx.mechanics.linsolve import LinearSolver
from harpx.mechanics.mesh import MeshSpec
from harpx.mechanics.newton import SolveResult, equilibrate

__all__ = ["GrowthField", "fiber_prestretch", "prestretch_growth", "release", "set_growth"]


@dataclass(frozen=True, eq=False)
class GrowthField:
    """A growth tensor per quadrature point, usable as ``Body(..., growth=GrowthField(Fg))``.

    Parameters
    ----------
    tensors : ndarray, shape (ncell, nqp, 3, 3)
        Growth tensors :math:`F_g` (dimensionless, ``det > 0``) at the body's Gauss points.

    Raises
    ------
    ValueError
        If ``tensors`` is not (ncell, nqp, 3, 3) or a determinant is not positive.

    Examples
    --------
    >>> from harpx.mechanics import Body, NeoHookean, box
    >>> from harpx.physiology.growth import GrowthField
    >>> Fg = np.broadcast_to(np.diag([1.1, 1.0, 1.0]), (1, 8, 3, 3))
    >>> body = Body(box(divisions=(1, 1, 1)), NeoHookean(1.0, 100.0), growth=GrowthField(Fg))
    >>> round(float(body.growth_jacobian[0]), 12)
    1.1
    """

    tensors: FloatArray
    #: a tensor per point: the body's fibres are not used
    needs_fibers: ClassVar[bool] = False

    def __post_init__(self) -> None:
        t = np.ascontiguousarray(np.asarray(self.tensors, dtype=np.float64))
        if t.ndim != 4 or t.shape[-2:] != (3, 3):
            raise ValueError(f"growth tensors have shape {t.shape!r}; expected (ncell, nqp, 3, 3)")
        if not np.all(np.linalg.det(t) > 0):
            raise ValueError("growth tensors must have det Fg > 0 at every point")
        object.__setattr__(self, "tensors", t)

    def tensor(self, fiber: ArrayLike) -> FloatArray:
        """The stored tensors; ``fiber`` only fixes the expected shape.

        Parameters
        ----------
        fiber : array_like, shape (ncell, nqp, 3)
            Reference fibres of the body at its Gauss points; their values are not used.

        Returns
        -------
        ndarray, shape (ncell, nqp, 3, 3)
            The growth tensors :math:`F_g` (dimensionless).

        Raises
        ------
        ValueError
            If ``fiber`` is not on as many cells and points as the tensors.
        """
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
        The body; its ``growth_tensor`` and ``growth_jacobian`` are updated
        (:meth:`Body.set_growth <harpx.mechanics.body.Body.set_growth>`).
    tensors : array_like, shape (ncell, nqp, 3, 3), or None
        New growth tensors :math:`F_g` (dimensionless).
    """
    if tensors is None:
        body.set_growth(None)
        return
    body.set_growth(GrowthField(np.broadcast_to(tensors, (body.ncell, body.nqp, 3, 3))))


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


def prestretch_growth(
    spec: MeshSpec,
    material: Any,
    dirichlet: list[Any],
    *,
    transmural: Callable[[FloatArray], FloatArray],
    mean: float = -0.05,
    gradient: float = 0.10,
    tol: float = 1e-3,
    max_updates: int = 10,
    in_situ: bool = True,
    linear_solver: str = "auto",
) -> tuple[GrowthField, dict[str, Any]]:
    r"""Fibre growth field whose equilibrium under ``dirichlet`` is the mesh's own geometry.

    Parameters
    ----------
    spec : MeshSpec
        Mesh with fibres (e.g. a ventricle at the image geometry of frame 0).
    material : object
        Passive material.
    dirichlet : list
        Boundary conditions held while equilibrating (e.g. the LV scene's
        :func:`harpx.scenes.lv.base_conditions`).
    transmural : callable
        ``transmural(points (n, 3) mm) -> (n,)``: the transmural coordinate ``t`` (0 at the
        inner wall, 1 at the outer; e.g. ``VentricleGeometry.transmural``) of the Gauss
        points; clipped to [0, 1].
    mean : float, default -0.05
        Mean in-situ fibre prestretch :math:`\lambda_p - 1` over the wall volume
        (dimensionless; :math:`\lambda_p = 1/|F_g f_0|` is the in-situ fibre length over
        the stress-free length, so -0.05 means compressed by 5 %).
    gradient : float, default 0.10
        Transmural change of the initial prestretch from endo- to epicardium: the growth
        starts from :math:`\lambda_p(t) = 1 + \text{mean} + \text{gradient}\,(t - 1/2)`
        (compressed endocardium, unstrained epicardium for the defaults).
    tol : float, default 1e-3
        Largest displacement (mm) of the equilibrium that counts as "geometry kept".
    max_updates : int, default 10
        Prestrain updates before giving up.
    in_situ : bool, default True
        Keep the *in-situ* mean fibre prestretch at ``mean`` (rescaling the fibre part of
        the growth after every update). With False, ``mean`` and ``gradient`` only set the
        initial growth and the equilibrium relaxes most of its uniform part (see
        ``benchmarks/results/tracking_defaults.md``).
    linear_solver : str, default "auto"
        See :mod:`harpx.mechanics.linsolve`.

    Returns
    -------
    GrowthField
        :math:`F_g` at the Gauss points of a hex8 body on ``spec``.
    info : dict
        ``updates``, ``displacement`` (max ``|u|`` of each equilibrium, mm), ``prestretch``
        (mean, endocardial and epicardial mean :math:`\lambda_p - 1`) and ``wall_time``.

    Raises
    ------
    ConvergenceError
        If the geometry is not kept to ``tol`` after ``max_updates`` updates.

    Notes
    -----
    Fibre growth :math:`F_g = I + (1/\lambda_p - 1) f_0 \otimes f_0` is incompatible
    (:math:`\lambda_p` and :math:`f_0` vary through the wall), so the grown body deforms
    when it equilibrates, by :math:`F`. The update :math:`F_g \leftarrow F_g F^{-1}` makes
    the equilibrium elastic strain the in-situ strain of the *reference* geometry (Maas et
    al. 2016); the fibre part is then rescaled, :math:`F_g \leftarrow F_g (I + (c - 1) f_0
    \otimes f_0)`, to keep the mean prestretch. Repeating drives the equilibrium
    displacement to zero (the rescale is over-relaxed, :math:`c` cubed, since most of a
    uniform fibre compression relaxes again in the next equilibrium). The converged field
    is a fibre compression with cross-fibre extension, nearly isochoric. The material's
    fibre axis stays :math:`f_0` (the small rotation of :math:`F_g f_0` away from it is
    neglected).
    """
    start = _time.perf_counter()
    body = Body(spec, material)
    fibers = body.fibers_qp
    assert fibers is not None
    weights = body.dV / body.dV.sum()
    t = transmural(body.quadrature_points.reshape(-1, 3)).reshape(body.ncell, body.nqp)
    t = np.clip(t, 0.0, 1.0)
    target = 1.0 + mean
    Fg = growth_tensor(fibers, 1.0 / (target + gradient * (t - 0.5)))
    body = Body(spec, material, growth=GrowthField(Fg))
    solver = LinearSolver(linear_solver)
    moved: list[float] = []
    for _ in range(max_updates):
        res = release(body, dirichlet, linear_solver=solver)
        moved.append(float(np.abs(res.u).max()))
        if moved[-1] < tol:
            break
        F = body.deformation_gradient(res.u)
        Fg = np.matmul(Fg, np.linalg.inv(F))
        lam = GrowthField(Fg).fiber_prestretch(fibers)
        # over-relaxed (cubed) rescale: most of a uniform fibre compression relaxes again in
        # the next equilibrium, so undershooting would make the updates crawl
        # (benchmarks/results/tracking_defaults.md)
        c = (float((weights * lam).sum()) / target) ** 3 if in_situ else 1.0
        grown = np.einsum("eqij,eqj->eqi", Fg, fibers)
        Fg = Fg + (c - 1.0) * np.einsum("eqi,eqj->eqij", grown, fibers)
        set_growth(body, Fg)
    else:
        raise ConvergenceError(
            f"the prestretched reference moved {moved[-1]:.3g} mm after {max_updates} "
            f"prestrain updates (> tol={tol!r} mm); lower |mean| or |gradient|",
            moved,
        )
    field_ = GrowthField(Fg)
    lam = field_.fiber_prestretch(fibers)
    endo, epi = t < 0.25, t > 0.75
    info = {
        "updates": len(moved),
        "displacement": moved,
        "prestretch": {
            "mean": float((weights * lam).sum()) - 1.0,
            "endo": float(np.average(lam[endo], weights=weights[endo])) - 1.0,
            "epi": float(np.average(lam[epi], weights=weights[epi])) - 1.0,
        },
        "wall_time": _time.perf_counter() - start,
    }
    return field_, info


def fiber_prestretch(body: Body) -> FloatArray:
    r"""In-situ fibre prestretch per cell, :math:`1/|F_g f_0|` volume-averaged (dimensionless).

    Parameters
    ----------
    body : Body
        Body with fibres; 1 everywhere without growth.

    Returns
    -------
    ndarray, shape (ncell,)
        Reference fibre length over stress-free fibre length (< 1: compressed in situ).
        Multiply a fibre stretch relative to the reference by it to refer the stretch to
        the stress-free fibre length.
    """
    if body.growth_tensor is None or body.fibers_qp is None:
        return np.ones(body.ncell)
    lam = GrowthField(body.growth_tensor).fiber_prestretch(body.fibers_qp)
    return (lam * body.dV).sum(axis=1) / body.cell_volume
