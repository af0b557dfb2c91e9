r"""Step 2: one linear equilibrium correction of a direct activation estimate.

One linear correction (not an optimisation loop)
------------------------------------------------
In a whole organ the element estimates are biased low (by about half for the tongue
scene: each muscle works against its neighbours and the attachments). :func:`correct_activation`
removes that bias with the model itself, without a search: at the tracked configuration
:math:`u` it takes one Newton step of the forward model with the per-muscle activations
:math:`t` as unknowns, :math:`\delta u = -K^{-1}(R_p(u) + \sum_m t_m B_m(u))`, and requires
that the step leaves every muscle's mean fibre stretch where the images put it,

.. math::

    \sum_m S_{km}\, t_m = -r_k, \qquad S_{km} = -D_k K^{-1} B_m, \qquad r_k = -D_k K^{-1} R_p,

a linear system of the size of the number of muscles (:math:`D_k` = derivative of muscle
:math:`k`'s mean stretch, :math:`R_p` the passive residual, :math:`B_m` the residual of a
unit :math:`T_{max}` in muscle :math:`m`, :math:`K` the tangent at :math:`u` with the direct
estimates). It is exact when the tracked motion is an equilibrium of the model, needs one
factorisation, and propagates tracking errors like any stretch-matching estimate,
:math:`\delta t = -S^{-1}\delta\bar\lambda`.

"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from scipy import sparse
from scipy.sparse import linalg as spla

from harpx._typing import FloatArray
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.inverse._common import (
    attrs,
    matching_regions,
    region_means,
    time_index,
    tracked_u,
)
from harpx.mechanics.assembly import internal_forces
from harpx.mechanics.body import Body
from harpx.mechanics.fiber_laws import ActiveContraction
from harpx.physiology.active import default_law, fibred_body, with_active_law

__all__ = ["correct_activation"]


def _residual(body: Body, u: FloatArray) -> FloatArray:
    """Internal force vector at ``u``, whose tangent the caller found admissible (mN)."""
    r = internal_forces(body, u, tangent=False).r
    assert r is not None  # same state as the admissible tangent: no inverted cell
    return r


def _stretch_derivative(body: Body, u: FloatArray, du: FloatArray) -> FloatArray:
    """Cell-averaged ``dλ`` for displacement directions ``du`` (m, ndof) -> (m, ncell)."""
    F = body.deformation_gradient(u)
    f0 = body.fibers_qp
    assert f0 is not None  # checked by fibred_body
    a = np.einsum("eqiJ,eqJ->eqi", F, f0)
    lam = np.linalg.norm(a, axis=-1)
    out = []
    for d in du:  # loop over the few regions
        dF = body.deformation_gradient(d) - np.eye(3)
        dlam = np.einsum("eqi,eqiJ,eqJ->eq", a, dF, f0) / lam
        out.append(body.cell_average(dlam))
    return np.asarray(out)


def correct_activation(
    estimate: xr.Dataset,
    tracked: xr.Dataset,
    body: Body,
    *,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    time: int | None = None,
    law: ActiveContraction | None = None,
) -> xr.Dataset:
    r"""Refine a direct activation estimate with one linear equilibrium correction.

    Parameters
    ----------
    estimate : xarray.Dataset
        Output of :func:`estimate_activation` (``t_max`` over ``region``, kPa); its values
        only set the linearisation point (a NaN level counts as 0 there).
    tracked : xarray.Dataset
        The ``tracked/1`` result the estimate came from.
    body : Body
        The tracked model (fibres, regions); not modified.
    dirichlet : sequence, optional
        Boundary conditions of the model, e.g. ``[Fixed("mandible"), Fixed("base")]``.
    terms : sequence, optional
        Further loads (pressure, body force) acting in the tracked frame.
    time : int, optional
        Frame index of ``tracked``; default the estimate's ``time_index``.
    law : ActiveContraction, optional
        Active law; default ``body.active`` or ``ActiveContraction()``.

    Returns
    -------
    xarray.Dataset
        ``estimate`` with ``t_max`` (region) replaced by the corrected values (clipped at
        0; unclipped in ``t_max_linear``), the direct values kept in ``t_max_direct``, and
        the linear system: ``stretch_sensitivity`` (region, source_region), 1/kPa, and
        ``stretch_recoil`` (region); ``t_max_undetermined`` (region, bool) marks the
        regions whose activation changes no muscle's stretch at the tracked configuration
        (fibres past the law's active range): their ``t_max`` is NaN. attrs ``method`` is
        updated.

    Raises
    ------
    ValueError
        If ``tracked`` does not belong to ``body`` or the regions differ from the
        estimate's.

    Warns
    -----
    HarpxWarning
        If the tracked stretches do not determine a region's activation (``t_max`` NaN).

    Notes
    -----
    At the tracked configuration :math:`u` take *one* Newton step of the forward model
    with unknown per-muscle activations :math:`t`:
    :math:`\delta u = -K^{-1}\big(R_p(u) + \sum_m t_m B_m(u)\big)`, with :math:`R_p` the
    passive residual, :math:`B_m` the residual of a unit :math:`T_{max}` in muscle
    :math:`m` (the residual is linear in each :math:`T_{max}`) and :math:`K` the consistent
    tangent at :math:`u` (activations of ``estimate``; Dirichlet dofs held). Require that
    the step leaves each muscle's volume-weighted mean fibre stretch :math:`\bar\lambda_k`
    unchanged — the model holds the tracked shortening:

    .. math::

        \sum_m S_{km} t_m = -r_k, \qquad
        S_{km} = -D_k K^{-1} B_m, \quad r_k = -D_k K^{-1} R_p ,

    with :math:`D_k = \partial\bar\lambda_k/\partial u`. :math:`r_k` is the (linearised)
    recoil of muscle :math:`k` if every activation were switched off and :math:`S_{km}`
    the shortening per kPa of muscle :math:`m`. This is one linear solve of size
    (number of muscles), not an optimisation loop; it is exact when the tracked motion is
    an equilibrium of the model (tested), and its error propagation is that of the
    tracked mean stretches, :math:`\delta t = -S^{-1} \delta\bar\lambda`. Equivalently it
    is the virtual-fields method with the adjoint fields of the muscle-mean stretches as
    virtual fields.
    """
    fibred_body(body)
    law = default_law(body, law)
    names = matching_regions(estimate, body)
    index = time_index(tracked, int(estimate.attrs.get("time_index", -1)) if time is None else time)
    u = tracked_u(tracked, body, index)
    t0 = np.nan_to_num(np.asarray(estimate["t_max"].values, dtype=np.float64))
    active = with_active_law(body, law)
    active.set_t_max(dict(zip(names, t0.tolist(), strict=True)))
    internal = internal_forces(active, u, tangent=True)
    if internal.K is None:
        raise ValueError(
            f"the tracked frame {index} has inverted cells {internal.inverted_cells[:10]!r}; "
            "the activation cannot be corrected there"
        )
    K = internal.K
    R_extra = np.zeros(body.ndof)
    for term in terms:  # the few extra loads
        r_t, K_t = term.residual_tangent(active, u, 1.0)
        R_extra += np.asarray(r_t, dtype=np.float64)
        if K_t is not None:
            K = K + K_t
    active.set_t_max(0.0)
    R_p = _residual(active, u) + R_extra
    rhs = [R_p]
    for name in names:  # residual per unit T_max of each region (linear in T_max)
        active.set_t_max({name: 1.0})
        rhs.append(_residual(active, u) + R_extra - R_p)
    fixed = [np.asarray(d.dofs(body), dtype=np.int64) for d in dirichlet]
    is_fixed = np.zeros(body.ndof, dtype=bool)
    if fixed:
        is_fixed[np.concatenate(fixed)] = True
    free = np.nonzero(~is_fixed)[0]
    K_ff = sparse.csc_matrix(sparse.csr_matrix(K)[free][:, free])
    X = spla.splu(K_ff).solve(np.asarray(rhs)[:, free].T)
    du = np.zeros((len(rhs), body.ndof))
    du[:, free] = -X.T
    dcell = _stretch_derivative(body, u, du)  # (1 + nregion, ncell)
    D = np.array([region_means(body, names, d) for d in dcell])  # (1 + nregion, nregion)
    recoil, S = D[0], D[1:].T  # S[k, m]: stretch change of region k per kPa in region m
    reach = np.abs(S).max(axis=0)
    undetermined = ~(reach > 1e-10 * reach.max())  # g = 0 there: T_max moves nothing
    t1 = np.full(len(names), np.nan)
    if not undetermined.all():
        t1[~undetermined] = np.linalg.lstsq(S[:, ~undetermined], -recoil, rcond=None)[0]
    if undetermined.any():
        warnings.warn(
            "the tracked stretches do not determine the activation of region(s) "
            f"{[n for n, u in zip(names, undetermined, strict=True) if u]!r}: a unit T_max "
            "there changes no muscle's stretch (their fibres are shortened past the law's "
            "active range, g = 0, at the tracked configuration), so their corrected t_max is "
            "NaN ('t_max_undetermined'), not 0",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    out = estimate.copy()
    out = out.assign_coords(
        source_region=("source_region", names, {"units": "1", "long_name": "activated region"})
    )
    out["t_max_direct"] = ("region", np.asarray(estimate["t_max"].values), attrs("t_max_direct"))
    out["t_max_linear"] = ("region", t1, attrs("t_max_linear"))
    out["t_max"] = ("region", np.maximum(t1, 0.0), attrs("t_max"))
    out["stretch_sensitivity"] = (("region", "source_region"), S, attrs("stretch_sensitivity"))
    out["stretch_recoil"] = ("region", recoil, attrs("stretch_recoil"))
    out["t_max_undetermined"] = ("region", undetermined, attrs("t_max_undetermined"))
    out.attrs["method"] = (
        "direct (uniaxial fibre equilibrium per element) + one linear equilibrium correction "
        "at the tracked configuration"
    )
    return out
