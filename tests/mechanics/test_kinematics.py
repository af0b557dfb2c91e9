"""Tests of harpx.mechanics.kinematics: identities, growth split and its chain rule."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.mechanics.kinematics import (
    cofactor,
    fiber_basis,
    fiber_stretch,
    green_strain,
    growth_tensor,
    push_growth_response,
    right_cauchy_green,
    split_growth,
    unit_fibers,
    volumetric_response,
)

# Floating-point identities below use rtol/atol 1e-12: every quantity is O(1) and built from
# a handful of products, so round-off is ~1e-15.
EXACT = 1e-12
# Central differences with h = 1e-6: truncation ~h^2 |W'''| ~ 1e-12, round-off
# ~eps |W| / h ~ 1e-10; 1e-6 (stress) and 1e-5 (tangent, STYLE section 9) leave ample margin.
FD_H = 1e-6
FD_RTOL_P = 1e-6
FD_RTOL_A = 1e-5


def _random_F(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    """Random deformation gradients ``I + scale * N(0, 1)`` with 0.7 <= det F <= 1.4."""
    F = np.eye(3) + scale * rng.standard_normal((20 * n, 3, 3))
    J = np.linalg.det(F)
    F = F[(J >= 0.7) & (J <= 1.4)][:n]
    assert len(F) == n
    return F


def _random_fibers(rng: np.random.Generator, n: int) -> np.ndarray:
    f = rng.standard_normal((n, 3))
    return f / np.linalg.norm(f, axis=-1, keepdims=True)


def _rel(actual: np.ndarray, expected: np.ndarray) -> float:
    """Largest per-point relative error in the Frobenius norm."""
    ax = tuple(range(1, expected.ndim))
    return float(
        np.max(np.linalg.norm(actual - expected, axis=ax) / np.linalg.norm(expected, axis=ax))
    )


def test_green_strain_and_cauchy_green(rng):
    F = _random_F(rng, 10, 0.3)
    C = right_cauchy_green(F)
    np.testing.assert_allclose(C, np.einsum("nki,nkj->nij", F, F), rtol=EXACT, atol=EXACT)
    np.testing.assert_allclose(green_strain(F), 0.5 * (C - np.eye(3)), rtol=EXACT, atol=EXACT)


def test_cofactor_is_det_times_inverse_transpose(rng):
    F = _random_F(rng, 10, 0.3)
    expected = np.linalg.det(F)[:, None, None] * np.linalg.inv(F).transpose(0, 2, 1)
    np.testing.assert_allclose(cofactor(F), expected, rtol=EXACT, atol=EXACT)


def test_fiber_stretch_matches_green_strain(rng):
    F = _random_F(rng, 10, 0.3)
    f = _random_fibers(rng, 10)
    E_ff = np.einsum("ni,nij,nj->n", f, green_strain(F), f)
    np.testing.assert_allclose(fiber_stretch(F, f), np.sqrt(2.0 * E_ff + 1.0), rtol=EXACT)


def test_fiber_stretch_broadcasts_per_cell_fibers(rng):
    F = _random_F(rng, 12, 0.3).reshape(4, 3, 3, 3)  # (cells, qp, 3, 3)
    f = _random_fibers(rng, 4)[:, None, :]  # one fiber per cell
    lam = fiber_stretch(F, f)
    assert lam.shape == (4, 3)
    np.testing.assert_allclose(lam[2, 1], np.linalg.norm(F[2, 1] @ f[2, 0]), rtol=EXACT)


def test_fiber_basis_is_orthonormal_right_handed_and_deterministic(rng):
    raw = rng.standard_normal((50, 3)) * 3.0
    f, s, n = fiber_basis(raw)
    R = np.stack([f, s, n], axis=-1)
    np.testing.assert_allclose(
        R.transpose(0, 2, 1) @ R, np.broadcast_to(np.eye(3), R.shape), atol=EXACT
    )
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=EXACT)
    np.testing.assert_allclose(f, raw / np.linalg.norm(raw, axis=-1, keepdims=True), rtol=EXACT)
    f2, s2, n2 = fiber_basis(raw)
    assert np.array_equal(s, s2) and np.array_equal(n, n2)


@pytest.mark.parametrize(
    ("fiber", "s_expected", "n_expected"),
    [
        pytest.param([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], id="x"),
        pytest.param([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], id="y"),
        pytest.param([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], id="z"),
    ],
)
def test_fiber_basis_coordinate_axes(fiber, s_expected, n_expected):
    _, s, n = fiber_basis(fiber)
    np.testing.assert_allclose(s, s_expected, atol=EXACT)
    np.testing.assert_allclose(n, n_expected, atol=EXACT)


def test_fiber_basis_rejects_zero_fiber():
    with pytest.raises(ValueError, match="'fiber' has 1 zero-length"):
        fiber_basis([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


def test_unit_fibers_rejects_bad_shape():
    with pytest.raises(ValueError, match=r"'fiber' must have shape \(\.\.\., 3\)"):
        unit_fibers(np.ones((4, 2)))


def test_cofactor_rejects_bad_shape():
    with pytest.raises(ValueError, match=r"'F' must have shape \(\.\.\., 3, 3\)"):
        cofactor(np.ones((4, 2, 3)))


def test_growth_tensor_stretches_fibers_only(rng):
    f = _random_fibers(rng, 8)
    theta = 1.3
    Fg = growth_tensor(f, theta)
    _, s, n = fiber_basis(f)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", Fg, f), theta * f, atol=EXACT)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", Fg, s), s, atol=EXACT)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", Fg, n), n, atol=EXACT)
    np.testing.assert_allclose(np.linalg.det(Fg), theta, rtol=EXACT)


def test_split_growth_recovers_total(rng):
    F = _random_F(rng, 8, 0.3)
    Fg = growth_tensor(_random_fibers(rng, 8), rng.uniform(0.8, 1.2, 8))
    Fe = split_growth(F, Fg)
    np.testing.assert_allclose(Fe @ Fg, F, atol=EXACT)


def _quartic(Fe: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """W_e = (Fe:Fe)^2 / 4 with P_e = (Fe:Fe) Fe and A_e = (Fe:Fe) I + 2 Fe (x) Fe."""
    I1 = np.einsum("...ij,...ij->...", Fe, Fe)
    P = I1[..., None, None] * Fe
    A = 2.0 * Fe[..., :, :, None, None] * Fe[..., None, None, :, :]
    A += I1[..., None, None, None, None] * np.einsum("ik,jl->ijkl", np.eye(3), np.eye(3))
    return 0.25 * I1**2, P, A


@pytest.mark.parametrize(
    "scale", [pytest.param(0.05, id="near-identity"), pytest.param(0.35, id="large-strain")]
)
def test_push_growth_response_matches_finite_differences(rng, scale):
    n = 12
    F = _random_F(rng, n, scale)
    Fg = growth_tensor(_random_fibers(rng, n), rng.uniform(0.8, 1.25, n))
    Jg = np.linalg.det(Fg)

    def energy(F):
        return Jg * _quartic(split_growth(F, Fg))[0]

    def response(F):
        _, P_e, A_e = _quartic(split_growth(F, Fg))
        return push_growth_response(P_e, A_e, Fg)

    P, A = response(F)
    P_fd = np.zeros_like(P)
    for i in range(3):
        for j in range(3):
            d = np.zeros((3, 3))
            d[i, j] = FD_H
            P_fd[:, i, j] = (energy(F + d) - energy(F - d)) / (2 * FD_H)
    assert _rel(P, P_fd) <= FD_RTOL_P, f"P error {_rel(P, P_fd):.2e}"
    dF = rng.standard_normal(F.shape)
    dP_fd = (response(F + FD_H * dF)[0] - response(F - FD_H * dF)[0]) / (2 * FD_H)
    dP = np.einsum("nijkl,nkl->nij", A, dF)
    assert _rel(dP, dP_fd) <= FD_RTOL_A, f"A error {_rel(dP, dP_fd):.2e}"


def test_volumetric_response_matches_finite_differences(rng):
    kappa = 120.0
    F = _random_F(rng, 12, 0.35)

    def derivs(F):
        J = np.linalg.det(F)
        lnJ = np.log(J)
        return 0.5 * kappa * lnJ**2, kappa * lnJ / J, kappa * (1.0 - lnJ) / J**2

    P, A = volumetric_response(F, *derivs(F)[1:])
    P_fd = np.zeros_like(P)
    for i in range(3):
        for j in range(3):
            d = np.zeros((3, 3))
            d[i, j] = FD_H
            P_fd[:, i, j] = (derivs(F + d)[0] - derivs(F - d)[0]) / (2 * FD_H)
    assert _rel(P, P_fd) <= FD_RTOL_P, f"P error {_rel(P, P_fd):.2e}"
    dF = rng.standard_normal(F.shape)
    resp = lambda G: volumetric_response(G, *derivs(G)[1:])[0]  # noqa: E731
    dP_fd = (resp(F + FD_H * dF) - resp(F - FD_H * dF)) / (2 * FD_H)
    dP = np.einsum("nijkl,nkl->nij", A, dF)
    assert _rel(dP, dP_fd) <= FD_RTOL_A, f"A error {_rel(dP, dP_fd):.2e}"
