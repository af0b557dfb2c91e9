"""Image noise from the signal-free spectrum, and the noise it leaves in the harmonic image.

Each estimate is checked against the noise actually there: the difference between images
synthesised with and without noise from the same seed."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.imaging.harp import extract_phase
from harpx.imaging.noise import slice_noise
from harpx.imaging.synth import synthesize_tagged


def _ring(X: np.ndarray) -> np.ndarray:
    R = np.hypot(X[:, 0], X[:, 1])
    return ((R > 8.0) & (R < 16.0)).astype(np.float64)


def _pair(sequence: str, snr: float):
    kw = dict(
        shape=(3, 48, 48), spacing=(6.0, 1.2, 1.2), origin=(-6.0, -28.2, -28.2),
        times=[0.0, 40.0], tag_period=7.0, tags=("x", "y"), slice_axis="z",
        sequence=sequence, body=_ring, oversample=1,
    )  # fmt: skip
    still = lambda X, t: 0.0 * X  # noqa: E731
    noisy = synthesize_tagged(still, snr=snr, rng=3, **kw)
    clean = synthesize_tagged(still, snr=None, **kw)
    return noisy, clean


@pytest.mark.parametrize("sigma", [4.0, 10.0])
def test_slice_noise_recovers_white_noise_under_tags_and_edges(rng, sigma):
    # a tagged disk with sharp edges (peak 200, SNR 50 and 20): the estimate must not see
    # the tags or the edges. Within 8 %: the MAD of 12k samples has ~1.5 % sd, and the
    # ~5 % of differences that straddle the disk's edge lift the median by ~4 %.
    x = (np.arange(64) - 31.5) * 1.2
    X, Y = np.meshgrid(x, x, indexing="ij")
    disk = (np.hypot(X, Y) < 25.0) * 100.0 * (1.0 + np.cos(2 * np.pi * Y / 7.0))
    noisy = disk[None] + rng.normal(0.0, sigma, (3, 64, 64))
    assert slice_noise(noisy, (1.2, 1.2), (0.0, 1 / 7)) == pytest.approx(sigma, rel=0.08)


def test_slice_noise_is_nan_for_tags_oblique_to_both_axes(rng):
    # tags at 45°: no pixel axis runs along the tag lines, so no difference removes them
    image = rng.normal(0.0, 1.0, (4, 64, 64))
    f = np.array([1.0, 1.0]) / (7.0 * np.sqrt(2.0))
    assert np.isnan(slice_noise(image, (1.2, 1.2), f))
    assert slice_noise(image, (1.2, 1.2), (0.0, 1 / 7)) == pytest.approx(1.0, rel=0.08)


@pytest.mark.parametrize("sequence", ["CSPAMM", "SPAMM"])
def test_harmonic_noise_matches_the_noise_in_the_harmonic_image(sequence):
    noisy, clean = _pair(sequence, snr=15.0)
    pn, pc = extract_phase(noisy), extract_phase(clean)
    est = pn["harmonic_noise"]
    assert est.attrs["units"] and est.attrs["long_name"]
    assert "harmonic_noise" in pc and pc["harmonic_noise"].dims == ("tag",)
    hn = pn.magnitude * np.exp(1j * pn.phase)
    hc = pc.magnitude * np.exp(1j * pc.phase)
    actual = np.sqrt((np.abs(hn - hc) ** 2).isel(time=0).mean(("z", "y", "x"))).values
    # within 25 %: SPAMM magnitude noise is Rician, weaker outside the tissue, and the
    # ring's edges leave a little signal in the noise band
    np.testing.assert_allclose(est.values, actual, rtol=0.25)
    # noise-free images: (almost) nothing, far below the noisy estimate
    assert np.all(pc["harmonic_noise"].values < 0.05 * est.values)


def test_harmonic_noise_stays_lazy():
    from tests._helpers import raise_if_dask_computes

    noisy, _ = _pair("CSPAMM", snr=15.0)
    lazy = noisy.copy()
    lazy["image"] = noisy["image"].chunk({"tag": 1, "time": 1})
    with raise_if_dask_computes():
        out = extract_phase(lazy)
    assert out["harmonic_noise"].chunks is not None
    eager = extract_phase(noisy)["harmonic_noise"].values
    np.testing.assert_allclose(out["harmonic_noise"].values, eager, rtol=1e-12)


def test_tracker_noise_floor_is_the_residual_of_noise_at_the_true_motion():
    # a still ring imaged twice with independent noise: at the true motion (none) the
    # tracking residual is noise alone, the independent truth both floor estimates are held
    # to. From harmonic_noise: measured floor / residual = 1.32 (CSPAMM) and 1.06 (SPAMM) at
    # SNR 10 (σ is estimated from one frame; near the ring's edges |H| is low, where the
    # first-order phase noise σ/|H| overstates the saturating true one, more so for CSPAMM's
    # weaker harmonic at the edges). Within ±12 %: the one-frame σ estimate from ~2k
    # signal-free samples has a few % sd, so a change of the formula (e.g. dropping the
    # factor ½ of the across-H noise: ×√2) fails it.
    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean
    from harpx.mechanics.mesh import tube
    from harpx.tracking.constraint import PhaseConstraint

    mesh = tube(9.0, 15.0, 12.0, n_radial=2, n_circumferential=16, n_axial=2,
                center=(0.0, 0.0, -6.0))  # fmt: skip
    body = Body(mesh, NeoHookean(c1=1.0, kappa=50.0))
    measured = {"CSPAMM": (1.32, 1.20), "SPAMM": (1.06, 1.38)}  # (noise, affine) / residual
    for sequence in ("CSPAMM", "SPAMM"):
        noisy, clean = _pair(sequence, snr=10.0)
        phase = extract_phase(noisy)
        constraint = PhaseConstraint(body, phase)
        constraint.set_frame(1)
        still_u = np.zeros(body.ndof)
        floor, actual = constraint.epsilon_floor(still_u), constraint.epsilon_at(still_u)
        from_noise, from_affine = measured[sequence]
        assert floor / actual == pytest.approx(from_noise, rel=0.12), sequence
        # without the noise estimate (an older archive) the floor comes from the affine fit
        # of the reference frame's phase: it counts the filter's edge error as noise too, so
        # it lies higher, 1.20 / 1.38 times the residual measured (±12 % as above)
        older = PhaseConstraint(body, phase.drop_vars("harmonic_noise"))
        assert older.harmonic_noise is None
        older.set_frame(1)
        assert older.epsilon_floor(still_u) / actual == pytest.approx(from_affine, rel=0.12)
        # noise-free images: no noise floor
        quiet = PhaseConstraint(body, extract_phase(clean))
        quiet.set_frame(1)
        assert quiet.epsilon_floor(still_u) < 0.05 * floor


@pytest.mark.parametrize("with_noise", [True, False], ids=["harmonic_noise", "affine"])
def test_a_noise_floor_where_the_phase_was_just_sampled_reuses_those_magnitudes(
    with_noise, monkeypatch
):
    # the predictor samples its candidates' phase (epsilon_at); the noise floor at the chosen
    # one takes the magnitudes of that sampling: the same floor to the bit, no new sampling.
    # Another displacement or another preparation of the frame samples again.
    from harpx.imaging.sample import PhaseSampler
    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean
    from harpx.mechanics.mesh import tube
    from harpx.tracking.constraint import PhaseConstraint

    mesh = tube(9.0, 15.0, 12.0, n_radial=2, n_circumferential=16, n_axial=2,
                center=(0.0, 0.0, -6.0))  # fmt: skip
    body = Body(mesh, NeoHookean(c1=1.0, kappa=50.0))
    phase = extract_phase(_pair("CSPAMM", snr=10.0)[0])
    constraint = PhaseConstraint(body, phase if with_noise else phase.drop_vars("harmonic_noise"))
    constraint.set_frame(1)
    u = np.random.default_rng(3).normal(0.0, 0.3, body.ndof)
    fresh = constraint.epsilon_floor(u)
    calls = []
    sample = PhaseSampler.magnitude
    monkeypatch.setattr(PhaseSampler, "magnitude", lambda s, p: calls.append(1) or sample(s, p))
    constraint.epsilon_at(u + 0.2)
    constraint.epsilon_at(u.copy())
    assert constraint.epsilon_floor(u) == fresh and not calls
    assert constraint.epsilon_floor(u + 0.1) != fresh and len(calls) == 1
    constraint.set_frame(1)
    assert constraint.epsilon_floor(u) == fresh and len(calls) == 2
