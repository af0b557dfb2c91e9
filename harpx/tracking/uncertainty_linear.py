r"""The tracker's final Gauss–Newton system rebuilt per frame, and noise pushed through it.

Part of :mod:`harpx.tracking.uncertainty`.

Linearisation
-------------
At the tracked state :math:`u_n` of frame :math:`n` the residual on the free dofs vanishes,
:math:`R(u_n) = R_{int}(u_n) + R_c(u_n; \phi_n, \phi_0) \,[+\, \text{terms}] = 0`, with the
constraint force of :mod:`harpx.tracking.constraint`. Noise moves the phase the current
frame shows at the current point, :math:`\delta\phi_n(x)`, and the reference phase,
:math:`\delta\phi_0(X)`, so the mismatch :math:`r_t` of every constraint point and tag by
:math:`\delta r_t = \delta\phi_{n,t}(x) - \delta\phi_{0,t}(X)`, and the residual by

.. math::

    \delta R^c_{ai} = \int m\, N_a\, \lambda_n \sum_t s(r_t)\, (\nabla\phi_t)_i\,
        \delta r_t \, dV,
    \qquad s(r) = \max\!\Big(0, \frac{1 - r^2/r_0^2}{(1 + r^2/r_0^2)^2}\Big),

where :math:`s` is the slope of the Cauchy force :math:`r/(1 + r^2/r_0^2)` (1 for the
quadratic penalty) and :math:`\lambda_n` the frame's final penalty. To first order the
equilibrium then moves by

.. math::

    J\, \delta u_n = -\delta R^c\, [+\, K_{mech}(u_{n-1})\, \delta u_{n-1}],
    \qquad J = K_{int}(u_n) + \int m\, \lambda_n\, N N \sum_t s(r_t)\,
        \nabla\phi_t \nabla\phi_t^T\, dV \,[+\, K_{terms}],

with :math:`K_{int}` the consistent hyperelastic tangent (with the pressure's initial
stress) and the bracketed term only for ``regularization="increment"``, whose residual
holds the previous frame's mechanical force. Dirichlet dofs are held (:math:`\delta u = 0`)
and the rigid-body modes no tag sees are removed, both as the tracker holds them
(:mod:`harpx.tracking.equilibrium`). :math:`J` is factorised once per frame.

With the band-pass blur correction (:mod:`harpx.tracking.blur`) the final pass tracked
images from which the correction :math:`c(U_1)` of the previous pass's motion was removed,
and the noise moved that motion too. The previous pass's response is taken as the one
above, :math:`\delta U_1 \approx \delta U`, each sample's correction is recomputed,
:math:`\delta c = c(U + \delta U) - c(U)`, and its phase change at the points, sampled as
the tracker samples the deblurred images, is pushed through the same factorised systems
and added. Since the previous pass's motion is not stored, :math:`c(U)` of the final
motion stands in for :math:`c(U_1)` throughout.

Each sample keeps its frame-0 noise in every frame, so the samples are joint over frames
(the reference noise correlates them) and extremes over frames can be taken per sample.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from scipy.sparse import linalg as spla

from harpx._typing import FloatArray, IntArray
from harpx.imaging.sample import PhaseSampler
from harpx.mechanics.assembly import internal_forces
from harpx.schema import GRID_DIMS, validate
from harpx.tracking.blur import blur_correction, deblurred
from harpx.tracking.constraint import ConstraintState, PhaseConstraint
from harpx.tracking.equilibrium import split_dirichlet
from harpx.tracking.uncertainty_noise import ImageNoise
from harpx.tracking.uncertainty_phase import frame_harmonic, harmonic_fields, perturbed_phases

__all__ = ["Problem", "mechanical_tangent", "rebuild", "sample_response", "setting"]

#: Bytes of complex harmonic noise held at once (bounds the samples generated together).
_CHUNK_BYTES = 128e6


def _slope(residual: FloatArray, scale: float | None) -> FloatArray | None:
    """Slope s(r) of the (Cauchy) constraint force (module notes); None when quadratic."""
    if scale is None:
        return None
    q = (residual / scale) ** 2
    return np.asarray(np.clip((1.0 - q) / (1.0 + q) ** 2, 0.0, None), dtype=np.float64)


def setting(tracked: xr.Dataset, name: str, default: Any) -> Any:
    """A tracking setting as the result records it (``setting_<name>`` attribute).

    Parameters
    ----------
    tracked : xarray.Dataset
        A ``tracked/1`` result of :func:`harpx.tracking.track.track`.
    name : str
        Field name of :class:`~harpx.tracking.settings.TrackingSettings`.
    default : object
        Returned when the result does not record the setting.

    Returns
    -------
    object
        The recorded value (a numpy scalar as its Python value), else ``default``.
    """
    value = tracked.attrs.get(f"setting_{name}", default)
    return value.item() if isinstance(value, np.generic) else value


def mechanical_tangent(body: Any, u: FloatArray, terms: Sequence[Any]) -> tuple[Any, FloatArray]:
    """Consistent internal tangent plus term tangents, and the matching force, at ``u``.

    Parameters
    ----------
    body : Body
        The body.
    u : ndarray, shape (ndof,)
        Displacement, mm.
    terms : sequence of ResidualTerm
        Further residual terms (``residual_tangent(body, u, s)``), taken at load factor 1.

    Returns
    -------
    K : scipy.sparse.csr_matrix, shape (ndof, ndof)
        Consistent tangent of the internal force plus the terms' tangents, mN/mm.
    r : ndarray, shape (ndof,)
        Internal force plus the terms' residuals, mN.

    Raises
    ------
    ValueError
        If ``u`` inverts cells of the body.
    """
    internal = internal_forces(body, u)
    if internal.r is None or internal.K is None:
        raise ValueError(
            "the tracked displacement inverts cells of this body; pass the body that was tracked"
        )
    K, r = internal.K.copy(), np.array(internal.r, dtype=np.float64)
    for term in terms:
        rt, Kt = term.residual_tangent(body, u, 1.0)
        r = r + rt
        if Kt is not None:
            K = K + Kt
    return K.tocsr(), r


def _check_inputs(tracked: xr.Dataset, body: Any) -> None:
    validate(tracked, "tracked")
    if "dof_displacement" not in tracked.variables:
        raise ValueError("tracked has no 'dof_displacement'; pass the result of harpx track")
    if tracked.sizes["dof"] != body.ndof or not np.allclose(
        tracked["points"].values, body.dof_points, atol=1e-6
    ):
        raise ValueError(
            f"the body ({body.ndof} dofs) is not the one tracked ({tracked.sizes['dof']} dofs "
            "or other node positions); pass the body given to track"
        )
    method = setting(tracked, "method", "penalty")
    if method != "penalty":
        raise ValueError(
            f"the result was tracked with method={method!r}; the uncertainty linearises the "
            "penalty method (the augmented-Lagrangian multipliers move with the data too)"
        )


@dataclass
class Problem:
    """The tracker's problem rebuilt from a result (what every frame's solve needs).

    Built by :func:`rebuild`.

    Attributes
    ----------
    body : Body
        The tracked body.
    dirichlet, terms : sequence
        The Dirichlet conditions and residual terms given to the tracker.
    constraint : PhaseConstraint
        The rebuilt constraint, with the observability applied; with the blur correction it
        holds the deblurred images.
    raw : xarray.Dataset
        The ``phase/1`` dataset as given (before any blur correction).
    U : ndarray, shape (ntime, ndof)
        Tracked displacement, mm.
    penalty : ndarray, shape (ntime,)
        Absolute final penalty of each frame, kPa/rad².
    robust_scale : float or None
        Cauchy scale of the constraint, rad; None: quadratic.
    increment : bool
        Whether the tracker used ``regularization="increment"``.
    tolerance : float
        The tracker's Gauss–Newton tolerance, mm.
    free : ndarray of int, shape (nfree,)
        Dofs solved for: neither held by a Dirichlet condition nor pinned for an unseen
        rigid mode.
    correction : ndarray, shape (tag, time, z, y, x), optional
        Blur correction of ``U`` (:func:`~harpx.tracking.blur.blur_correction`), rad; None
        without blur correction.
    linear_solver : str
        The linear solver method the tracker used.
    max_iterations : int
        The tracker's Gauss–Newton iterations per solve.
    """

    body: Any
    dirichlet: Sequence[Any]
    terms: Sequence[Any]
    constraint: PhaseConstraint
    raw: xr.Dataset  # the phase as given (the constraint may hold the deblurred one)
    U: FloatArray  # (time, dof) tracked displacement, mm
    penalty: FloatArray  # (time,) absolute final penalty, kPa/rad²
    robust_scale: float | None
    increment: bool
    tolerance: float
    free: IntArray
    correction: np.ndarray | None = None  # blur correction of U (tag, time, z, y, x), rad
    linear_solver: str = "auto"
    max_iterations: int = 20

    def remove_unseen(self, du: FloatArray) -> FloatArray:
        """Rows of ``du`` with the unseen rigid modes removed, as the tracker does.

        Parameters
        ----------
        du : ndarray, shape (k, ndof)
            Displacement changes, mm.

        Returns
        -------
        ndarray, shape (k, ndof)
            ``du`` without the unseen rigid modes' amplitudes, mm (``du`` itself when no
            mode is unseen).
        """
        seen = self.constraint.observability
        if seen is None or not seen.unseen_modes.shape[0]:
            return du
        amplitude = (du * seen.mode_weights) @ seen.unseen_modes.T
        return du - amplitude @ seen.unseen_modes


def rebuild(
    tracked: xr.Dataset, body: Any, phase: xr.Dataset, dirichlet: Sequence[Any],
    terms: Sequence[Any],
) -> Problem:  # fmt: skip
    """The constraint, held dofs and penalties the tracker ended with (checked).

    Parameters
    ----------
    tracked : xarray.Dataset
        ``tracked/1`` result of the penalty method, with ``dof_displacement``.
    body : Body
        The body that was tracked.
    phase : xarray.Dataset
        The ``phase/1`` dataset that was tracked.
    dirichlet, terms : sequence
        The Dirichlet conditions and residual terms given to the tracker.

    Returns
    -------
    Problem
        The rebuilt problem; with blur-correction passes, the correction of the final motion
        is computed and the constraint reads the deblurred images.

    Raises
    ------
    ValueError
        If ``tracked`` is not a penalty-method result with this body, or the Dirichlet
        conditions differ from the tracked ones (held dofs moved, or another number of
        unseen rigid modes).
    """
    _check_inputs(tracked, body)
    U = np.asarray(tracked["dof_displacement"].transpose("time", "dof").values, dtype=np.float64)
    intorder = int(setting(tracked, "intorder", -1))
    robust = setting(tracked, "robust_scale", "none")
    robust_scale = None if isinstance(robust, str) else float(robust)
    constraint = PhaseConstraint(
        body, phase, intorder=None if intorder < 0 else intorder, robust_scale=robust_scale
    )
    fixed, values = split_dirichlet(body, dirichlet)
    if fixed.size and np.abs(U[1:, fixed] - values).max(initial=0.0) > 1e-6:
        raise ValueError(
            "the tracked displacement does not hold the given Dirichlet dofs at their values; "
            "pass the dirichlet= given to track"
        )
    seen = constraint.observe(fixed)
    recorded = tracked.attrs.get("rigid_modes_removed")
    removed = seen.unseen_modes.shape[0] if recorded is None else int(recorded)
    if removed != seen.unseen_modes.shape[0]:
        raise ValueError(
            f"with these Dirichlet conditions {seen.unseen_modes.shape[0]} rigid mode(s) are "
            f"unseen, but tracking removed {removed}; pass the dirichlet= given to track"
        )
    correction = None
    if int(tracked.attrs.get("blur_passes_applied", 0)) > 0:
        # the final pass tracked images deblurred with the previous pass's motion, which is
        # not stored: the correction of the final motion stands in for it
        correction = blur_correction(phase, body, U)
        constraint.replace_images(deblurred(phase, correction))
    penalty = np.asarray(tracked["penalty"].values, dtype=np.float64)
    return Problem(
        body=body, dirichlet=dirichlet, terms=terms, constraint=constraint, raw=phase, U=U,
        penalty=penalty * constraint.penalty_scale(), robust_scale=robust_scale,
        increment=setting(tracked, "regularization", "total") == "increment",
        tolerance=float(setting(tracked, "tolerance", 0.01)),
        free=np.setdiff1d(np.arange(body.ndof), np.union1d(fixed, seen.pinned_dofs)),
        correction=correction, linear_solver=str(tracked.attrs.get("linear_solver", "auto")),
        max_iterations=int(setting(tracked, "max_iterations", 20)),
    )  # fmt: skip


@dataclass
class _Frame:
    """One frame's linearised system (module notes), factorised."""

    state: ConstraintState  # at the tracked state, with the slopes s(r) as weights
    lu: Any  # factorised J on the free dofs
    mechanical: Any  # K_mech(u_n), needed by the next frame with increment regularisation
    step: float  # largest nodal change of a Newton step from the tracked state, mm
    penalty: float  # the frame's absolute penalty, kPa/rad²


def _frame_system(problem: Problem, n: int) -> _Frame:
    """Assemble and factorise frame ``n``'s J, and the Newton step at its tracked state."""
    constraint, U, free = problem.constraint, problem.U, problem.free
    constraint.set_frame(n)
    st = constraint.state(U[n])
    constraint.penalty = float(problem.penalty[n])
    constraint.multipliers[:] = 0.0
    slope = _slope(st.residual, problem.robust_scale)
    linear = ConstraintState(st.residual, st.gradient, st.weight, st.tag_valid, slope)
    _, Kc = constraint.assemble(linear)
    K, r = mechanical_tangent(problem.body, U[n], problem.terms)
    R = r + constraint.force(st)
    if problem.increment:
        R = R - mechanical_tangent(problem.body, U[n - 1], problem.terms)[1]
    lu = spla.splu((K + Kc)[free][:, free].tocsc())
    newton = np.zeros((1, U.shape[1]))
    newton[0, free] = -lu.solve(R[free])
    step = float(np.abs(problem.remove_unseen(newton)).max())
    return _Frame(linear, lu, K if problem.increment else None, step, float(problem.penalty[n]))


def sample_response(
    problem: Problem, noise: ImageNoise, samples: int, seed: int | None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    r"""Sampled displacement changes, the mean :math:`|\delta r|` per frame and the Newton
    step of each frame's rebuilt state (module notes).

    Parameters
    ----------
    problem : Problem
        The rebuilt problem (:func:`rebuild`).
    noise : ImageNoise
        The noise of the images behind ``problem.raw``.
    samples : int
        Noise samples M.
    seed : int or None
        Seed of the noise samples (None: fresh entropy).

    Returns
    -------
    dU : ndarray, shape (samples, ntime, ndof)
        Displacement change of each sample, mm (0 in frame 0), blur correction included.
    noise_residual : ndarray, shape (ntime,)
        Mean over the samples of :math:`|\delta r|`, weighted as ε, rad (NaN in frame 0).
    step : ndarray, shape (ntime,)
        Largest nodal change a Newton step would make at each frame's rebuilt state, mm (0
        in frame 0).
    """
    constraint, raw, U = problem.constraint, problem.raw, problem.U
    rng = np.random.default_rng(seed)
    order = constraint.spline_order
    nvox = int(np.prod([raw.sizes[d] for d in GRID_DIMS]))
    per_sample = (24.0 + (4.0 * U.shape[0] if problem.correction is not None else 0.0)) * nvox
    chunk = int(max(1, min(samples, _CHUNK_BYTES // (per_sample * constraint.ntag))))
    starts = [(s, min(chunk, samples - s)) for s in range(0, samples, chunk)]
    # frame 0: one reference-noise field per sample, shared by all its frames
    dphi0 = np.zeros((samples, *constraint.reference_valid.shape), dtype=np.float32)
    H0 = frame_harmonic(raw, 0)
    for s, count in starts:
        fields = harmonic_fields(noise, raw, rng, count)
        dphi0[s : s + count] = perturbed_phases(
            raw, H0, fields, constraint.points, constraint.reference_phase, order
        )
    ntime, ndof = U.shape
    dU = np.zeros((samples, ntime, ndof))
    noise_residual = np.full(ntime, np.nan)
    step = np.zeros(ntime)
    previous = None
    frames: dict[int, _Frame] = {}
    for n in range(1, ntime):
        frame = frames[n] = _frame_system(problem, n)
        step[n] = frame.step
        st = frame.state
        points = constraint.current_points(U[n])
        baseline, _ = PhaseSampler(raw, n, order=order).phase(points, per_tag=True)
        Hn = frame_harmonic(raw, n)
        w = st.weight[:, None] * st.tag_valid
        mean_abs = 0.0
        for s, count in starts:
            fields = harmonic_fields(noise, raw, rng, count)
            dphi = perturbed_phases(raw, Hn, fields, points, baseline, order)
            delta = np.where(st.tag_valid, dphi - dphi0[s : s + count], 0.0)
            mean_abs += float((w * np.abs(delta)).sum()) / max(float(w.sum()), 1e-300)
            dU[s : s + count, n] = _respond(
                problem, frame, delta, previous, dU[s : s + count, n - 1]
            )
        noise_residual[n] = mean_abs / samples
        previous = frame.mechanical
    if problem.correction is not None:
        for s, count in starts:
            dU[s : s + count] += _blur_feedback(problem, frames, dU[s : s + count])
    return dU, noise_residual, step


def _respond(
    problem: Problem, frame: _Frame, delta: FloatArray, previous: Any, last: FloatArray
) -> FloatArray:
    """Displacement changes (k, ndof) of a frame for residual changes ``delta`` (k, nq, ntag);
    ``previous`` K_mech of the last frame and ``last`` its changes (increment
    regularisation), else None."""
    st, constraint = frame.state, problem.constraint
    constraint.penalty = frame.penalty
    rhs = np.empty((problem.free.size, delta.shape[0]))
    for m in range(delta.shape[0]):  # one force assembly per sample (vectorised over points)
        moved = ConstraintState(delta[m], st.gradient, st.weight, st.tag_valid,
                                st.robust_weight)  # fmt: skip
        force = -constraint.force(moved)
        if previous is not None:  # increment regularisation: the last frame's change
            force += previous @ last[m]
        rhs[:, m] = force[problem.free]
    du = np.zeros((delta.shape[0], problem.U.shape[1]))
    du[:, problem.free] = frame.lu.solve(rhs).T
    return problem.remove_unseen(du)


def _blur_feedback(problem: Problem, frames: dict[int, _Frame], dU: FloatArray) -> FloatArray:
    """The further change (k, time, dof) of the motions ``U + dU`` (k samples) through the blur
    correction: the final pass tracked images deblurred by the correction of the previous
    pass's motion, which the noise moved too (module notes)."""
    constraint, U, raw = problem.constraint, problem.U, problem.raw
    assert problem.correction is not None
    count, ntime, _ = dU.shape
    # the correction of each perturbed motion, less that of the tracked one (tag, time, ...)
    change = [blur_correction(raw, problem.body, U + dU[m]) - problem.correction
              for m in range(count)]  # fmt: skip
    out = np.zeros_like(dU)
    previous = None
    for n in range(1, ntime):
        points = constraint.current_points(U[n])
        baseline, _ = PhaseSampler(constraint.phase, n, order=constraint.spline_order).phase(
            points, per_tag=True
        )
        deblurred_n = frame_harmonic(constraint.phase, n)
        # the deblurred image with the perturbed correction removed instead: H e^{-i δc}
        fields = np.stack([deblurred_n * np.expm1(-1j * c[:, n]).astype(np.complex64)
                           for c in change], axis=1)  # fmt: skip
        dphi = perturbed_phases(constraint.phase, deblurred_n, fields, points, baseline,
                                 constraint.spline_order)  # fmt: skip
        delta = np.where(frames[n].state.tag_valid, dphi, 0.0)
        out[:, n] = _respond(problem, frames[n], delta, previous, out[:, n - 1])
        previous = frames[n].mechanical
    return out
