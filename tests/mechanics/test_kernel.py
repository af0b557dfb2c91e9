"""Factored tangent kernel: same element matrices and residuals as the former dense assembly."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.mechanics import (
    ActiveContraction,
    Body,
    FiberGrowth,
    Guccione,
    NeoHookean,
    box,
    kernel,
    tetrahedralize,
)
from harpx.mechanics.assembly import (
    _nodal_tangent,
    _pressure_space,
    _volumetric,
    internal_forces,
    material_response,
    sparsity,
)

NEO = NeoHookean(c1=1.0, kappa=120.0)
GUC = Guccione(c=2.0, bf=8.0, bt=2.0, bfs=4.0, kappa=120.0)

# both codes sum the same products in another order: round-off only (~1e-16 relative, a
# few hundred operations per entry)
RTOL = 1e-12


def _reference(body, u, pressure_stiffness=True):
    """The dense assembly of harpx 8f989f2 (4th-order tangent, volumetric terms apart)."""
    F = body.deformation_gradient(u)
    P, A = material_response(body, F, tangent=True)
    p, cof, J, extra = _volumetric(body, F)
    P = P + p[..., None, None] * cof
    G = body.grad_N
    dV = body.dV
    nel, nq, nb, _ = G.shape
    Gt = G.transpose(0, 2, 1, 3).reshape(nel, nb, nq * 3)
    Pt = (P * dV[..., None, None]).transpose(0, 1, 3, 2).reshape(nel, nq * 3, 3)
    re = np.matmul(Gt, Pt)
    r = np.bincount(body.element_dofs.ravel(), weights=re.ravel(), minlength=body.ndof)
    Bq = np.matmul(G, np.swapaxes(cof, -1, -2)).reshape(nel, nq, 3 * nb)
    if pressure_stiffness:
        w_geo = p / J * dV
        Mg = np.matmul(np.swapaxes(Bq, 1, 2), Bq * w_geo[..., None]).reshape(nel, nb, 3, nb, 3)
        Kvol = Mg - Mg.transpose(0, 1, 4, 3, 2)
    else:
        Kvol = np.zeros((nel, nb, 3, nb, 3))
    if "d2U" in extra:
        w_u = extra["d2U"] * dV
        Kvol += np.matmul(np.swapaxes(Bq, 1, 2), Bq * w_u[..., None]).reshape(nel, nb, 3, nb, 3)
    Q = extra.get("Q")
    if Q is not None:
        C = np.matmul(_pressure_space(body)[1], Bq)
        Kvol += np.matmul(np.swapaxes(C, 1, 2), np.matmul(Q, C)).reshape(nel, nb, 3, nb, 3)
    Ke = Kvol.transpose(0, 1, 2, 4, 3).copy()
    Ap = (A.transpose(0, 1, 3, 2, 4, 5) * dV[:, :, None, None, None, None]).reshape(nel, nq, 27, 3)
    B = np.matmul(Ap, G.transpose(0, 1, 3, 2))
    Ke += np.matmul(Gt, B.reshape(nel, nq * 3, 9 * nb)).reshape(nel, nb, 3, 3, nb)
    pat = sparsity(body)
    data = np.bincount(pat.element_positions.ravel(), weights=Ke.ravel(), minlength=pat.nnz)
    if extra.get("nodal") is not None:
        beta = np.matmul(np.swapaxes(extra["nodal_weights"], 1, 2), Bq)
        data += _nodal_tangent(body, pat, beta, extra["nodal"])
    return r, data


def _body(element, volumetric, case, rng):
    spec = box((1.0, 1.5, 1.0), (2, 2, 2))
    if element.startswith("tet"):
        spec = tetrahedralize(spec)
    kw: dict = {}
    if case in ("active", "active+growth"):
        kw["active"] = ActiveContraction(t_max=20.0)
    if case == "growth":
        kw["growth"] = FiberGrowth(1.15)
    mat = GUC if case in ("guccione", "active", "active+growth") else NEO
    probe = Body(spec, NEO, element=element)
    ncell = probe.ncell
    if case == "active+growth":
        kw["growth"] = rng.uniform(0.9, 1.1, ncell)
    fibers = rng.standard_normal((ncell, 3))
    body = Body(spec, mat, element=element, volumetric=volumetric, fibers=fibers, **kw)
    u = (0.04 if element in ("hex8", "tet4") else 0.015) * rng.standard_normal(body.ndof)
    return body, u


CASES = [
    (element, volumetric, case)
    for element, vols in (
        ("hex8", ("mean-dilatation", "pointwise")),
        ("hex20", ("mean-dilatation", "linear-dilatation", "pointwise")),
        ("tet4", ("nodal-dilatation",)),
        ("tet10", ("nodal-dilatation", "pointwise")),
    )
    for volumetric in vols
    for case in ("neo", "guccione", "active", "growth", "active+growth")
]


@pytest.mark.parametrize(("element", "volumetric", "case"), CASES)
@pytest.mark.parametrize("pressure_stiffness", [True, False])
def test_assembly_matches_former_dense_code(element, volumetric, case, pressure_stiffness, rng):
    body, u = _body(element, volumetric, case, rng)
    r_ref, data_ref = _reference(body, u, pressure_stiffness)
    res = internal_forces(body, u, pressure_stiffness=pressure_stiffness)
    scale = np.abs(data_ref).max()
    np.testing.assert_allclose(res.r, r_ref, rtol=0.0, atol=RTOL * np.abs(r_ref).max())
    np.testing.assert_allclose(res.K.data, data_ref, rtol=0.0, atol=RTOL * scale)


@pytest.mark.parametrize("element", ["hex8", "hex20"])
def test_factored_and_dense_element_matrices_agree(element, rng):
    body, u = _body(element, "mean-dilatation", "neo", rng)
    F = body.deformation_gradient(u)
    _, fac = NEO.isochoric_factors(F)
    grads = kernel.Gradients.of(body.grad_N)
    nel, nq, nb, _ = body.grad_N.shape
    Ke_f = np.empty((nel, nb, 3, 3, nb))
    Ke_d = np.empty_like(Ke_f)
    hw = rng.uniform(0.5, 2.0, (nel, nq))  # any H⊗H weight
    kernel.factored_tangent(grads, body.dV, fac, hw, kernel.into(Ke_f))
    H = fac.H
    A = fac.dense() + hw[..., None, None, None, None] * (
        H[..., :, :, None, None] * H[..., None, None, :, :]
    )
    kernel.dense_tangent(grads, body.dV, A, kernel.into(Ke_d))
    np.testing.assert_allclose(Ke_f, Ke_d, rtol=0.0, atol=RTOL * np.abs(Ke_d).max())
    # symmetric element matrices: (a, i, k, b) <-> (b, k, i, a)
    np.testing.assert_allclose(
        Ke_f, Ke_f.transpose(0, 4, 3, 2, 1), rtol=0.0, atol=RTOL * np.abs(Ke_f).max()
    )


def test_neo_hookean_factors_are_the_closed_form_tangent(rng):
    F = np.eye(3) + 0.2 * rng.standard_normal((7, 5, 3, 3))
    F[np.linalg.det(F) <= 0] = np.eye(3)
    P, A = NEO.isochoric_response(F)
    # closed form (module notes of harpx.mechanics.materials)
    J = np.linalg.det(F)
    H = np.linalg.inv(F).swapaxes(-1, -2)
    I1 = np.einsum("...iJ,...iJ->...", F, F)
    a = 2.0 * NEO.c1 * J ** (-2.0 / 3.0)
    eye = np.eye(3)
    ref = (
        np.einsum("ik,JL->iJkL", eye, eye)
        - 2.0
        / 3.0
        * (np.einsum("...iJ,...kL->...iJkL", F, H) + np.einsum("...iJ,...kL->...iJkL", H, F))
        + 2.0 / 9.0 * I1[..., None, None, None, None] * np.einsum("...iJ,...kL->...iJkL", H, H)
        + I1[..., None, None, None, None] / 3.0 * np.einsum("...iL,...kJ->...iJkL", H, H)
    ) * a[..., None, None, None, None]
    np.testing.assert_allclose(A, ref, rtol=0.0, atol=RTOL * np.abs(ref).max())
    np.testing.assert_allclose(
        P, a[..., None, None] * (F - (I1 / 3.0)[..., None, None] * H), rtol=0.0, atol=1e-13
    )


def test_guccione_factors_are_its_tangent_and_keep_y_h_exact(rng):
    # the factored Guccione tangent (nine rank-one factors, c H⊙H, δ_ik S_JL) is the dense
    # tangent of isochoric_response; the factor the assembly adds its H ⊗ H weight to is H
    F = np.eye(3) + 0.15 * rng.standard_normal((6, 4, 3, 3))
    F[np.linalg.det(F) <= 0] = np.eye(3)
    fibers = rng.standard_normal((6, 4, 3))
    fibers /= np.linalg.norm(fibers, axis=-1, keepdims=True)
    P_ref, A_ref = GUC.isochoric_response(F, fibers)
    P, fac = GUC.isochoric_factors(F, fibers)
    np.testing.assert_allclose(P, P_ref, rtol=0.0, atol=1e-13 * np.abs(P_ref).max())
    np.testing.assert_allclose(fac.dense(), A_ref, rtol=0.0, atol=RTOL * np.abs(A_ref).max())
    H = np.linalg.inv(F).swapaxes(-1, -2)
    np.testing.assert_allclose(fac.Y[..., fac.h_index, :, :], H, rtol=0.0, atol=1e-12)
    assert fac.S is not None and np.all(fac.s == 0.0)
