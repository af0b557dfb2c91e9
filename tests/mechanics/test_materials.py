"""Tests of harpx.mechanics.materials at material-point level.

Energy conventions: ``NeoHookean(c1, kappa)`` is the *uncoupled*
neo-Hookean solid W = C1 (J^(-2/3) I1 - 3) + kappa/2 (ln J)^2 (FEBio ``Mooney-Rivlin`` with
c2 = 0, pressure_model 0), mu = 2 C1. ``Guccione`` is uncoupled in Ebar = (J^(-2/3) C - I)/2
with the same log volumetric term.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from harpx.mechanics.fiber_laws import ActiveContraction, FiberGrowth
from harpx.mechanics.kinematics import growth_tensor, push_growth_response, split_growth
from harpx.mechanics.materials import Guccione, NeoHookean

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
@pytest.mark.parametrize(
    "mat", [pytest.param(NH, id="neo-hookean"), pytest.param(GUCCIONE, id="guccione")]
)
def test_isochoric_stress_is_energy_gradient(rng, mat, scale):
    n = 30
    F = _random_F(rng, n, scale)
    fiber = _random_fibers(rng, n)
    P, _ = mat.isochoric_response(F, fiber)
    P_fd = _fd_gradient(_isochoric_energy(mat, fiber), F)
    err = _rel(P, P_fd)
    assert err <= FD_RTOL_P, f"P vs dW/dF: relative error {err:.2e}"
    # the stress-only path (residuals without a tangent) against the same truth
    err = _rel(mat.isochoric_stress(F, fiber), P_fd)
    assert err <= FD_RTOL_P, f"isochoric_stress vs dW/dF: relative error {err:.2e}"


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize(
    "mat", [pytest.param(NH, id="neo-hookean"), pytest.param(GUCCIONE, id="guccione")]
)
def test_isochoric_tangent_matches_finite_differences(rng, mat, scale):
    n = 30
    F = _random_F(rng, n, scale)
    fiber = _random_fibers(rng, n)
    err = _check_tangent(lambda G: mat.isochoric_response(G, fiber), F, rng)
    assert err <= FD_RTOL_A, f"A vs dP/dF: relative error {err:.2e}"


@pytest.mark.parametrize(
    "mat", [pytest.param(NH, id="neo-hookean"), pytest.param(GUCCIONE, id="guccione")]
)
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
# closed forms of homogeneous stress states
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
    """F = diag(lam, lt, lt), sigma_yy = sigma_zz = 0 (closed form with the log volumetric energy).

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
    """F = I + gamma e1 (x) e2, J = 1: exact for the uncoupled energy."""
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
    np.testing.assert_allclose(
        dU, 4.0 / 3.0 * NH.c1 * J ** (-5.0 / 3.0) * (lam**2 - lz**2), rtol=CLOSED_FORM
    )
    np.testing.assert_allclose(s[0, 0], expected, rtol=CLOSED_FORM)
    np.testing.assert_allclose(s[1, 1], expected, rtol=CLOSED_FORM)
    np.testing.assert_allclose(s[0, 0], 1.5 * dU, rtol=CLOSED_FORM)


@pytest.mark.parametrize(
    ("lam", "sigma_table"),
    [
        pytest.param(1.05, 1.018183, id="1.05"),
        pytest.param(1.1, 2.420691, id="1.1"),
        pytest.param(1.2, 8.096521, id="1.2"),
    ],
)
def test_guccione_fiber_uniaxial_at_unit_jacobian(rng, lam, sigma_table):
    """F = diag(lam, lam^-1/2, lam^-1/2) in the fiber basis (f, s, n), J = 1.

    The incompressible table value is sigma_ff = sigma~_ff - p with the pressure p fixed by
    the free lateral faces, sigma_ss = sigma~_ss - p = 0, i.e. sigma_ff = sigma~_ff - sigma~_ss
    with sigma~ = F S~ F^T, S~ = dW/dE. Our uncoupled response is
    sigma_iso = J^-1 dev(Fbar Sbar Fbar^T) (+ U'(J) I, zero at J = 1); at J = 1, Fbar = F and
    Ebar = E, so sigma~ = Fbar Sbar Fbar^T and dev only shifts the diagonal by a multiple of I.
    Hence sigma_ff - sigma_ss of our (deviatoric) stress equals the table's sigma_ff, and in
    closed form C e^Q (bf E_ff lam^2 - bt E_ss / lam) with Q = bf E_ff^2 + 2 bt E_ss^2.
    A random fiber and a random transverse pair (s, n) also check that Q does not depend on
    the choice of s and n.
    """
    mat = Guccione(c=2.0, bf=8.0, bt=2.0, bfs=4.0, kappa=100.0)  # bfs does not enter
    f = _random_fibers(rng, 1)[0]
    s = np.cross(f, rng.standard_normal(3))
    s /= np.linalg.norm(s)
    n = np.cross(f, s)
    Qb = np.stack([f, s, n], axis=-1)
    F = Qb @ np.diag([lam, lam**-0.5, lam**-0.5]) @ Qb.T
    sigma = mat.cauchy_stress(F, f)
    diff = f @ sigma @ f - s @ sigma @ s
    E_ff, E_ss = (lam**2 - 1) / 2, (1 / lam - 1) / 2
    Q = mat.bf * E_ff**2 + 2 * mat.bt * E_ss**2
    closed = mat.c * np.exp(Q) * (mat.bf * E_ff * lam**2 - mat.bt * E_ss / lam)
    np.testing.assert_allclose(diff, sigma_table, rtol=1e-5)  # table: 7 significant digits
    np.testing.assert_allclose(diff, closed, rtol=EXACT)  # same formula, round-off only
    # lateral faces carry the same stress by transverse isotropy
    np.testing.assert_allclose(n @ sigma @ n, s @ sigma @ s, rtol=EXACT, atol=EXACT)


# --------------------------------------------------------------------------------------
# objectivity
# --------------------------------------------------------------------------------------


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


@pytest.mark.parametrize(
    "mat", [pytest.param(NH, id="neo-hookean"), pytest.param(GUCCIONE, id="guccione")]
)
def test_superposed_rotation_rotates_stress(rng, mat):
    F = _random_F(rng, 10, 0.3)
    fiber = _random_fibers(rng, 10)
    R = _rotation(rng.standard_normal(3), 1.234)
    P, _ = mat.isochoric_response(F, fiber)
    PR, _ = mat.isochoric_response(R @ F, fiber)
    np.testing.assert_allclose(PR, R @ P, atol=EXACT * np.max(np.abs(P)))


@pytest.mark.parametrize(
    "angle", [pytest.param(np.pi / 2, id="90deg"), pytest.param(np.pi, id="180deg")]
)
@pytest.mark.parametrize("axis", [[0, 0, 1], [1, 1, 0]])
@pytest.mark.parametrize(
    "mat", [pytest.param(NH, id="neo-hookean"), pytest.param(GUCCIONE, id="guccione")]
)
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


# --------------------------------------------------------------------------------------
# active contraction
# --------------------------------------------------------------------------------------

ACTIVE_LAWS = [pytest.param("prescribed", id="prescribed"), pytest.param("calcium", id="calcium")]


@pytest.mark.parametrize(
    ("lam", "expected"),
    [(0.8, 29.6992), (0.9, 95.4767), (1.0, 120.4368), (1.1, 129.9082), (1.2, 133.5022)],
)
def test_calcium_law_reproduces_reference_table(lam, expected):
    # the calcium law with FEBio's "typical" parameters (Guccione et al. 1993);
    # 4 decimals -> 1e-4 kPa
    act = ActiveContraction()
    assert act.t_max == 135.7
    np.testing.assert_allclose(act.tension(lam), expected, atol=1e-4)


def test_calcium_law_is_inactive_below_threshold():
    act = ActiveContraction()
    lam = np.array([0.5, 0.7, act.l0 / act.lr, 0.775])
    np.testing.assert_array_equal(act.tension(lam)[:3], 0.0)
    assert act.tension(lam)[3] > 0.0


def test_prescribed_law_is_constant():
    act = ActiveContraction(t_max=50.0, law="prescribed")
    np.testing.assert_array_equal(act.tension([0.5, 1.0, 1.7]), 50.0)
    np.testing.assert_array_equal(act.activation_factor([0.5, 1.0]), 1.0)


@pytest.mark.parametrize("law", ACTIVE_LAWS)
def test_t_max_for_tension_inverts_the_law(rng, law):
    act = ActiveContraction(law=law)
    lam = rng.uniform(0.8, 1.3, 50)
    t_max = rng.uniform(10.0, 200.0, 50)
    T = act.tension(lam, t_max=t_max)
    # tension / g undoes t_max * g: one rounding each way
    np.testing.assert_allclose(act.t_max_for_tension(lam, T), t_max, rtol=EXACT)


def test_t_max_for_tension_is_nan_where_inactive_without_warnings():
    import warnings

    act = ActiveContraction()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = act.t_max_for_tension([0.7, np.nan, 1.0, np.inf], [10.0, 10.0, np.nan, 10.0])
    assert np.isnan(out[:3]).all()
    # infinite stretch saturates the law (g = 1)
    np.testing.assert_allclose(out[3], 10.0, rtol=EXACT)


def _active_sample(rng, act, n, scale):
    """Random (F, fiber) with stretch >= 0.8, away from the calcium-law kink at 0.7745."""
    F = _random_F(rng, 4 * n, scale)
    f = _random_fibers(rng, 4 * n)
    lam = np.linalg.norm(np.einsum("nij,nj->ni", F, f), axis=-1)
    keep = lam >= 0.8
    assert keep.sum() >= n
    return F[keep][:n], f[keep][:n]


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("law", ACTIVE_LAWS)
def test_active_tangent_matches_finite_differences(rng, law, scale):
    act = ActiveContraction(law=law)
    F, f = _active_sample(rng, act, 30, scale)
    t_max = rng.uniform(50.0, 150.0, 30)  # per-point values also exercise broadcasting
    err = _check_tangent(lambda G: act.response(G, f, t_max=t_max), F, rng)
    assert err <= FD_RTOL_A, f"A vs dP/dF: relative error {err:.2e}"


@pytest.mark.parametrize("law", ACTIVE_LAWS)
def test_active_stress_derives_from_fiber_potential(rng, law):
    """P = dW_a/dF with W_a(F) = int_1^lambda T_a(mu) mu dmu, lambda = |F f0|.

    The central difference of W_a is the integral between the two perturbed stretches,
    evaluated by adaptive quadrature (error ~1e-14 of an O(h) integral).
    """
    from scipy.integrate import quad

    act = ActiveContraction(law=law)
    F, f = _active_sample(rng, act, 4, 0.2)
    P, _ = act.response(F, f)

    def stretch(G):
        return np.linalg.norm(np.einsum("nij,nj->ni", G, f), axis=-1)

    P_fd = np.zeros_like(P)
    for i in range(3):
        for j in range(3):
            d = np.zeros((3, 3))
            d[i, j] = FD_H
            lo, hi = stretch(F - d), stretch(F + d)
            for p in range(len(F)):
                val, _ = quad(
                    lambda m: float(act.tension(m)) * m, lo[p], hi[p], epsabs=0.0, epsrel=1e-13
                )
                P_fd[p, i, j] = val / (2 * FD_H)
    err = _rel(P, P_fd)
    assert err <= FD_RTOL_P, f"P vs dW_a/dF: relative error {err:.2e}"


def test_active_stress_is_second_piola_kirchhoff_fiber_tension(rng):
    act = ActiveContraction()
    F = _random_F(rng, 5, 0.2)
    f = _random_fibers(rng, 5)
    P, _ = act.response(F, f)
    S = np.linalg.solve(F, P)  # S = F^-1 P
    lam = np.linalg.norm(np.einsum("nij,nj->ni", F, f), axis=-1)
    expected = act.tension(lam)[:, None, None] * f[:, :, None] * f[:, None, :]
    np.testing.assert_allclose(S, expected, atol=EXACT * 200.0)  # |S| ~ 100 kPa


def test_active_response_broadcasts_per_cell_t_max(rng):
    act = ActiveContraction()
    F = _random_F(rng, 12, 0.1).reshape(4, 3, 3, 3)  # (cells, qp, 3, 3)
    f = _random_fibers(rng, 4)[:, None, :]
    t_max = np.array([10.0, 20.0, 30.0, 40.0])[:, None]  # per cell
    P, A = act.response(F, f, t_max=t_max)
    assert P.shape == (4, 3, 3, 3) and A.shape == (4, 3, 3, 3, 3, 3)
    P1, A1 = act.response(F[2, 1], f[2, 0], t_max=30.0)
    np.testing.assert_allclose(P[2, 1], P1, rtol=EXACT, atol=EXACT)
    np.testing.assert_allclose(A[2, 1], A1, rtol=EXACT, atol=EXACT)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        pytest.param({"t_max": -1.0}, "t_max", id="t_max"),
        pytest.param({"ca0": 0.0}, "ca0", id="ca0"),
        pytest.param({"ca0_max": -4.0}, "ca0_max", id="ca0_max"),
        pytest.param({"beta": 0.0}, "beta", id="beta"),
        pytest.param({"l0": -1.0}, "l0", id="l0"),
        pytest.param({"lr": float("nan")}, "lr", id="lr"),
    ],
)
def test_active_bad_parameters_name_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=f"parameter '{name}' must be"):
        ActiveContraction(**kwargs)


def test_active_bad_law():
    with pytest.raises(ValueError, match="parameter 'law' must be 'prescribed' or 'calcium'"):
        ActiveContraction(law="hill")  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------
# growth
# --------------------------------------------------------------------------------------


def _total_response(mat, fiber):
    """Total (isochoric + volumetric, pointwise J) response of an uncoupled material."""
    from harpx.mechanics.kinematics import volumetric_response

    def response(Fe):
        P, A = mat.isochoric_response(Fe, fiber)
        _, dU, d2U = mat.volumetric(np.linalg.det(Fe))
        Pv, Av = volumetric_response(Fe, dU, d2U)
        return P + Pv, A + Av

    return response


def _grown(mat, growth, fiber):
    Fg = growth.tensor(fiber)
    Jg = np.linalg.det(Fg)
    elastic = _total_response(mat, fiber)

    def energy(F):
        return Jg * mat.strain_energy(split_growth(F, Fg), fiber)

    def response(F):
        return push_growth_response(*elastic(split_growth(F, Fg)), Fg)

    return energy, response


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("theta", [0.85, 1.2])
@pytest.mark.parametrize(
    "mat", [pytest.param(NH, id="neo-hookean"), pytest.param(GUCCIONE, id="guccione")]
)
def test_growth_composed_response_matches_finite_differences(rng, mat, theta, scale):
    n = 20
    F = _random_F(rng, n, scale)
    fiber = _random_fibers(rng, n)
    energy, response = _grown(mat, FiberGrowth(theta), fiber)
    P, _ = response(F)
    err_P = _rel(P, _fd_gradient(energy, F))
    assert err_P <= FD_RTOL_P, f"P vs dW/dF: relative error {err_P:.2e}"
    err_A = _check_tangent(response, F, rng)
    assert err_A <= FD_RTOL_A, f"A vs dP/dF: relative error {err_A:.2e}"


@pytest.mark.parametrize(
    "mat", [pytest.param(NH, id="neo-hookean"), pytest.param(GUCCIONE, id="guccione")]
)
def test_pure_growth_is_stress_free(rng, mat):
    fiber = _random_fibers(rng, 6)
    growth = FiberGrowth(1.15)
    _, response = _grown(mat, growth, fiber)
    P, _ = response(growth.tensor(fiber))
    # Fe = I up to one rounding: stresses ~1e-13 kPa against moduli ~1e2 kPa
    np.testing.assert_allclose(P, 0.0, atol=EXACT * mat.kappa)


@pytest.mark.parametrize(
    "mat", [pytest.param(NH, id="neo-hookean"), pytest.param(GUCCIONE, id="guccione")]
)
def test_growth_held_at_reference_compresses_fibers(rng, mat):
    fiber = _random_fibers(rng, 6)
    _, response = _grown(mat, FiberGrowth(1.15), fiber)
    P, _ = response(np.broadcast_to(np.eye(3), (6, 3, 3)))
    P_ff = np.einsum("ni,nij,nj->n", fiber, P, fiber)
    assert np.all(P_ff < 0.0), f"P_ff = {P_ff}"


def test_fiber_growth_tensor_matches_kinematics(rng):
    fiber = _random_fibers(rng, 4)
    np.testing.assert_array_equal(FiberGrowth(1.1).tensor(fiber), growth_tensor(fiber, 1.1))


@pytest.mark.parametrize("stretch", [0.0, -1.0, float("nan")])
def test_fiber_growth_bad_stretch(stretch):
    with pytest.raises(ValueError, match="parameter 'stretch' must be a finite number > 0"):
        FiberGrowth(stretch)
