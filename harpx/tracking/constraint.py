r"""The harmonic-phase conservation constraint as a body force on a finite-element model.

With :math:`\phi(x, t)` the vector of harmonic phases (one per tag direction) sampled at the
current position :math:`x = X + u(X)` of a material point and :math:`\phi_0(X) = \phi(X, t_0)`
its phase in the reference frame, the constraint energy is

.. math::

    \Pi_c(u) = \int_{\mathcal R} \tfrac12\, m(X)
        \sum_t \Big(\lambda\, r_t^2 + 2\Lambda_t r_t\Big)\, dV,
    \qquad r_t = W\big(\phi_t(x, t) - \phi_{0,t}(X)\big),

with :math:`W(a) = \operatorname{angle}(e^{ia})` the wrap to :math:`[-\pi, \pi)`, :math:`m` the
data mask, :math:`\lambda` the penalty (kPa/rad²) and :math:`\Lambda` per-point
augmented-Lagrangian multipliers (kPa/rad). Because :math:`\partial r_t/\partial x = \nabla\phi_t`
(the wrap is locally the identity), its contribution to the residual is the body force of
paper eq. 5,

.. math::

    r^c_{ai} = \int m\, N_a \sum_t (\nabla\phi_t)_i\, (\lambda r_t + \Lambda_t)\, dV ,

and the Gauss–Newton tangent of paper eq. 6 drops the phase Hessian:

.. math::

    K^c_{ai,bk} = \int m\, \lambda\, N_a N_b \sum_t (\nabla\phi_t)_i (\nabla\phi_t)_k\, dV .

The integral uses its own quadrature (``intorder``), dense enough that sample points are no
farther apart than a voxel, so the model sees every voxel of data; the phase images are
prefiltered once per frame (:class:`harpx.imaging.sample.PhaseSampler`), not per Newton
iteration. Phase gradients come from the complex harmonic image, never from differences of
wrapped phase (those jump by 2π across every tag line).

The penalty is stated relative to the material: ``penalty = 1`` makes the data stiffness
per unit volume, :math:`\lambda |k|^2`, equal to the material stiffness per unit volume at
the element scale, :math:`\mu / h^2`, with :math:`\mu` the small-strain shear modulus,
:math:`|k| = 2\pi f` the tag wavenumber and :math:`h` the mean element size. The same
relative penalty therefore serves stiffer or softer materials and other tag spacings.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import skfem
import xarray as xr
from scipy import sparse

from harpx._blas import matmul_one_thread
from harpx._typing import FloatArray, IntArray
from harpx.imaging.phase_parameters import PhaseParameters
from harpx.imaging.sample import PhaseSampler, wrap
from harpx.mechanics.assembly import sparsity
from harpx.schema import GRID_DIMS, grid_step
from harpx.tracking.constraint_points import ConstraintState, constraint_quadrature, epsilon_of
from harpx.tracking.noise import epsilon_floor, noise_floor, reference_residual
from harpx.tracking.observability import Observability, observability

if TYPE_CHECKING:
    from harpx.mechanics.body import Body

__all__ = [
    "ConstraintState",
    "PhaseConstraint",
    "WINDOW_PERIODS",
    "constraint_quadrature",
    "shear_modulus",
]

# floats per temporary block when forming element matrices (bounds memory to ~64 MB)
_BLOCK_FLOATS = 8_000_000


def shear_modulus(body: Body) -> float:
    """Small-strain shear modulus μ (kPa) of the body's material, from its tangent at F = I.

    Parameters
    ----------
    body : Body
        The finite-element body; only its ``material`` is used (a fibre material is
        evaluated with the fibre along x).

    Returns
    -------
    float
        μ, the component A_xyxy of the isochoric tangent at F = I, kPa.
    """
    material = body.material
    fiber = None
    if getattr(material, "needs_fibers", False):
        fiber = np.array([[1.0, 0.0, 0.0]])
    _, A = material.isochoric_response(np.eye(3)[None], fiber)
    # a shear across the fibre plane (x–y), A_xyxy = μ for an isotropic solid
    return float(A[0, 0, 1, 0, 1])


#: Tag periods (of the longest tag period) by which the box a frame's images are prepared in
#: reaches beyond its starting points on every side (:meth:`PhaseConstraint.set_frame`):
#: more than a frame's motion on every scene measured; a point beyond it makes the frame's
#: images be prepared on the whole grid.
WINDOW_PERIODS = 2.0

#: Phase samplings of a frame (:meth:`PhaseConstraint.epsilon_at`, e.g. the predictor's
#: candidates) whose harmonic magnitudes are kept for a noise floor at one of them
_MAGNITUDE_MEMO = 4


def _harmonic_noise(phase: xr.Dataset) -> FloatArray | None:
    """The images' ``harmonic_noise`` per tag, or None where absent or not finite."""
    if "harmonic_noise" not in phase.variables:
        return None
    sigma = np.asarray(phase["harmonic_noise"].values, dtype=np.float64).reshape(-1)
    return sigma if bool(np.all(np.isfinite(sigma) & (sigma >= 0))) else None


class PhaseConstraint:
    r"""Phase-conservation body force and Gauss–Newton tangent for one body and phase series.

    Parameters
    ----------
    body : Body
        The finite-element body in its reference configuration (frame 0), mm.
    phase : xarray.Dataset
        A ``phase/1`` dataset.
    intorder : int, optional
        Isotropic Gauss order of the constraint quadrature. Default: a tensor rule with
        points at most one acquired voxel apart (:func:`constraint_quadrature`).
    spline_order : {1, 3}, default 1
        Interpolation of the demodulated harmonic images between voxels. The demodulated
        image varies on the scale of the strain, not of the tags, so trilinear
        interpolation is as accurate as cubic for tracking, at a fraction of the cost.
    robust_scale : float, optional
        Residual scale :math:`r_0` (rad) of a Cauchy (Lorentzian) loss on each point's
        phase mismatch: the penalty energy :math:`\tfrac12 \lambda r^2` becomes
        :math:`\tfrac12 \lambda r_0^2 \ln(1 + r^2/r_0^2)`, so its force is
        :math:`\lambda\, w(r)\, r\, \nabla\phi` with :math:`w = 1/(1 + r^2/r_0^2)` (and the
        Gauss–Newton tangent uses the same :math:`w`, iteratively reweighted least squares).
        A point whose phase sits in a neighbouring tag's basin (:math:`|r|` near π) then
        pulls with a fraction :math:`(r_0/\pi)^2` of its quadratic force, so a high penalty
        cannot drag the body across a wrap. None (the paper's formulation): quadratic.

    Attributes
    ----------
    points : ndarray, shape (nq, 3)
        Reference positions of the constraint points, mm (cell-major).
    volume : ndarray, shape (nq,)
        Reference volume of each point, mm³.
    reference_phase : ndarray, shape (nq, ntag)
        φ0 at the points, rad.
    reference_valid : ndarray of bool, shape (nq, ntag)
        Which tags have data at each point in the reference frame (inside the field of
        view, the tag's mask and above its magnitude floor). A point keeps the tags it has:
        e.g. where only long-axis slices image the apex, only their tag pulls it.
    penalty : float
        Current penalty λ, kPa/rad² (absolute).
    multipliers : ndarray, shape (nq, ntag)
        Augmented-Lagrangian multipliers Λ, kPa/rad.

    Raises
    ------
    ValueError
        If ``robust_scale`` is not a positive number.
    """

    def __init__(
        self,
        body: Body,
        phase: xr.Dataset,
        *,
        intorder: int | None = None,
        spline_order: int = 1,
        robust_scale: float | None = None,
    ) -> None:
        self.body = body
        if robust_scale is not None and not (np.isfinite(robust_scale) and robust_scale > 0):
            raise ValueError(f"robust_scale={robust_scale!r} must be a positive number of rad")
        self.robust_scale = None if robust_scale is None else float(robust_scale)
        self.phase = phase
        # the acquired voxel: grid spacing times the upsampling factor of the phase images
        upsample = PhaseParameters.from_dataset(phase).upsample
        spacing = upsample * min(
            abs(step) for step in (grid_step(phase, d) for d in GRID_DIMS) if step is not None
        )
        element = body.scalar_element
        if intorder is None:
            basis = skfem.CellBasis(
                body.mesh,
                element,
                quadrature=constraint_quadrature(body, spacing),
            )
        else:
            basis = skfem.CellBasis(body.mesh, element, intorder=int(intorder))
        self.intorder = intorder
        nb = len(basis.basis)
        self.shape_values = np.stack([np.asarray(basis.basis[a][0]) for a in range(nb)], axis=-1)
        ncell, npc = self.shape_values.shape[:2]
        self.points_per_cell = npc
        self._shared_products = _shared_shape_products(self.shape_values, body)
        self.points = np.ascontiguousarray(
            np.asarray(basis.global_coordinates()).transpose(1, 2, 0).reshape(-1, 3)
        )
        self.volume = np.asarray(basis.dx, dtype=np.float64).ravel()
        self._cell_dofs = body.element_dofs  # (ncell, nb, 3)
        self.spline_order = int(spline_order)
        reference = PhaseSampler(phase, 0, order=self.spline_order)
        phi0, _, valid0 = reference.sample(self.points, per_tag=True)
        self.reference_phase = phi0
        self.reference_valid = valid0
        self.ntag = phi0.shape[1]
        self.directions = np.asarray(
            phase["tag_direction"].transpose("tag", "axis").sel(axis=["x", "y", "z"]), dtype=float
        )
        self.wavevectors = (
            2.0 * np.pi * np.asarray(phase["tag_frequency"], dtype=float)[:, None]
        ) * self.directions
        self.reference_noise = reference_residual(
            self.points, self.volume, phi0, valid0, self.wavevectors
        )
        point_magnitude = reference.magnitude(self.points)[0]
        self.reference_magnitude = self._mean_magnitude(point_magnitude, valid0)
        self.harmonic_noise = _harmonic_noise(phase)
        self._reference_point_magnitude = None if self.harmonic_noise is None else point_magnitude
        self.observability: Observability | None = None
        self.penalty = 0.0
        self.multipliers = np.zeros_like(phi0)
        self._sampler: PhaseSampler | None = None
        # the harmonic magnitudes of the last few phase samplings of this frame (epsilon_at),
        # for a noise floor at one of their displacements: (u, sampler, |H| (nq, ntag),
        # valid (nq,))
        self._magnitudes: list[tuple[FloatArray, PhaseSampler, FloatArray, np.ndarray]] = []
        self.frame = 0
        k = 2.0 * np.pi * np.asarray(phase["tag_frequency"], dtype=float)
        self.wavenumber = float(np.sqrt(np.mean(k**2)))
        self.max_wavenumber = float(np.max(k))
        self.min_wavenumber = float(np.min(k))
        self.element_size = float(np.cbrt(np.mean(body.cell_volume)))
        self.shear_modulus = shear_modulus(body)

    # ------------------------------------------------------------------ set-up
    def penalty_scale(self) -> float:
        """Absolute penalty (kPa/rad²) that corresponds to a relative penalty of 1.

        Returns
        -------
        float
            μ / (k h)², with μ the shear modulus, k the root-mean-square tag wavenumber and
            h the mean element size (module notes), kPa/rad².
        """
        return self.shear_modulus / (self.wavenumber * self.element_size) ** 2

    def observe(self, fixed_dofs: np.ndarray) -> Observability:
        """Work out what the tags see (:mod:`harpx.tracking.observability`) and apply it.

        From here on the phase force acts through each point's seen projector, and
        :attr:`observability` lists the rigid-body modes that neither the tags nor the
        Dirichlet dofs ``fixed_dofs`` hold.

        Parameters
        ----------
        fixed_dofs : array_like of int, shape (nfixed,)
            Indices of the displacement dofs held by Dirichlet conditions.

        Returns
        -------
        Observability
            The same object, stored as :attr:`observability`.
        """
        self.observability = observability(
            self.body,
            self.points,
            self.volume,
            self.shape_values,
            self._cell_dofs,
            self.directions,
            self.reference_valid,
            np.asarray(fixed_dofs, dtype=np.int64),
        )
        return self.observability

    def _mean_magnitude(self, magnitude: FloatArray, valid: np.ndarray) -> FloatArray:
        """Volume-weighted mean of ``magnitude`` (nq, ntag) over the ``valid`` points, per tag."""
        w = self.volume[:, None] * valid
        total = w.sum(axis=0)
        return np.where(total > 0, (w * magnitude).sum(axis=0) / np.where(total > 0, total, 1), 0)

    def epsilon_floor(self, u: FloatArray) -> float:
        """Noise floor of ε in the current frame with the tissue at ``u`` (rad).

        See :mod:`harpx.tracking.noise`: the phase noise of both frames where the images
        carry ``harmonic_noise``; otherwise the affine-fit residual of the reference frame
        (alone in frame 0), grown by the tags' fading.

        Parameters
        ----------
        u : ndarray, shape (ndof,)
            Displacement, mm (where the current frame's harmonic magnitudes are sampled;
            unused in frame 0 or before :meth:`set_frame`).

        Returns
        -------
        float
            Expected ε of the phase noise alone, rad.
        """
        if self.harmonic_noise is not None and self._reference_point_magnitude is not None:
            if self.frame == 0 or self._sampler is None:
                magnitude, valid = self._reference_point_magnitude, self.reference_valid
            else:
                magnitude, now = self._point_magnitude(u)
                valid = self.reference_valid & now[:, None]
            return noise_floor(
                self.harmonic_noise, self._reference_point_magnitude, magnitude, self.volume,
                valid,
            )  # fmt: skip
        share = (self.volume[:, None] * self.reference_valid).sum(axis=0)
        share = share / max(float(share.sum()), 1e-300)
        if self.frame == 0 or self._sampler is None:
            ok = np.isfinite(self.reference_noise)
            return float((share[ok] * self.reference_noise[ok]).sum() / share[ok].sum())
        magnitude = self._mean_magnitude(self._point_magnitude(u)[0], self.reference_valid)
        return epsilon_floor(self.reference_noise, self.reference_magnitude, magnitude, share)

    def _point_magnitude(self, u: FloatArray) -> tuple[FloatArray, np.ndarray]:
        """``|H|`` (nq, ntag) of the current frame at the points displaced by ``u``, and
        which points are valid for every tag (nq,): from :meth:`epsilon_at`'s sampling at
        the same ``u`` in this frame if there was one, else sampled."""
        for seen, sampler, magnitude, valid in self._magnitudes:
            if sampler is self._sampler and np.array_equal(seen, u):
                return magnitude, valid
        points = self.current_points(u)
        return self._frame_sampler(points).magnitude(points)

    def replace_images(self, phase: xr.Dataset) -> None:
        """Read later frames from ``phase`` (same grid and tags, frame 0 unchanged).

        Used by the blur correction (:mod:`harpx.tracking.blur`), which leaves the reference
        frame as it is: the reference samples, the noise floor and the observability
        worked out from it stay valid, so the set-up is not repeated.

        Parameters
        ----------
        phase : xarray.Dataset
            A ``phase/1`` dataset on the same grid, with the same tags and frame count and
            the same frame 0 (to 1e-5 rad); the current frame must be set again
            (:meth:`set_frame`).

        Raises
        ------
        ValueError
            If ``phase`` has another grid, other tags, or a different frame 0.
        """
        same = all(phase.sizes[d] == self.phase.sizes[d] for d in ("tag", "time", "z", "y", "x"))
        if same:
            # frame 0 in the images' own precision, compared a block of planes at a time: no
            # grid-sized float64 temporaries
            new, old = (np.asarray(p["phase"].isel(time=0).transpose("tag", ...).values)
                        for p in (phase, self.phase))  # fmt: skip
            new = new.reshape(-1, *new.shape[-2:])
            old = old.reshape(new.shape)
            step = max(1, (1 << 18) // max(1, new[0].size))
            same = all(
                np.abs(wrap(new[k : k + step] - old[k : k + step])).max(initial=0.0) <= 1e-5
                for k in range(0, new.shape[0], step)
            )
            del new, old
        if not same:
            raise ValueError(
                "replace_images needs images on the same grid and tags with frame 0 unchanged"
            )
        self.phase = phase
        self._use_sampler(None)

    def release_frame(self) -> None:
        """Drop the sampler of the current frame (its grid-sized buffers) until the next
        :meth:`set_frame`; evaluating the constraint before that raises RuntimeError."""
        self._use_sampler(None)

    def _use_sampler(self, sampler: PhaseSampler | None) -> None:
        """Sample the current frame with ``sampler`` from now on (None: no frame ready); the
        magnitudes kept from another sampler no longer apply."""
        self._sampler = sampler
        self._magnitudes = []

    def set_frame(self, time_index: int, near: FloatArray | None = None) -> None:
        """Target the phase images of frame ``time_index`` (prepares them once).

        Parameters
        ----------
        time_index : int
            Index of the frame along ``time``.
        near : ndarray, shape (ndof,), optional
            A displacement the frame's solves start close to, mm. The images are then
            prepared only in the box its points occupy, widened by :data:`WINDOW_PERIODS`
            tag periods on every side; should a point leave that box later, they are
            prepared on the whole grid (the box bounds the work, never what can be
            sampled). None: the whole grid.
        """
        region = None
        if near is not None:
            points = self.current_points(near)
            reach = WINDOW_PERIODS * 2.0 * np.pi / self.min_wavenumber
            region = np.stack([points.min(axis=0) - reach, points.max(axis=0) + reach])
            if not np.isfinite(region).all():  # no box to speak of: the whole grid
                region = None
        # the previous frame's sampler is done with: its tap buffer is reused
        self._use_sampler(PhaseSampler(
            self.phase, int(time_index), order=self.spline_order, reuse=self._sampler,
            region=region,
        ))  # fmt: skip
        self.frame = int(time_index)

    def _frame_sampler(self, points: FloatArray) -> PhaseSampler:
        """The current frame's sampler, prepared on the whole grid if ``points`` leave its
        window (:meth:`set_frame`)."""
        sampler = self._sampler
        if sampler is None:
            raise RuntimeError("call set_frame(time_index) before evaluating the constraint")
        if sampler.outside_window(points):
            sampler = PhaseSampler(self.phase, self.frame, order=self.spline_order, reuse=sampler)
            self._use_sampler(sampler)
        return sampler

    def current_points(self, u: FloatArray) -> FloatArray:
        """Current positions x = X + u(X) of the constraint points.

        Parameters
        ----------
        u : ndarray, shape (ndof,)
            Displacement, mm.

        Returns
        -------
        ndarray, shape (nq, 3)
            Positions (x, y, z), mm, in the order of :attr:`points`.
        """
        ue = u[self._cell_dofs]  # (ncell, nb, 3)
        disp = np.matmul(self.shape_values, ue)
        return self.points + disp.reshape(-1, 3)

    # ------------------------------------------------------------------ evaluation
    def state(self, u: FloatArray) -> ConstraintState:
        """Phase mismatch, gradients and weights at displacement ``u``.

        Parameters
        ----------
        u : ndarray, shape (ndof,)
            Displacement, mm.

        Returns
        -------
        ConstraintState
            The state of every constraint point in the current frame (:meth:`set_frame`),
            phase gradients projected onto the seen directions once :meth:`observe` ran.
        """
        points = self.current_points(u)
        phi, grad, valid = self._frame_sampler(points).sample(points, per_tag=True)
        ok = valid & self.reference_valid  # (nq, ntag)
        residual = np.where(ok, wrap(phi - self.reference_phase), 0.0)
        grad = np.where(ok[..., None], grad, 0.0)
        if self.observability is not None and (self.observability.point_rank < 3).any():
            # the force acts along seen directions only (module notes of observability)
            # P g per point and tag, written g P (the projectors are symmetric, V Vᵀ): a
            # batched matmul, much faster than the equivalent einsum
            grad = np.matmul(grad, self.observability.projectors)
        robust = None
        if self.robust_scale is not None:
            robust = 1.0 / (1.0 + (residual / self.robust_scale) ** 2)
        return ConstraintState(residual, grad, self.volume * ok.any(axis=1), ok, robust)

    def epsilon_at(self, u: FloatArray) -> float:
        """Tracking residual ε at displacement ``u`` (phase only, no gradients).

        Parameters
        ----------
        u : ndarray, shape (ndof,)
            Displacement, mm.

        Returns
        -------
        float
            ε in the current frame, rad (NaN if no point has data).
        """
        points = self.current_points(u)
        sampler = self._frame_sampler(points)
        phi, magnitude, valid = sampler.phase_and_magnitude(points)
        seen = (np.array(u, dtype=np.float64), sampler, magnitude, np.all(valid, axis=1))
        self._magnitudes = [*self._magnitudes, seen][-_MAGNITUDE_MEMO:]
        ok = valid & self.reference_valid
        return epsilon_of(self.volume, ok, np.where(ok, wrap(phi - self.reference_phase), 0.0))

    def residual_tangent(
        self, body: Body, u: FloatArray, s: float = 1.0
    ) -> tuple[FloatArray, sparse.csr_matrix]:
        """Contribution to the residual R(u) = f_int − f_ext and its Gauss–Newton tangent.

        Parameters
        ----------
        body : Body
            The body (must be the one the constraint was built for).
        u : ndarray, shape (ndof,)
            Displacement, mm.
        s : float, default 1
            Load factor (scales the penalty and multipliers).

        Returns
        -------
        r : ndarray, shape (ndof,)
            Residual contribution, mN.
        K : scipy.sparse.csr_matrix
            Gauss–Newton tangent on the body's stiffness pattern, mN/mm.
        """
        st = self.state(u)
        return self.assemble(st, s)

    def force(self, st: ConstraintState, s: float = 1.0) -> FloatArray:
        """Residual contribution (paper eq. 5) from an evaluated state (no tangent).

        Parameters
        ----------
        st : ConstraintState
            State from :meth:`state`.
        s : float, default 1
            Load factor (scales the penalty and multipliers).

        Returns
        -------
        ndarray, shape (ndof,)
            Residual contribution, mN.
        """
        N = self.shape_values  # (c, q, a)
        ncell, npc, nb = N.shape
        drive = s * self.penalty * st.penalty_weight() * st.residual
        drive = drive + s * self.multipliers * st.tag_valid
        force = np.einsum("qt,qti->qi", drive, st.gradient) * st.weight[:, None]
        fe = np.matmul(N.transpose(0, 2, 1), force.reshape(ncell, npc, 3))  # (c, a, i)
        ndof = int(self.body.ndof)
        # numpy's stub types every bincount as int; with float weights it is float64
        return np.bincount(self._cell_dofs.ravel(), weights=fe.ravel(), minlength=ndof)  # type: ignore[return-value]

    def assemble(self, st: ConstraintState, s: float = 1.0) -> tuple[FloatArray, sparse.csr_matrix]:
        """Residual and tangent from an evaluated :class:`ConstraintState`.

        Parameters
        ----------
        st : ConstraintState
            State from :meth:`state`.
        s : float, default 1
            Load factor (scales the penalty and multipliers).

        Returns
        -------
        r : ndarray, shape (ndof,)
            Residual contribution, mN.
        K : scipy.sparse.csr_matrix
            Gauss–Newton tangent on the body's stiffness pattern, mN/mm.
        """
        N = self.shape_values  # (c, q, a)
        ncell, npc, nb = N.shape
        r = self.force(st, s)
        # λ w Σ_t w_t g_t g_tᵀ per point: rows (i, k), columns the points (c, q)
        M = _point_blocks(st.gradient, st.robust_weight, (s * self.penalty) * st.weight)
        pat = sparsity(self.body)
        if self._shared_products is not None:
            # every cell has the same N at its points: K[(i, k, c), ab] = Σ_q M[ik, c, q]
            # NN[q, ab] is one matrix product, scattered in its own layout (i, k, c, a, b)
            NN, positions = self._shared_products
            K = matmul_one_thread(M.reshape(9 * ncell, npc), NN)
            data: FloatArray = np.bincount(  # type: ignore[assignment]
                positions, weights=K.ravel(), minlength=pat.nnz
            )
            return r, pat.matrix(data)
        # K_e[a, i, k, b] = Σ_q N_a N_b M_q[i, k], as (c, ab, q) @ (c, q, ik) in cell blocks
        Mc = M.reshape(9, ncell, npc).transpose(1, 2, 0)  # (c, q, ik)
        Ke = np.empty((ncell, nb, 3, 3, nb))
        block = max(1, _BLOCK_FLOATS // (npc * nb * nb))
        for start in range(0, ncell, block):  # a few blocks bound the memory, not a cell loop
            sl = slice(start, min(start + block, ncell))
            NN = (N[sl, :, :, None] * N[sl, :, None, :]).reshape(-1, npc, nb * nb)
            K = np.matmul(NN.transpose(0, 2, 1), Mc[sl])  # (c, ab, ik)
            Ke[sl] = K.reshape(-1, nb, nb, 3, 3).transpose(0, 1, 3, 4, 2)
        # numpy's stub types every bincount as int; with float weights it is float64
        data = np.bincount(  # type: ignore[assignment]
            pat.element_positions.ravel(), weights=Ke.ravel(), minlength=pat.nnz
        )
        return r, pat.matrix(data)

    def update_multipliers(self, st: ConstraintState) -> float:
        """Augmented-Lagrangian update Λ ← Λ + λ r of :attr:`multipliers`.

        Parameters
        ----------
        st : ConstraintState
            State from :meth:`state` (r is 0 where a tag has no data).

        Returns
        -------
        float
            Relative change ‖ΔΛ‖/‖Λ‖ of the updated multipliers (dimensionless; 0 if they
            are all 0).
        """
        step = self.penalty * st.residual * st.tag_valid
        new = self.multipliers + step
        norm = float(np.linalg.norm(new))
        change = float(np.linalg.norm(step)) / norm if norm > 0 else 0.0
        self.multipliers = new
        return change

    def epsilon_cell(self, st: ConstraintState) -> FloatArray:
        """Per-cell tracking residual: weighted mean ``|W(φ − φ0)|`` over the cell's points and
        their valid tags.

        Parameters
        ----------
        st : ConstraintState
            State from :meth:`state`.

        Returns
        -------
        ndarray, shape (ncell,)
            ε of each cell, rad (NaN for cells without data).
        """
        ncell, npc = self.shape_values.shape[:2]
        w = (st.weight[:, None] * st.tag_valid).reshape(ncell, -1)
        e = np.abs(st.residual).reshape(ncell, -1)
        total = w.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(total > 0, (w * e).sum(axis=1) / total, np.nan)


def _shared_shape_products(
    shape_values: FloatArray, body: Body
) -> tuple[FloatArray, IntArray] | None:
    """``(N_a N_b per point, CSR positions in (i, k, cell, a, b) order)`` when every cell has
    the same shape values at its constraint points (a mesh-wide quadrature on one element
    type), else None; :meth:`PhaseConstraint.assemble` then needs one matrix product."""
    first = shape_values[0]
    if not np.array_equal(shape_values, np.broadcast_to(first, shape_values.shape)):
        return None
    npc, nb = first.shape
    NN = (first[:, :, None] * first[:, None, :]).reshape(npc, nb * nb)
    positions = sparsity(body).element_positions.transpose(2, 3, 0, 1, 4)  # (i, k, c, a, b)
    return NN, np.ascontiguousarray(positions).ravel()


def _point_blocks(gradient: FloatArray, robust: FloatArray | None, scale: FloatArray) -> FloatArray:
    """Gauss–Newton blocks ``scale_q Σ_t w_qt g_qt g_qtᵀ`` of every point, shape (9, nq).

    ``gradient`` (nq, ntag, 3), ``robust`` the weights ``w`` (nq, ntag) or None (1),
    ``scale`` (nq,). Row ``3 i + k`` holds component (i, k) of every point: the products
    run on contiguous rows (numpy's stacked 3 × 3 products are several times slower).
    """
    rows = np.ascontiguousarray(gradient.transpose(1, 2, 0))  # (tag, i, point)
    weighted = rows if robust is None else rows * robust.T[:, None, :]
    M = np.empty((9, gradient.shape[0]))
    for i in range(3):
        for k in range(i, 3):
            np.einsum("tq,tq->q", weighted[:, i], rows[:, k], out=M[3 * i + k])
            M[3 * i + k] *= scale
            if k != i:
                M[3 * k + i] = M[3 * i + k]
    return M
