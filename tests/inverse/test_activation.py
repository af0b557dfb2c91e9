"""Direct activation estimate, equilibrium correction, calibration and re-simulation."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.errors import HarpxWarning
from harpx.inverse import (
    calibrate_activation,
    correct_activation,
    estimate_activation,
    resimulate,
    uniaxial_active_tension,
)
from harpx.mechanics.body import Body
from harpx.mechanics.fiber_laws import ActiveContraction
from harpx.mechanics.loads import Fixed
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box
from harpx.physiology.active import region_values, simulate_activation, simulate_history
from harpx.plotting import plot_stretch_agreement

MATERIAL = NeoHookean(c1=1.0, kappa=120.0)
SYMMETRY = [Fixed("left", (0,)), Fixed("front", (1,)), Fixed("bottom", (2,))]


def _as_tracked(body, U):
    """A minimal tracked/1-like dataset of the displacement history U (ntime, ndof)."""
    return xr.Dataset(
        {
            "points": (("node", "axis"), body.dof_points),
            "displacement": (
                ("time", "node", "axis"),
                np.stack([body.nodal_displacement(u) for u in U]),
            ),
            "fiber_stretch": (("time", "cell"), np.stack([body.fiber_stretch(u) for u in U])),
        },
        coords={"time": np.arange(len(U)) * 50.0, "axis": ["x", "y", "z"]},
    )


def _block(fiber, law, element="hex8"):
    spec = box((10.0, 4.0, 4.0), (3, 2, 2))  # coarse mesh so the test is fast
    fibers = np.tile(np.asarray(fiber, dtype=float), (spec.mesh.nelements, 1))
    return Body(spec, MATERIAL, fibers=fibers, element=element, active=law, t_max=0.0)


@pytest.mark.parametrize("lam", [0.8, 0.95, 1.1])
def test_uniaxial_tension_closed_form(lam):
    F = np.diag([lam, lam**-0.5, lam**-0.5])  # isochoric uniaxial stretch along the fibre
    T, stretch = uniaxial_active_tension(MATERIAL, F, [1.0, 0.0, 0.0])
    # T_a = 2 C1 (λ⁻³ - 1) for the uncoupled neo-Hookean solid: an identity, round-off
    np.testing.assert_allclose(T, 2.0 * (lam**-3 - 1.0), rtol=1e-12)
    np.testing.assert_allclose(stretch, lam, rtol=1e-14)


def test_tension_is_objective_and_ignores_the_pressure(rng):
    F = np.diag([0.9, 1.02, 1.07])  # J != 1: the pressure-free form must not care
    R, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    R *= np.sign(np.linalg.det(R))
    f = [1.0, 0.0, 0.0]
    T, _ = uniaxial_active_tension(MATERIAL, F, f)
    T_rot, _ = uniaxial_active_tension(MATERIAL, R @ F, f)
    np.testing.assert_allclose(T_rot, T, rtol=1e-12)  # superposed rotation: round-off
    stiff = NeoHookean(c1=1.0, kappa=1e4)
    np.testing.assert_allclose(uniaxial_active_tension(stiff, F, f)[0], T, rtol=1e-12)


@pytest.mark.parametrize(
    ("law", "fiber", "t_true"),
    [
        pytest.param(ActiveContraction(t_max=0.0), [1.0, 0.0, 0.0], 2.0, id="calcium-x"),
        pytest.param(ActiveContraction(t_max=0.0), [0.0, 0.0, 1.0], 1.3, id="calcium-z"),
        pytest.param(
            ActiveContraction(t_max=0.0, law="prescribed"), [0.0, 1.0, 0.0], 0.7, id="prescribed-y"
        ),
    ],
)
def test_homogeneous_block_recovers_t_max_exactly(law, fiber, t_true):
    # symmetry planes and free faces: homogeneous uniaxial stress along the fibre, where the
    # direct estimate's assumption holds exactly (any κ)
    body = _block(fiber, law)
    u = simulate_activation(body, t_true, loads=SYMMETRY, steps=3).u
    lam = body.fiber_stretch(u)
    assert 0.75 < lam.mean() < 0.97  # a real contraction
    passive = Body(
        body.mesh, MATERIAL, fibers=body.fibers, regions=body.regions, boundaries=body.boundaries
    )
    est = estimate_activation(_as_tracked(passive, [np.zeros(body.ndof), u]), passive, law=law)
    # Newton's relative tolerance 1e-8 bounds the equilibrium error
    np.testing.assert_allclose(est["t_max_cell"].values, t_true, rtol=1e-6)
    np.testing.assert_allclose(est["t_max"].values, t_true, rtol=1e-6)
    assert est["t_max"].dims == ("region",) and int(est["valid_cells"][0]) == body.ncell
    assert est.attrs["time_index"] == 1


@pytest.fixture(scope="module")
def two_muscles():
    """A clamped bar with two muscles (fibres along x, then along y) of known activation."""
    spec = box((12.0, 4.0, 4.0), (4, 2, 2))  # coarse mesh so the test is fast
    centres = spec.mesh.p[:, spec.mesh.t].mean(axis=1)
    front = np.nonzero(centres[0] < 6.0)[0]
    back = np.nonzero(centres[0] >= 6.0)[0]
    fibers = np.zeros((spec.mesh.nelements, 3))
    fibers[front, 0] = 1.0
    fibers[back, 1] = 1.0
    regions = {"A": front, "B": back}
    law = ActiveContraction(t_max=0.0)
    active = Body(
        spec, MATERIAL, fibers=fibers, regions=regions, element="hex20", active=law, t_max=0.0
    )
    truth = {"A": 0.6, "B": 0.4}  # 5-7 % fibre shortening, as in the tongue scene
    bcs = [Fixed("left")]
    U = simulate_history(active, truth, 3, dirichlet=bcs)
    passive = Body(spec, MATERIAL, fibers=fibers, regions=regions, element="hex20")
    return passive, bcs, truth, U


def test_direct_estimate_is_biased_and_the_correction_removes_the_bias(two_muscles):
    body, bcs, truth, U = two_muscles
    tracked = _as_tracked(body, U)
    direct = estimate_activation(tracked, body)
    t_true = np.array([truth["A"], truth["B"]])
    # the clamp and the other muscle carry part of the load: the local (uniaxial) estimate
    # is biased low (measured 4 % and 4 %)
    assert np.all(direct["t_max"].values < 0.98 * t_true), direct["t_max"].values
    corrected = correct_activation(direct, tracked, body, dirichlet=bcs)
    # exact when the tracked motion is an equilibrium of the model: linear solve, round-off
    # and Newton tolerance (1e-8)
    np.testing.assert_allclose(corrected["t_max"].values, t_true, rtol=1e-6)
    np.testing.assert_allclose(corrected["t_max_direct"].values, direct["t_max"].values)
    assert corrected["stretch_sensitivity"].dims == ("region", "source_region")
    # a muscle shortens when it is activated
    assert np.all(np.diag(corrected["stretch_sensitivity"].values) < 0)


def test_resimulation_with_the_truth_reproduces_the_tracked_stretch(two_muscles, tmp_path):
    body, bcs, truth, U = two_muscles
    tracked = _as_tracked(body, U)
    sim = resimulate(body, truth, dirichlet=bcs, tracked=tracked)
    # same model, same activation: the stretches agree to the Newton tolerance
    np.testing.assert_allclose(
        sim["fiber_stretch_simulated"], sim["fiber_stretch_tracked"], atol=1e-7
    )
    assert float(sim["mean_abs_difference_all"]) < 1e-7
    assert float(sim["correlation_all"]) > 0.999999
    assert body.active is None  # the tracking model is not modified
    fig = plot_stretch_agreement(sim, path=tmp_path / "fig3c.png", truth={"A": 0.93, "B": 0.95})
    assert (tmp_path / "fig3c.png").stat().st_size > 10_000
    assert len(fig.axes) == 2


def test_calibration_undoes_an_attenuating_measurement(two_muscles):
    body, bcs, truth, U = two_muscles

    def measure(b, displacement):  # a chain that loses 30 % of every displacement
        return _as_tracked(b, 0.7 * np.asarray(displacement))

    tracked = measure(body, U)
    est = correct_activation(estimate_activation(tracked, body), tracked, body, dirichlet=bcs)
    t_true = np.array([truth["A"], truth["B"]])
    assert np.all(est["t_max"].values < 0.85 * t_true)  # attenuated by the chain
    cal = calibrate_activation(est, tracked, body, measure=measure, dirichlet=bcs)
    # exact for a chain that is linear in activation; a 0.7 displacement scale is not quite
    # (the stretch-activation relation is nonlinear): measured 3.4 % and 2.1 %, bound 5 %
    np.testing.assert_allclose(cal["t_max"].values, t_true, rtol=0.05)
    np.testing.assert_allclose(cal["t_max_uncalibrated"].values, est["t_max"].values)
    assert np.all(cal["chain_transfer"].values < 0.85)
    # an identity chain leaves the estimate unchanged (its own re-simulation is reproduced)
    same = calibrate_activation(
        est, tracked, body, measure=lambda b, d: _as_tracked(b, d), dirichlet=bcs
    )
    np.testing.assert_allclose(same["chain_transfer"].values, 1.0, rtol=1e-6)


def test_estimate_round_trips_through_netcdf(two_muscles, tmp_path):
    from harpx.io.netcdf import open_dataset, to_netcdf

    body, bcs, truth, U = two_muscles
    tracked = _as_tracked(body, U)
    est = correct_activation(estimate_activation(tracked, body), tracked, body, dirichlet=bcs)
    back = open_dataset(to_netcdf(est, tmp_path / "activation.nc"))
    xr.testing.assert_identical(back, est)  # exact: floats, strings and attrs round-trip


def test_bad_inputs_are_named(two_muscles):
    body, bcs, truth, U = two_muscles
    tracked = _as_tracked(body, U)
    no_fibres = Body(box((1.0, 1.0, 1.0), (1, 1, 1)), MATERIAL)
    with pytest.raises(ValueError, match="no fibers"):
        estimate_activation(tracked, no_fibres)
    with pytest.raises(ValueError, match="time=5"):
        estimate_activation(tracked, body, time=5)
    with pytest.raises(ValueError, match="aggregate='mode'"):
        estimate_activation(tracked, body, aggregate="mode")
    other = Body(box((12.0, 4.0, 4.0), (2, 1, 1)), MATERIAL, fibers=np.tile([1.0, 0, 0], (2, 1)))
    with pytest.raises(ValueError, match="do not match"):
        estimate_activation(tracked, other)
    with pytest.raises(ValueError, match="'displacement', 'points'"):
        estimate_activation(tracked.drop_vars(["displacement", "points"]), body)
    with pytest.raises(ValueError, match="region 'C'"):
        resimulate(body, {"C": 1.0}, dirichlet=bcs)
    # NaN is a region without an estimate: simulated at rest, with a warning naming it (it may
    # be the most contracted muscle, past the law's range); an infinite level is refused
    with pytest.warns(HarpxWarning, match=r"region\(s\) \['A'\]"):
        assert region_values(body, {"A": np.nan, "B": 0.4}) == {"A": 0.0, "B": 0.4}
    with pytest.raises(ValueError, match="t_max of region 'A' is inf kPa"):
        resimulate(body, {"A": np.inf, "B": 0.4}, dirichlet=bcs)
    with pytest.raises(ValueError, match="active law"):
        simulate_activation(body, 1.0)
    with pytest.raises(ValueError, match="frames=1"):
        simulate_history(body, truth, 1)
    est = estimate_activation(tracked, body)
    with pytest.raises(ValueError, match="measure"):
        calibrate_activation(est, tracked, body, measure=lambda b, d: _as_tracked(b, d[:2]))
    with pytest.raises(ValueError, match="no tracked stretch"):
        plot_stretch_agreement(resimulate(body, truth, dirichlet=bcs))


def test_calibration_keeps_a_region_without_an_estimate_nan(two_muscles):
    # muscle B without an estimate: it rests in the calibration run and stays NaN (it came
    # out 0 kPa before, a plausible "inactive muscle"); A is calibrated as usual
    body, bcs, truth, U = two_muscles

    def measure(b, displacement):
        return _as_tracked(b, 0.7 * np.asarray(displacement))

    tracked = measure(body, U)
    est = correct_activation(estimate_activation(tracked, body), tracked, body, dirichlet=bcs)
    est["t_max"] = est["t_max"].where(est["region"] != "B")
    with pytest.warns(HarpxWarning, match=r"region\(s\) \['B'\] have no estimate"):
        cal = calibrate_activation(est, tracked, body, measure=measure, dirichlet=bcs)
    assert np.isnan(cal["t_max"].sel(region="B").item())
    assert cal["t_max_missing"].values.tolist() == [False, True]
    assert 0.0 < cal["t_max"].sel(region="A").item() < 2 * truth["A"]
