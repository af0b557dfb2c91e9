"""Residual and tangent: finite-difference checks, energy consistency, pattern, objectivity."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from harpx.mechanics import (
    ActiveContraction,
    Body,
    BodyForce,
    FiberGrowth,
    Guccione,
    NeoHookean,
    Pressure,
    box,
)
from harpx.mechanics.assembly import first_piola, internal_forces, sparsity

NEO = NeoHookean(c1=1.0, kappa=120.0)
GUC = Guccione(c=2.0, bf=8.0, bt=2.0, bfs=4.0, kappa=120.0)

# FD tolerance (STYLE §9): central differences have O(h²) truncation error ~1e-12 relative
# at h = 1e-6‖u‖ and round-off ~1e-16/1e-6 = 1e-10 relative; 1e-5 leaves ample margin.
FD_RTOL = 1e-5


def _random_body(rng, element, case, volumetric="mean-dilatation"):
    spec = box((1.0, 1.5, 1.0), (2, 2, 2))
    fibers = rng.standard_normal((spec.mesh.nelements, 3))
    kw: dict = {}
    mat = NEO
    if case == "guccione":  # factored tangent; the residual from the stress-only path
        mat = GUC
    if case in ("active", "active+growth"):
        mat = GUC
        kw["active"] = ActiveContraction(t_max=20.0)  # calcium law, length dependent
    if case == "growth":
        kw["growth"] = FiberGrowth(1.15)
    if case == "active+growth":
        kw["growth"] = rng.uniform(0.9, 1.1, spec.mesh.nelements)
    return Body(spec, mat, element=element, fibers=fibers, volumetric=volumetric, **kw)


def _fd_check(residual, K, u, rng):
    d = rng.standard_normal(u.size)
    h = 1e-6 * max(np.linalg.norm(u), 1.0) / np.linalg.norm(d)
    fd = (residual(u + h * d) - residual(u - h * d)) / (2 * h)
    Kd = K @ d
    return np.linalg.norm(fd - Kd) / np.linalg.norm(Kd)


CASES = [
    pytest.param("hex8", "plain", "mean-dilatation", id="hex8"),
    pytest.param("hex20", "plain", "mean-dilatation", id="hex20"),
    pytest.param("hex8", "plain", "pointwise", id="hex8-pointwise"),
    pytest.param("hex20", "plain", "pointwise", id="hex20-pointwise"),
    pytest.param("hex8", "guccione", "mean-dilatation", id="hex8-guccione"),
    pytest.param("hex20", "guccione", "pointwise", id="hex20-guccione-pointwise"),
    pytest.param("hex8", "active", "mean-dilatation", id="hex8-guccione-active"),
    pytest.param("hex20", "active", "mean-dilatation", id="hex20-guccione-active"),
    pytest.param("hex8", "growth", "mean-dilatation", id="hex8-growth"),
    pytest.param("hex20", "growth", "mean-dilatation", id="hex20-growth"),
    pytest.param("hex8", "active+growth", "pointwise", id="hex8-active-growth-pointwise"),
    pytest.param("hex20", "active+growth", "mean-dilatation", id="hex20-active-growth"),
    pytest.param("hex20", "plain", "linear-dilatation", id="hex20-linear-dilatation"),
    pytest.param("hex20", "active+growth", "linear-dilatation", id="hex20-Q2P1-active-growth"),
]


@pytest.mark.parametrize(("element", "case", "volumetric"), CASES)
def test_tangent_matches_finite_differences(element, case, volumetric, rng):
    body = _random_body(rng, element, case, volumetric)
    # random strains of a few % (mid-side nodes of hex20 need a smaller amplitude)
    u = (0.04 if element == "hex8" else 0.015) * rng.standard_normal(body.ndof)
    res = internal_forces(body, u)
    assert res.min_jacobian > 0.2
    err = _fd_check(lambda v: internal_forces(body, v, tangent=False).r, res.K, u, rng)
    assert err <= FD_RTOL, f"relative FD error {err:.2e}"


def _energy(body, u):
    """Π = Σ∫ W_iso dV + volumetric energy of the body's formulation (NeoHookean only)."""
    F = body.deformation_gradient(u)
    W = body.material.isochoric_energy(F)
    J = np.linalg.det(F)
    if body.volumetric == "mean-dilatation":
        theta = (J * body.dV).sum(axis=1) / body.cell_volume
        U = body.material.volumetric(theta)[0] * body.cell_volume
        return float((W * body.dV).sum() + U.sum())
    if body.volumetric == "linear-dilatation":
        # L2 projection of J onto span{1, X, Y, Z} per cell, by least squares
        X = body.quadrature_points
        theta = np.empty_like(J)
        for e in range(body.ncell):  # small test mesh
            psi = np.column_stack([np.ones(body.nqp), X[e]])
            w = np.sqrt(body.dV[e])
            c = np.linalg.lstsq(psi * w[:, None], J[e] * w, rcond=None)[0]
            theta[e] = psi @ c
        return float(((W + body.material.volumetric(theta)[0]) * body.dV).sum())
    return float(((W + body.material.volumetric(J)[0]) * body.dV).sum())


@pytest.mark.parametrize(
    ("element", "volumetric"),
    [("hex8", "mean-dilatation"), ("hex8", "pointwise"), ("hex20", "mean-dilatation"),
     ("hex20", "pointwise"), ("hex20", "linear-dilatation")],
)  # fmt: skip
def test_residual_is_energy_gradient(element, volumetric, rng):
    body = Body(box((1.0, 1.0, 1.0), (2, 1, 2)), NEO, element=element, volumetric=volumetric)
    u = 0.015 * rng.standard_normal(body.ndof)
    r = internal_forces(body, u, tangent=False).r
    d = rng.standard_normal(body.ndof)
    h = 1e-5
    fd = (_energy(body, u + h * d) - _energy(body, u - h * d)) / (2 * h)
    # O(h²) truncation ~1e-10 relative; round-off of Π (~1e-16 Π / h) ~1e-11
    np.testing.assert_allclose(fd, r @ d, rtol=1e-6)


@pytest.mark.parametrize("element", ["hex8", "hex20"])
def test_pressure_tangent_matches_finite_differences(element, rng):
    body = Body(box((1.0, 1.0, 1.0), (2, 2, 1)), NEO, element=element)
    load = Pressure("top", 3.0)
    u = 0.015 * rng.standard_normal(body.ndof)
    r, K = load.residual_tangent(body, u, 0.7)
    assert K.indptr is sparsity(body).indptr  # built on the body pattern: no merge needed
    err = _fd_check(lambda v: load.residual_tangent(body, v, 0.7)[0], K, u, rng)
    assert err <= FD_RTOL, f"relative FD error {err:.2e}"


@pytest.mark.parametrize("element", ["hex8", "hex20"])
def test_pressure_and_body_force_totals(element):
    body = Body(box((2.0, 1.0, 1.0), (2, 2, 1)), NEO, element=element)
    u = np.zeros(body.ndof)
    r, _ = Pressure("top", 3.0).residual_tangent(body, u, 1.0)
    # r = -f_ext: pressure 3 kPa on the 2 mm² top face pushes down with 6 mN in total
    np.testing.assert_allclose(r.reshape(-1, 3).sum(axis=0), [0.0, 0.0, 6.0], atol=1e-12)
    # follower: after a rigid 90° rotation about x the top face normal points along -y
    R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    u_rot = (body.dof_points @ R.T - body.dof_points).ravel()
    r_rot, _ = Pressure("top", 3.0).residual_tangent(body, u_rot, 1.0)
    np.testing.assert_allclose(r_rot.reshape(-1, 3).sum(axis=0), [0.0, -6.0, 0.0], atol=1e-12)
    rb, Kb = BodyForce([0.0, 0.0, -0.5]).residual_tangent(body, u, 0.5)
    assert Kb is None
    # dead load: -∫ s b dV = +0.25 mN/mm³ x 2 mm³ in z (round-off)
    np.testing.assert_allclose(rb.reshape(-1, 3).sum(axis=0), [0.0, 0.0, 0.5], atol=1e-13)


@pytest.mark.parametrize("element", ["hex8", "hex20"])
def test_pattern_matches_plain_coo_assembly(element, rng):
    body = Body(box((1.0, 1.0, 1.0), (2, 1, 1)), NEO, element=element)
    u = 0.05 * rng.standard_normal(body.ndof)
    K = internal_forces(body, u).K
    pat = sparsity(body)
    assert sparsity(body) is pat  # cached once per body
    # reference: dense element-by-element scatter of K's own element matrices via columns
    dense = np.zeros((body.ndof, body.ndof))
    for j in range(body.ndof):  # small problem: build K column by column from K @ e_j
        e = np.zeros(body.ndof)
        e[j] = 1.0
        dense[:, j] = K @ e
    np.testing.assert_array_equal(K.toarray(), dense)
    # sparsity = union of element couplings
    ed = body.element_dofs.reshape(body.ncell, -1)
    rows = np.repeat(ed, ed.shape[1], axis=1).ravel()
    cols = np.tile(ed, (1, ed.shape[1])).ravel()
    ref = sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=K.shape)
    assert K.nnz == ref.nnz
    np.testing.assert_array_equal(K.indices, ref.indices)
    np.testing.assert_array_equal(K.indptr, ref.indptr)
    np.testing.assert_allclose(abs(K - K.T).max(), 0.0, atol=1e-12 * abs(K).max())


@pytest.mark.parametrize("element", ["hex8", "hex20"])
def test_rigid_motion_is_stress_free(element, rng):
    body = Body(box((1.0, 1.0, 1.0), (2, 2, 1)), GUC, element=element,
                fibers=rng.standard_normal((4, 3)))  # fmt: skip
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    u = (body.dof_points @ Q.T + [0.3, -0.2, 0.1] - body.dof_points).ravel()
    r = internal_forces(body, u, tangent=False).r
    np.testing.assert_allclose(r, 0.0, atol=1e-12)  # objectivity: zero stress to round-off
    np.testing.assert_allclose(first_piola(body, u), 0.0, atol=1e-12)


def test_inverted_cells_are_reported():
    body = Body(box((1.0, 1.0, 1.0), (2, 1, 1)), NEO)
    u = np.zeros(body.ndof)
    right = body.facet_dofs("right", (0,))
    u[right] = -1.5  # folds the right cell through itself
    res = internal_forces(body, u)
    assert res.r is None and res.K is None and res.min_jacobian <= 0
    np.testing.assert_array_equal(res.inverted_cells, [1])


def test_overflowing_stress_is_inadmissible_like_inversion():
    # Guccione's exp(Q) overflows at fibre stretch ~4 with bf = 18.5 (Q = bf E_ff² > 709)
    # while det F stays positive: the state must be rejected by cell, not returned as NaN
    body = Body(box((1.0, 1.0, 1.0), (2, 1, 1)), Guccione(c=0.88, bf=18.5, bt=3.58, bfs=1.63,
                kappa=350.0), fibers=np.tile([1.0, 0.0, 0.0], (2, 1)))  # fmt: skip
    u = np.zeros(body.ndof)
    u[body.facet_dofs("right", (0,))] = 3.0  # right cell stretched by 7 along the fibres
    res = internal_forces(body, u)
    assert res.r is None and res.K is None and res.min_jacobian > 0
    np.testing.assert_array_equal(res.inverted_cells, [1])
    u[body.facet_dofs("right", (0,))] = 0.1  # moderate stretch: admissible and finite
    res = internal_forces(body, u)
    assert res.r is not None and np.isfinite(res.r).all() and np.isfinite(res.K.data).all()
