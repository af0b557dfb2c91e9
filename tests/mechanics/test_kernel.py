"""Factored tangent kernel: element matrices against the dense form and against finite
differences of the residual, the closed-form tangent factors of the materials."""

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
    internal_forces,
)

NEO = NeoHookean(c1=1.0, kappa=120.0)
GUC = Guccione(c=2.0, bf=8.0, bt=2.0, bfs=4.0, kappa=120.0)

# element matrices computed two ways sum the same products in another order: round-off only
RTOL = 1e-12
# central differences at h = 1e-6 ‖u‖: truncation ~1e-12 and round-off ~1e-10 relative
FD_RTOL = 1e-5


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
def test_assembled_tangent_is_the_derivative_of_the_residual(element, volumetric, case, rng):
    # the independent truth of a tangent: central differences of the residual along a
    # random direction, for every element, volumetric formulation and material case
    body, u = _body(element, volumetric, case, rng)
    res = internal_forces(body, u)
    d = rng.standard_normal(u.size)
    h = 1e-6 * max(float(np.linalg.norm(u)), 1.0) / float(np.linalg.norm(d))
    plus = internal_forces(body, u + h * d, tangent=False).r
    minus = internal_forces(body, u - h * d, tangent=False).r
    Kd = res.K @ d
    err = np.linalg.norm((plus - minus) / (2 * h) - Kd) / np.linalg.norm(Kd)
    assert err <= FD_RTOL, f"relative FD error {err:.2e}"


@pytest.mark.parametrize("element", ["hex8", "tet4"])
def test_without_pressure_stiffness_only_the_geometric_pressure_term_is_left_out(element, rng):
    # pressure_stiffness=False drops the term p (cof ⊗ cof − cof ⊠ cof)/J: at the reference
    # state (p = 0) nothing is dropped, and under a uniform dilatation by s (F = s I,
    # p ≠ 0) the residual is the same and the tangent differs
    body, _ = _body(element, "mean-dilatation" if element == "hex8" else "nodal-dilatation",
                    "neo", rng)  # fmt: skip
    zero = np.zeros(body.ndof)
    a, b = internal_forces(body, zero), internal_forces(body, zero, pressure_stiffness=False)
    np.testing.assert_allclose((a.K - b.K).data, 0.0, atol=RTOL * np.abs(a.K.data).max())
    u = 0.02 * body.dof_points.ravel()
    a, b = internal_forces(body, u), internal_forces(body, u, pressure_stiffness=False)
    np.testing.assert_allclose(a.r, b.r, rtol=0, atol=RTOL * np.abs(a.r).max())
    assert np.abs((a.K - b.K).data).max() > 1e-3 * np.abs(a.K.data).max()


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
