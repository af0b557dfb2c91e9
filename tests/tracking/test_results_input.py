"""Inputs that would make the comparison with the truth or the uncertainty silently wrong.

* ``tracking_error``: the tracked displacement is relative to its first frame, the truth's
  to the frame where it is zero; a truth referenced elsewhere, or without the tracked
  reference frame, or with no frame after it, is refused (uniform motions, closed form);
* ``tracking_uncertainty``: noise-free images have no noise to propagate (refused); a tag
  without noise is not passed through the phase extraction (its harmonic noise is 0 in
  closed form) and what the extraction says about the internal noise samples reaches the
  user once, flagged, not as warnings about their frames.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import xarray as xr

from harpx.errors import HarpxWarning
from harpx.imaging.harp import extract_phase
from harpx.imaging.synth import synthesize_tagged
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box
from harpx.tracking import uncertainty_phase
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track
from harpx.tracking.uncertainty import image_noise, tracking_uncertainty
from harpx.tracking.uncertainty_phase import harmonic_fields

GRID = {"z": [0.0, 2.0], "y": [0.0, 2.0, 4.0], "x": [0.0, 2.0, 4.0, 6.0]}
DIMS = ("time", "axis", "z", "y", "x")


def _field(name: str, times: list[float], ux: list[float]) -> xr.Dataset:
    """A uniform displacement ``ux`` (mm, one per frame) along x on a 2 x 3 x 4 grid."""
    u = np.zeros((len(times), 3, 2, 3, 4))
    u[:, 0] = np.asarray(ux)[:, None, None, None]
    return xr.Dataset({name: (DIMS, u)}, coords={"time": times, "axis": ["x", "y", "z"], **GRID})


TIMES = [0.0, 10.0, 20.0, 30.0]
TRUTH = _field("displacement_true", TIMES, [0.1 * t for t in TIMES])  # 0.1 mm/ms from t = 0


def test_a_result_tracked_from_a_later_frame_is_refused() -> None:
    # exact tracking from 20 ms: 0.1 (t - 20) mm. Against the truth from 0 ms every frame
    # would differ by the truth's 2 mm at 20 ms (unfixed: mean_all 2.0 mm, true error 0)
    later = _field("displacement_grid", [20.0, 30.0], [0.0, 1.0])
    with pytest.raises(ValueError, match=r"time 20.0 ms.*referenced to time 0.0 ms"):
        tracking_error(later, TRUTH)
    # the truth cut to the same frames is still referenced to 0 ms (2 mm at 20 ms)
    with pytest.raises(ValueError, match=r"up to 2 mm\): no frame of the truth has zero"):
        tracking_error(later, TRUTH.sel(time=[20.0, 30.0]))


def test_a_truth_at_rest_until_the_tracked_reference_is_compared() -> None:
    # at rest until 10 ms: the configurations at 0 and 10 ms are the same, so a result
    # tracked from 10 ms compares exactly; here 0.05 mm too far at 30 ms
    truth = _field("displacement_true", TIMES, [0.0, 0.0, 1.0, 2.0])
    tracked = _field("displacement_grid", [10.0, 20.0, 30.0], [0.0, 1.0, 2.05])
    err = tracking_error(tracked, truth)
    assert err.time.values.tolist() == [10.0, 20.0, 30.0]
    np.testing.assert_allclose(err["mean"], [0.0, 0.0, 0.05], atol=1e-12)
    np.testing.assert_allclose(err["mean_all"], 0.025, atol=1e-12)  # frames 20 and 30


def test_a_truth_without_the_reference_frame_is_refused() -> None:
    # errors 0.05 n mm in frame n; unfixed, the truth at 20, 30 ms lost frame 20 from the
    # overall statistics (mean_all 0.15 mm instead of 0.125 mm)
    tracked = _field("displacement_grid", TIMES, [0.1 * t + 0.05 * n for n, t in enumerate(TIMES)])
    with pytest.raises(ValueError, match=r"lacks the tracked result's reference frame, time 0.0"):
        tracking_error(tracked, TRUTH.sel(time=[20.0, 30.0]))
    # keeping it: compared; the tracked frame at 10 ms has no truth and is named
    with pytest.warns(HarpxWarning, match=r"no frame at tracked t = 10 ms"):
        err = tracking_error(tracked, TRUTH.sel(time=[0.0, 20.0, 30.0]))
    np.testing.assert_allclose(err["mean"], [0.0, 0.10, 0.15], atol=1e-12)
    np.testing.assert_allclose(err["mean_all"], 0.125, atol=1e-12)


def test_only_the_reference_frame_in_common_is_named() -> None:
    tracked = _field("displacement_grid", TIMES, [0.1 * t for t in TIMES])
    with pytest.raises(ValueError, match=r"share only the reference frame, time 0.0 ms"):
        tracking_error(tracked, TRUTH.sel(time=[0.0]))  # unfixed: IndexError
    with pytest.raises(ValueError, match=r"no body voxel after the reference.*'where'"):
        tracking_error(tracked, TRUTH, where=TRUTH.x > 100.0)  # unfixed: IndexError


# --- tracking_uncertainty -------------------------------------------------------------------

SHIFT = np.array([0.8, -0.5, 0.3])  # mm at 20 ms
FIXED = {"epsilon": 1.0, "ramp": 1, "penalty": 20.0, "penalty_limit": 20.0}  # no λ choice


def _case(snr: float | None) -> tuple[xr.Dataset, xr.Dataset, Body, xr.Dataset]:
    """A rigid translation imaged on a small grid, tracked at a fixed penalty."""
    tagged = synthesize_tagged(
        lambda X, t: np.broadcast_to(SHIFT * t / 20.0, X.shape), shape=(8, 16, 16),
        spacing=(1.5, 1.5, 1.5), times=[0.0, 20.0], tags=("x", "y", "z"), snr=snr,
        oversample=1, rng=0,
    )  # fmt: skip
    body = Body(box((12.0, 12.0, 6.0), (2, 2, 1), origin=(-6.0, -6.0, -3.0)),
                NeoHookean(c1=1.0, kappa=100.0))  # fmt: skip
    phase = extract_phase(tagged)
    return tagged, phase, body, track(phase, body, **FIXED)


def test_noise_free_images_are_refused_with_one_error() -> None:
    tagged, phase, body, tracked = _case(None)
    assert phase["harmonic_noise"].values.tolist() == [0.0, 0.0, 0.0]
    # unfixed: every standard deviation 0, with 'constant images' warnings about the
    # internal noise samples (errors here) and a penalty ratio of order 1e5
    with pytest.raises(ValueError, match=r"noise-free.*harmonic_noise \[0.0, 0.0, 0.0\] and"):
        tracking_uncertainty(tracked, body, phase, tagged=tagged, samples=2, seed=0)
    with pytest.raises(ValueError, match=r"noise-free.*harmonic_noise \[0.0, 0.0, 0.0\]; "):
        tracking_uncertainty(tracked, body, phase, samples=2, seed=0)
    # the remedy the message names, an assumed level, is accepted (planes assumed
    # independent: that warning is the documented one)
    assumed = phase.assign(harmonic_noise=phase["harmonic_noise"] + 0.016)
    with pytest.warns(HarpxWarning, match="taken as independent"):
        out = tracking_uncertainty(tracked, body, assumed, samples=2, seed=0)
    assert float(out.displacement_std.isel(time=1).mean()) > 1e-3  # mm (measured 0.01)


def test_a_tag_without_noise_has_zero_harmonic_noise_and_no_extraction() -> None:
    tagged, phase, _, _ = _case(20.0)
    noise = image_noise(phase, tagged)
    silent = dataclasses.replace(noise, factors=(0.0 * noise.factors[0], *noise.factors[1:]))
    # unfixed: the blank noise images of tag x made the extraction warn (errors here)
    some = harmonic_fields(silent, phase, np.random.default_rng(5), 3)
    every = harmonic_fields(noise, phase, np.random.default_rng(5), 3)
    assert some.shape == every.shape == (3, 3, *(phase.sizes[d] for d in ("z", "y", "x")))
    assert not np.any(some[0])  # zero image noise: zero harmonic noise, exactly
    # the other tags drew the same numbers and are extracted tag by tag: the same fields
    np.testing.assert_allclose(some[1:], every[1:], rtol=0, atol=1e-6 * np.abs(every).max())
    assert np.abs(every[1:]).max() > 0.01  # and they are noise (measured about 0.06)


def test_a_noise_free_tag_among_noisy_ones_is_flagged_once() -> None:
    tagged, phase, body, tracked = _case(20.0)
    level = phase["harmonic_noise"] * xr.DataArray([0.0, 1.0, 1.0], dims="tag")  # x: none
    quiet = phase.assign(harmonic_noise=level)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = tracking_uncertainty(tracked, body, quiet, samples=2, seed=0)
    said = [str(w.message) for w in caught if issubclass(w.category, HarpxWarning)]
    assert len(said) == 2, said  # planes assumed independent; tag x without noise
    assert sum("tag(s) ['x'] carry no image noise" in m for m in said) == 1, said
    assert "carry no image noise" in out.attrs["flags"]
    assert float(out.displacement_std.isel(time=1).mean()) > 1e-3  # mm (y, z noise)


def test_warnings_about_internal_noise_samples_reach_the_user_once(monkeypatch) -> None:
    tagged, phase, body, tracked = _case(20.0)
    real = uncertainty_phase._extract_phase

    def noisy_extraction(*args, **kwargs):  # what a blank noise sample made it say
        warnings.warn("constant images: tag 'x' frame(s) [0, 1]", HarpxWarning, stacklevel=2)
        return real(*args, **kwargs)

    monkeypatch.setattr(uncertainty_phase, "_extract_phase", noisy_extraction)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = tracking_uncertainty(tracked, body, phase, tagged=tagged, samples=2, seed=0)
    said = [str(w.message) for w in caught if issubclass(w.category, HarpxWarning)]
    # unfixed: one 'constant images' warning per frame's noise batch (2 here), as if about
    # the user's frames 0 and 1
    assert len(said) == 1, said
    assert "sampled image-noise" in said[0] and "not your frames" in said[0]
    assert "in 2 of the noise sample batches" in said[0]
    assert said[0] in out.attrs["flags"]
    assert float(out.displacement_std.isel(time=1).mean()) > 1e-3  # mm: still computed
