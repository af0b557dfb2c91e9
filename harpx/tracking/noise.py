r"""The noise floor of the tracking residual ε that the images themselves allow.

Even at the true motion the residual :math:`W(\phi(x, t) - \phi_0(X))` is not zero: both
phases carry image noise, the band-pass filter blurs the phase near the tissue's edges, and
the tags fade. Raising the penalty past that floor only fits noise, and costs Gauss–Newton
iterations. The floor is estimated from the data, before any tracking:

1. **Reference frame.** At the tagging time the tags are undeformed, so each tag's phase is
   affine in the material position, :math:`\phi_{0,t}(X) = k_t \cdot X + c_t`. The weighted
   mean :math:`\varepsilon_{0,t}` of :math:`|W(\phi_{0,t} - k_t \cdot X - c_t)|` over the
   constraint points, after fitting :math:`k_t` and :math:`c_t` (starting from the nominal
   wave vector :math:`2\pi f_t \hat d_t`), is that frame's phase noise and edge error.
2. **Later frames.** Phase noise scales as :math:`\sigma/|H|` (for a harmonic image with
   additive complex noise σ, the phase error is :math:`\sigma/|H|` to first order), so as the
   tags fade the floor grows with the mean harmonic magnitude :math:`\bar m` at the tissue:

   .. math::

       \varepsilon_{\mathrm{floor}, n} = \sum_t w_t\, \varepsilon_{0,t}\,
       \max\!\big(1, \bar m_{0,t} / \bar m_{n,t}\big),

   with :math:`w_t` the share of constraint volume that tag t has data in. A single frame's
   error is used, not the root sum of two frames' (which would be
   :math:`\sqrt 2` larger for independent errors), because the filter's edge error moves
   with the tissue and largely cancels between frames.

The estimate is recorded per frame as ``epsilon_floor`` in the tracked result; the default
target is a fixed factor above it (:class:`harpx.tracking.settings.TrackingSettings`).

**From the image noise.** When the phase images carry ``harmonic_noise`` (the noise
standard deviation :math:`\sigma_H` of each complex harmonic image, measured from the
signal-free part of the tagged images' spectrum by :mod:`harpx.imaging.noise`), the floor is
the noise alone, point by point (:func:`noise_floor`): the residual
:math:`r = \phi_n(x) - \phi_0(X)` carries the phase noise of both frames,
:math:`\sigma_r^2 = \tfrac12 \sigma_H^2 (|H_0(X)|^{-2} + |H_n(x)|^{-2})` (only the noise
component across :math:`H`, half its complex variance, turns the phase), and its mean
modulus is
:math:`\sqrt{2/\pi}\,\sigma_r` (at most π/2, the mean of a uniform phase). This leaves out
the filter's edge error, which the affine estimate above counts as noise although it is a
bias the tracker should follow (stopping at it leaves the model short of the data). Phase
datasets without
``harmonic_noise`` (written by older versions or built by hand) keep the affine estimate.
"""

from __future__ import annotations

import numpy as np

from harpx._typing import FloatArray
from harpx.imaging.sample import wrap

__all__ = ["MAX_FADING", "epsilon_floor", "noise_floor", "reference_residual"]

#: Largest growth of the floor by tag fading (a frame whose tags faded tenfold has no usable
#: phase left; that is the sampler's magnitude floor's job to say).
MAX_FADING = 10.0


def reference_residual(
    points: FloatArray,
    volume: FloatArray,
    phase: FloatArray,
    valid: np.ndarray,
    wavevectors: FloatArray,
    *,
    refinements: int = 2,
) -> FloatArray:
    r"""Per-tag residual of an affine phase fitted to the reference frame, rad.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Reference positions, mm.
    volume : ndarray, shape (n,)
        Weights of the points (quadrature volumes), mm³.
    phase : ndarray, shape (n, ntag)
        Reference-frame phase φ0 at the points, rad (wrapped).
    valid : ndarray of bool, shape (n, ntag)
        Which tags have data at each point.
    wavevectors : ndarray, shape (ntag, 3)
        Nominal tag wave vectors 2π f d̂, rad/mm.
    refinements : int, default 2
        Weighted least-squares corrections of the wave vector and offset.

    Returns
    -------
    ndarray, shape (ntag,)
        Weighted mean :math:`|W(\phi_0 - k \cdot X - c)|` per tag, rad (NaN for a tag without data).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> X = rng.uniform(0, 20, (4000, 3))
    >>> k = np.array([[2 * np.pi / 8, 0, 0]])
    >>> noise = rng.normal(0, 0.1, (4000, 1))
    >>> phi = wrap(X @ (1.01 * k).T + 0.3 + noise)  # wave vector 1 % off nominal
    >>> eps0 = reference_residual(X, np.ones(4000), phi, np.ones((4000, 1), bool), k)
    >>> bool(abs(eps0[0] - 0.1 * np.sqrt(2 / np.pi)) < 0.005)
    True
    """
    ntag = phase.shape[1]
    out = np.full(ntag, np.nan)
    for t in range(ntag):  # loop over the ≤ 3 tags
        ok = valid[:, t]
        if not ok.any():
            continue
        X = points[ok]
        w = volume[ok]
        centre = (w[:, None] * X).sum(axis=0) / w.sum()
        A = X - centre
        k = np.asarray(wavevectors[t], dtype=np.float64).copy()
        c = 0.0
        for _ in range(refinements + 1):
            rho = wrap(phase[ok, t] - A @ k - c)
            c += float(np.angle(np.sum(w * np.exp(1j * rho))))
            rho = wrap(phase[ok, t] - A @ k - c)
            near = np.abs(rho) < 1.0  # robust to the odd wrapped outlier
            if near.sum() < 4:
                break
            sw = np.sqrt(w[near])
            dk, *_ = np.linalg.lstsq(A[near] * sw[:, None], rho[near] * sw, rcond=None)
            k = k + dk
        rho = wrap(phase[ok, t] - A @ k - c)
        out[t] = float((w * np.abs(rho)).sum() / w.sum())
    return out


def epsilon_floor(
    reference: FloatArray,
    reference_magnitude: FloatArray,
    magnitude: FloatArray,
    share: FloatArray,
) -> float:
    """Noise floor of ε in one frame (module notes), rad.

    Parameters
    ----------
    reference : ndarray, shape (ntag,)
        Reference-frame residual per tag (:func:`reference_residual`), rad.
    reference_magnitude, magnitude : ndarray, shape (ntag,)
        Mean harmonic magnitude at the tissue in the reference and in this frame (any
        common unit).
    share : ndarray, shape (ntag,)
        Share of the constraint volume that each tag has data in (weights, summing to 1).

    Returns
    -------
    float
        ``reference`` grown by each tag's fading ``reference_magnitude / magnitude`` (held
        in [1, :data:`MAX_FADING`]), averaged with the weights ``share`` over the tags with
        a finite reference residual and a positive share, rad; NaN if there is no such tag.

    Examples
    --------
    >>> round(epsilon_floor(np.array([0.1]), np.array([2.0]), np.array([1.0]), np.ones(1)), 4)
    0.2
    """
    ok = np.isfinite(reference) & (share > 0)
    if not ok.any():
        return float("nan")
    ratio = np.where(magnitude > 0, reference_magnitude / np.where(magnitude > 0, magnitude, 1), 1)
    per_tag = reference * np.clip(ratio, 1.0, MAX_FADING)
    return float((share[ok] * per_tag[ok]).sum() / share[ok].sum())


def noise_floor(
    sigma: FloatArray,
    reference_magnitude: FloatArray,
    magnitude: FloatArray,
    weight: FloatArray,
    valid: np.ndarray,
) -> float:
    """Mean phase-noise modulus of the residual between two frames (module notes), rad.

    Parameters
    ----------
    sigma : ndarray, shape (ntag,)
        Noise standard deviation σ_H of each tag's complex harmonic image (magnitude units).
    reference_magnitude, magnitude : ndarray, shape (n, ntag)
        Harmonic magnitude :math:`|H|` at the points in the reference and in the current frame.
    weight : ndarray, shape (n,)
        Weights of the points (quadrature volumes), mm³.
    valid : ndarray of bool, shape (n, ntag)
        Which (point, tag) pairs the residual ε averages over.

    Returns
    -------
    float
        Expected ε of pure noise, weighted as ε is (NaN without a valid pair).

    Examples
    --------
    >>> m = np.full((10, 1), 2.0)
    >>> eps = noise_floor(np.array([0.1]), m, m, np.ones(10), np.ones((10, 1), bool))
    >>> bool(abs(eps - np.sqrt(2 / np.pi) * 0.05) < 1e-12)
    True
    """
    sigma = np.asarray(sigma, dtype=np.float64)
    # σ/|H| beyond 1e3 saturates at π/2 anyway: the floor on |H| only avoids overflow
    tiny = 1e-3 * sigma + 1e-300
    inv0 = sigma / np.maximum(np.asarray(reference_magnitude, dtype=np.float64), tiny)
    inv = sigma / np.maximum(np.asarray(magnitude, dtype=np.float64), tiny)
    # only the noise component across H turns its phase: half the complex variance
    spread = np.sqrt(0.5 * (inv0**2 + inv**2))
    mean_abs = np.minimum(np.sqrt(2.0 / np.pi) * spread, 0.5 * np.pi)
    w = np.asarray(weight, dtype=np.float64)[:, None] * valid
    total = w.sum()
    if total <= 0:
        return float("nan")
    return float((w * np.where(valid, mean_abs, 0.0)).sum() / total)
