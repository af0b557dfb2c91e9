"""Tests of harpx.mechanics.materials at material-point level.

Energy conventions (REFERENCES section 2.1): ``NeoHookean(c1, kappa)`` is the *uncoupled*
neo-Hookean solid W = C1 (J^(-2/3) I1 - 3) + kappa/2 (ln J)^2 (FEBio ``Mooney-Rivlin`` with
c2 = 0, pressure_model 0), mu = 2 C1. ``Guccione`` is uncoupled in Ebar = (J^(-2/3) C - I)/2
with the same log volumetric term.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from harpx.mechanics.kinematics import growth_tensor, push_growth_response, split_growth
from harpx.mechanics.materials import ActiveContraction, FiberGrowth, Guccione, NeoHookean

# Floating-point identities: O(1) quantities built from a few products, round-off ~1e-15.
EXACT = 1e-12
# Central differences with h = 1e-6: truncation ~h^2 |W'''| <~ 1e-10 (relative) and
# round-off ~eps |W| / h ~ 1e-10; 1e-6 for P (brief) and 1e-5 for A (STYLE section 9) keep
# a wide margin while still catching any missing term (those give errors of O(1)).
FD_H = 1e-6
FD_RTOL_P = 1e-6
FD_RTOL_A = 1e-5
# brentq tolerances used to solve the lateral/through-thickness stress conditions: the
# root is then exact to ~1e-15 in the stretch, so closed forms that hold *given* the root
# agree to ~1e-13 relative; 1e-10 is the asserted bound.
ROOT_KW = {"xtol": 1e-15, "rtol": 1e-15}
CLOSED_FORM = 1e-10

NH = NeoHookean(c1=1.0, kappa=120.0)
GUCCIONE = Guccione(c=2.0, bf=8.0, bt=2.0, bfs=4.0, kappa=100.0)


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


def _fd_gradient(energy, F: np.ndarray) -> np.ndarray:
    """Central-difference dW/dF, component by component."""
    P = np.zeros_like(F)
    for i in range(3):
        for j in range(3):
            d = np.zeros((3, 3))
            d[i, j] = FD_H
            P[..., i, j] = (energy(F + d) - energy(F - d)) / (2 * FD_H)
    return P


def _check_tangent(response, F: np.ndarray, rng: np.random.Generator) -> float:
    """Relative error of A : dF against central differences of P along random dF."""
    _, A = response(F)
    dF = rng.standard_normal(F.shape)
    dP_fd = (response(F + FD_H * dF)[0] - response(F - FD_H * dF)[0]) / (2 * FD_H)
    dP = np.einsum("...ijkl,...kl->...ij", A, dF)
    return _rel(dP, dP_fd)


SCALES = [pytest.param(0.05, id="near-identity"), pytest.param(0.35, id="large-strain")]


# --------------------------------------------------------------------------------------
# finite-difference checks
# --------------------------------------------------------------------------------------


def _isochoric_energy(mat, fiber):
    def energy(F):
        return mat.strain_energy(F, fiber) - mat.volumetric(np.linalg.det(F))[0]

    return energy


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("mat", [pytest.param(NH, id="neo-hookean"),
                                 pytest.param(GUCCIONE, id="guccione")])
def test_isochoric_stress_is_energy_gradient(rng, mat, scale):
    n = 30
    F = _random_F(rng, n, scale)
    fiber = _random_fibers(rng, n)
    P, _ = mat.isochoric_response(F, fiber)
    P_fd = _fd_gradient(_isochoric_energy(mat, fiber), F)
    err = _rel(P, P_fd)
    assert err <= FD_RTOL_P, f"P vs dW/dF: relative error {err:.2e}"


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("mat", [pytest.param(NH, id="neo-hookean"),
                                 pytest.param(GUCCIONE, id="guccione")])
def test_isochoric_tangent_matches_finite_differences(rng, mat, scale):
    n = 30
    F = _random_F(rng, n, scale)
    fiber = _random_fibers(rng, n)
    err = _check_tangent(lambda G: mat.isochoric_response(G, fiber), F, rng)
    assert err <= FD_RTOL_A, f"A vs dP/dF: relative error {err:.2e}"


@pytest.mark.parametrize("mat", [pytest.param(NH, id="neo-hookean"),
                                 pytest.param(GUCCIONE, id="guccione")])
def test_tangent_has_major_symmetry(rng, mat):
    F = _random_F(rng, 10, 0.35)
    _, A = mat.isochoric_response(F, _random_fibers(rng, 10))
    A9 = A.reshape(-1, 9, 9)
    # hyperelastic tangent is a Hessian; asymmetry only from round-off at the scale of |A|
    assert np.max(np.abs(A9 - A9.transpose(0, 2, 1))) <= EXACT * np.max(np.abs(A9))


def test_response_broadcasts_cell_fibers_over_quadrature_points(rng):
    F = _random_F(rng, 12, 0.2).reshape(4, 3, 3, 3)  # (cells, qp, 3, 3)
    f = _random_fibers(rng, 4)
    P, A = GUCCIONE.isochoric_response(F, f[:, None, :])
    P1, A1 = GUCCIONE.isochoric_response(F[2, 1], f[2])
    assert P.shape == (4, 3, 3, 3) and A.shape == (4, 3, 3, 3, 3, 3)
    np.testing.assert_allclose(P[2, 1], P1, rtol=EXACT, atol=EXACT)
    np.testing.assert_allclose(A[2, 1], A1, rtol=EXACT, atol=EXACT)


# --------------------------------------------------------------------------------------
# closed forms (REFERENCES sections 2.2-2.5)
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("lam", "lt_table", "sigma_table", "P_table"),
    [
        pytest.param(1.1, 0.954255, 0.597139, 0.543756, id="1.1"),
        pytest.param(1.5, 0.820061, 3.109513, 2.091150, id="1.5"),
        pytest.param(2.0, 0.713908, 6.761447, 3.446071, id="2.0"),
    ],
)
def test_neo_hookean_uniaxial_free_lateral_faces(lam, lt_table, sigma_table, P_table):
    """F = diag(lam, lt, lt), sigma_yy = sigma_zz = 0 (REFERENCES 2.2, log U row).

    For any uncoupled energy, sigma_yy = 0 and tr(dev sigma) = 0 give sigma_xx = 3 U'(J).
    """

    def sigma(lt):
        return NH.cauchy_stress(np.diag([lam, lt, lt]))

    lt = brentq(lambda t: sigma(t)[1, 1], 0.3, 1.0, **ROOT_KW)
    s = sigma(lt)
    J = lam * lt * lt
    # the table carries 6 significant digits: 1e-5 relative
    np.testing.assert_allclose(lt, lt_table, rtol=1e-5)
    np.testing.assert_allclose(s[0, 0], sigma_table, rtol=1e-5)
    np.testing.assert_allclose(s[0, 0] * lt * lt, P_table, rtol=1e-5)
    np.testing.assert_allclose(s[0, 0], 3.0 * NH.volumetric(J)[1], rtol=CLOSED_FORM)
    np.testing.assert_allclose(
        s[0, 0], 2.0 * NH.c1 * J ** (-5.0 / 3.0) * (lam**2 - lt**2), rtol=CLOSED_FORM
    )


@pytest.mark.parametrize("gamma", [0.1, 0.5, 2.0])
def test_neo_hookean_simple_shear(gamma):
    """F = I + gamma e1 (x) e2, J = 1 (REFERENCES 2.3): exact for the uncoupled energy."""
    F = np.eye(3)
    F[0, 1] = gamma
    s = NH.cauchy_stress(F)
    c1 = NH.c1
    # floating-point identity: a few products of O(1) numbers
    np.testing.assert_allclose(s[0, 1], 2 * c1 * gamma, rtol=EXACT)
    np.testing.assert_allclose(s[0, 0], 4.0 / 3.0 * c1 * gamma**2, rtol=EXACT)
    np.testing.assert_allclose(s[1, 1], -2.0 / 3.0 * c1 * gamma**2, rtol=EXACT)
    np.testing.assert_allclose(s[2, 2], -2.0 / 3.0 * c1 * gamma**2, rtol=EXACT)
    P, _ = NH.isochoric_response(F)
    np.testing.assert_allclose(P[0, 0], s[0, 0] - gamma * s[0, 1], rtol=EXACT)


@pytest.mark.parametrize("lam", [1.1, 1.3, 1.6])
def test_neo_hookean_equibiaxial(lam):
    r"""F = diag(lam, lam, lz) with sigma_zz = 0.

    With J = lam^2 lz and I1 = 2 lam^2 + lz^2, the deviatoric Cauchy stress
    2 C1 J^(-5/3) (b - I1/3 I) has components dev_xx = dev_yy = (2/3) C1 J^(-5/3)
    (lam^2 - lz^2) and dev_zz = -(4/3) C1 J^(-5/3) (lam^2 - lz^2). Then sigma_zz = 0 means

        U'(J) = (4/3) C1 J^(-5/3) (lam^2 - lz^2)          (solved for lz),

    and sigma_xx = sigma_yy = sigma_xx - sigma_zz = 2 C1 J^(-5/3) (lam^2 - lz^2)
    = (3/2) U'(J).
    """

    def sigma(lz):
        return NH.cauchy_stress(np.diag([lam, lam, lz]))

    lz = brentq(lambda t: sigma(t)[2, 2], 0.2, 1.0, **ROOT_KW)
    s = sigma(lz)
    J = lam * lam * lz
    dU = NH.volumetric(J)[1]
    expected = 2.0 * NH.c1 * J ** (-5.0 / 3.0) * (lam**2 - lz**2)
    np.testing.assert_allclose(dU, 4.0 / 3.0 * NH.c1 * J ** (-5.0 / 3.0) * (lam**2 - lz**2),
                               rtol=CLOSED_FORM)
    np.testing.assert_allclose(s[0, 0], expected, rtol=CLOSED_FORM)
    np.testing.assert_allclose(s[1, 1], expected, rtol=CLOSED_FORM)
    np.testing.assert_allclose(s[0, 0], 1.5 * dU, rtol=CLOSED_FORM)


# --------------------------------------------------------------------------------------
# objectivity
# --------------------------------------------------------------------------------------


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


@pytest.mark.parametrize("mat", [pytest.param(NH, id="neo-hookean"),
                                 pytest.param(GUCCIONE, id="guccione")])
def test_superposed_rotation_rotates_stress(rng, mat):
    F = _random_F(rng, 10, 0.3)
    fiber = _random_fibers(rng, 10)
    R = _rotation(rng.standard_normal(3), 1.234)
    P, _ = mat.isochoric_response(F, fiber)
    PR, _ = mat.isochoric_response(R @ F, fiber)
    np.testing.assert_allclose(PR, R @ P, atol=EXACT * np.max(np.abs(P)))


@pytest.mark.parametrize("angle", [pytest.param(np.pi / 2, id="90deg"),
                                   pytest.param(np.pi, id="180deg")])
@pytest.mark.parametrize("axis", [[0, 0, 1], [1, 1, 0]])
@pytest.mark.parametrize("mat", [pytest.param(NH, id="neo-hookean"),
                                 pytest.param(GUCCIONE, id="guccione")])
def test_rigid_rotation_is_stress_free(rng, mat, angle, axis):
    R = _rotation(axis, angle)
    fiber = _random_fibers(rng, 5)
    P, _ = mat.isochoric_response(np.broadcast_to(R, (5, 3, 3)), fiber)
    sigma = mat.cauchy_stress(np.broadcast_to(R, (5, 3, 3)), fiber)
    # E = 0 exactly up to round-off of R (~1e-16): stresses are ~1e-15 kPa
    np.testing.assert_allclose(P, 0.0, atol=EXACT)
    np.testing.assert_allclose(sigma, 0.0, atol=EXACT)


# --------------------------------------------------------------------------------------
# bad parameters
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("factory", "name"),
    [
        pytest.param(lambda: NeoHookean(c1=-1.0, kappa=120.0), "c1", id="nh-c1<0"),
        pytest.param(lambda: NeoHookean(c1=1.0, kappa=0.0), "kappa", id="nh-kappa=0"),
        pytest.param(lambda: NeoHookean(c1=float("nan"), kappa=1.0), "c1", id="nh-c1-nan"),
        pytest.param(lambda: NeoHookean(c1=1.0, kappa=float("inf")), "kappa", id="nh-k-inf"),
        pytest.param(lambda: Guccione(c=0.0, bf=8, bt=2, bfs=4, kappa=1e2), "c", id="gu-c"),
        pytest.param(lambda: Guccione(c=2.0, bf=-8, bt=2, bfs=4, kappa=1e2), "bf", id="gu-bf"),
        pytest.param(lambda: Guccione(c=2.0, bf=8, bt=-2, bfs=4, kappa=1e2), "bt", id="gu-bt"),
        pytest.param(lambda: Guccione(c=2.0, bf=8, bt=2, bfs=-1, kappa=1e2), "bfs", id="gu-bfs"),
        pytest.param(lambda: Guccione(c=2.0, bf=8, bt=2, bfs=4, kappa=-1), "kappa", id="gu-k"),
    ],
)
def test_bad_parameters_name_the_parameter(factory, name):
    with pytest.raises(ValueError, match=f"parameter '{name}' must be"):
        factory()


def test_guccione_without_fibers_raises():
    with pytest.raises(ValueError, match="Guccione needs fiber directions"):
        GUCCIONE.isochoric_response(np.eye(3))


def test_inverted_element_raises():
    F = np.diag([1.0, 1.0, -1.0])
    with pytest.raises(ValueError, match=r"det F <= 0 \(or NaN\) at 1 point"):
        NH.isochoric_response(F)
