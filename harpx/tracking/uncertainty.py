r"""How much the image noise moves a tracked motion: a linearised, sampled uncertainty.

A post-processing step after :func:`harpx.tracking.track.track`: it rebuilds the tracker's
final Gauss–Newton system of every frame and pushes sampled image noise through it. The
work is split by job:

* :mod:`harpx.tracking.uncertainty_noise`: the image noise behind the phase (white within
  a slice, measured or assumed covariance across the planes), :func:`image_noise`;
* :mod:`harpx.tracking.uncertainty_phase`: sampled noise through the phase extraction to
  the phase change at the tracker's points;
* :mod:`harpx.tracking.uncertainty_linear`: the linearisation (the rebuilt, factorised
  system of each frame and the response of the motion, blur correction included);
* this module: :func:`tracking_uncertainty`, its checks and its result.

The standard deviation is the root mean square over the :math:`M` samples (the linear
response has zero mean); its relative sampling error is about :math:`1/\sqrt{2M}`.

Not included
------------
Model and regularisation bias (what the mechanics adds where the data are silent, and its
misfit of the true motion); the band-pass blur correction's own model error; the
tracker's per-frame choice of the penalty, which adapts to the data and can differ between
acquisitions by a level (``penalty_sensitivity`` says how far a level lower moves the
motion, and a warning names the frames where that exceeds half the noise); the phase
Hessian dropped by the Gauss–Newton tangent; effects beyond first order (a noise excursion
that carries a point into a neighbouring tag's basin); the noise estimate's own sampling
error; noise that is not white within a slice or is correlated between frames or tags.
The result's attributes repeat this list. How well the standard deviations cover the
spread over repeated acquisitions is measured in
``benchmarks/results/uncertainty_coverage.md``.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import FloatArray
from harpx.errors import HarpxError, HarpxWarning, user_stacklevel
from harpx.imaging.harp import extract_phase
from harpx.mechanics.linsolve import LinearSolver
from harpx.schema import validate
from harpx.tracking.equilibrium import equilibrate
from harpx.tracking.uncertainty_linear import (
    Problem,
    mechanical_tangent,
    rebuild,
    sample_response,
    setting,
)
from harpx.tracking.uncertainty_noise import BACKGROUND, SIGNIFICANCE, ImageNoise, image_noise
from harpx.tracking.uncertainty_phase import NoiseSampleWarning

__all__ = [
    "BACKGROUND",
    "DEFAULT_SAMPLES",
    "EXCLUDED",
    "PENALTY_SENSITIVITY",
    "SIGNIFICANCE",
    "ImageNoise",
    "image_noise",
    "tracking_uncertainty",
]

#: Noise samples drawn by default (relative sampling error of a standard deviation ≈ 9 %).
DEFAULT_SAMPLES = 64
#: What the uncertainty leaves out (module notes), as written into the result's attributes.
EXCLUDED = (
    "model and regularisation bias; the band-pass blur correction's model error; the "
    "tracker's per-frame choice of the penalty; the phase Hessian; effects beyond first "
    "order (tag jumps); the noise estimate's own error; noise not white in-plane or "
    "correlated between frames or tags"
)
#: Motion change at half the penalty, in standard deviations (RMS over the dofs), above
#: which the tracker's penalty choice is flagged as a spread the standard deviations leave
#: out. Below 1, as a level's change is smooth and regional averages feel it more than the
#: nodal noise (why this value: ``benchmarks/results/uncertainty_coverage.md``).
PENALTY_SENSITIVITY = 0.5
#: RMS phase noise of the residual (rad) above which the first-order model is doubtful.
_LINEAR_PHASE_LIMIT = 0.3
#: Image noise level, relative to the largest frame-0 harmonic magnitude of its tag, at or
#: below which a tag's images count as noise-free (an SNR above about a million).
_NOISE_FREE = 1e-6


def tracking_uncertainty(
    tracked: xr.Dataset,
    body: Any,
    images: xr.Dataset,
    *,
    tagged: xr.Dataset | None = None,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    samples: int = DEFAULT_SAMPLES,
    seed: int | None = None,
    keep_samples: bool = False,
) -> xr.Dataset:
    r"""Standard deviation of a tracked displacement due to the image noise (module notes).

    Parameters
    ----------
    tracked : xarray.Dataset
        ``tracked/1`` result of :func:`~harpx.tracking.track.track` (penalty method).
    body : Body
        The body that was tracked (reference configuration, mm).
    images : xarray.Dataset
        What was tracked: the ``phase/1`` dataset, or ``tagged/1`` images (their phase is
        then extracted with the defaults, as ``track`` does, and they also serve as
        ``tagged``).
    tagged : xarray.Dataset, optional
        The ``tagged/1`` images the phase came from: they give the noise covariance across
        the slices (:func:`image_noise`). Without them the planes of the grid are taken as
        independent, which understates the noise of slices thicker than the grid spacing
        (warned).
    dirichlet, terms : sequence, optional
        The Dirichlet conditions and residual terms given to ``track``.
    samples : int, default 64
        Noise samples M (≥ 2); the relative sampling error of each standard deviation is
        about :math:`1/\sqrt{2M}`.
    seed : int, optional
        Seed of the noise samples.
    keep_samples : bool, default False
        Also return the sampled displacement changes (``dof_displacement_samples``).

    Returns
    -------
    xarray.Dataset
        ``displacement_std`` (time, node, axis), mm: standard deviation of each node's
        displacement; ``noise_residual`` (time), rad: mean :math:`|\delta r|` of the sampled
        noise over the valid points and tags, weighted as ε (compare ``epsilon_floor``);
        ``equilibrium_step`` (time), mm: largest change a further Newton step would make at
        the rebuilt state (about the tracking tolerance when body, conditions and images
        are the tracked ones; with the blur correction also the change from recomputing it
        from the final motion, since the previous pass's motion is not stored);
        ``penalty_sensitivity`` (time): root-mean-square change of the motion had the frame
        stopped at half its final penalty, over its root-mean-square standard deviation
        (the tracker's discrete, data-dependent penalty choice, not in the σ); with
        ``keep_samples`` ``dof_displacement_samples`` (sample, time, dof), mm.
        Attributes: ``samples``, ``seed``, ``relative_sampling_error``, ``noise_model``
        per tag, ``excludes`` (what is left out) and ``flags`` (the warnings raised, "" if
        none).

    Raises
    ------
    ValueError
        If ``tracked`` is not a penalty-method result of this body, ``samples`` < 2, the
        Dirichlet conditions differ from the tracked ones (the held dofs moved, or another
        number of rigid modes is unseen), there is no noise level (no
        ``harmonic_noise`` and no ``tagged``), or the images are noise-free (every tag's
        noise level at most 1e-6 of its largest harmonic magnitude: nothing to propagate).

    Warns
    -----
    HarpxWarning
        When the noise across slices is assumed rather than measured, some tags carry no
        noise while others do, a frame missed its target or did not converge, the rebuilt
        state is not in equilibrium, the noise is too large for a first-order model, half
        the penalty moves a frame's motion by more than its standard deviation, or the
        phase extraction warned about the internal noise samples (once, gathered; each
        also listed in ``flags``).

    Notes
    -----
    Cost per frame: one factorisation, the image noise of M frames through the phase
    extraction, M phase samplings of the constraint points and M back-substitutions; with
    the blur correction also M corrections of the whole motion (usually the largest part).

    Examples
    --------
    The rigid translation of :func:`~harpx.tracking.track.track`'s example, imaged at an
    SNR of 20 (seeded noise) and tracked; 4 noise samples (a quick look, the default is 64)
    give the standard deviation of each node's displacement:

    >>> from harpx.imaging.harp import extract_phase
    >>> from harpx.imaging.synth import synthesize_tagged
    >>> from harpx.mechanics.body import Body
    >>> from harpx.mechanics.materials import NeoHookean
    >>> from harpx.mechanics.mesh import box
    >>> from harpx.tracking.track import track
    >>> shift = np.array([0.8, -0.5, 0.3])  # mm at t = 20 ms
    >>> tagged = synthesize_tagged(
    ...     lambda X, t: np.broadcast_to(shift * t / 20.0, X.shape), shape=(12, 24, 24),
    ...     spacing=(1.5, 1.5, 1.5), times=[0.0, 20.0], tags=("x", "y", "z"), snr=20.0,
    ...     oversample=1, rng=0)
    >>> body = Body(box((12.0, 12.0, 6.0), (4, 4, 2), origin=(-6.0, -6.0, -3.0)),
    ...             NeoHookean(c1=1.0, kappa=100.0))
    >>> phase = extract_phase(tagged)
    >>> result = track(phase, body)
    >>> sd = tracking_uncertainty(result, body, phase, tagged=tagged, samples=4, seed=0)
    >>> dict(sd.displacement_std.sizes)
    {'time': 2, 'node': 75, 'axis': 3}
    >>> float(sd.displacement_std.isel(time=0).max())  # the reference frame has no noise
    0.0
    >>> bool(0.002 < float(sd.displacement_std.isel(time=-1).mean()) < 0.05)  # mm
    True
    """
    if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or samples < 2:
        raise ValueError(f"samples={samples!r} must be a whole number ≥ 2")
    if images.attrs.get("harpx_schema") == "tagged/1":
        tagged = images if tagged is None else tagged
        images = extract_phase(images)
    validate(images, "phase")
    flags: list[str] = []

    def flag(message: str) -> None:
        flags.append(message)
        warnings.warn(message, HarpxWarning, stacklevel=user_stacklevel())

    problem = rebuild(tracked, body, images, dirichlet, terms)
    noise = image_noise(images, tagged)
    _check_noise_level(noise, images, tagged is not None, flag)
    if not noise.estimated.all():
        unmeasured = [str(t) for t, e in zip(images["tag"].values, noise.estimated, strict=True)
                      if not e]  # fmt: skip
        flag(
            f"the image noise of tag(s) {unmeasured} is taken as independent between the "
            "grid's planes along the slice axis (no tagged images, or tags oblique to every "
            "grid axis): slices thicker than the grid spacing make it correlated and the "
            "standard deviations too small; pass tagged="
        )
    _warn_frames(tracked, flag)
    # the noise samples pass through the phase extraction as frames of their own: what it
    # says about them is gathered into one flag; anything else reaches the caller as raised
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dU, noise_residual, step = sample_response(problem, noise, int(samples), seed)
    internal = [w for w in caught if issubclass(w.category, NoiseSampleWarning)]
    for w in caught:
        if not issubclass(w.category, NoiseSampleWarning):
            warnings.warn(w.message, w.category, stacklevel=user_stacklevel())
    if internal:
        said = dict.fromkeys(str(w.message) for w in internal)  # distinct, in order
        flag(
            f"{' / '.join(said)} (in {len(internal)} of the noise sample batches): the "
            "standard deviations rest on these samples and may be wrong"
        )
    std = np.sqrt(np.mean(dU**2, axis=0))  # (time, dof): the linear response has zero mean
    _check_result(problem, std, step, noise_residual, flag)
    sensitivity = _penalty_sensitivity(problem, std)
    ramp, limit = setting(tracked, "ramp", 2), setting(tracked, "penalty_limit", np.inf)
    if not (int(ramp) == 1 and float(limit) < 2.0 * float(setting(tracked, "penalty", 1.0))):
        _check_penalty(sensitivity, flag)  # else the penalty was fixed: no choice to flag
    names = [str(t) for t in images["tag"].values]
    ntime = dU.shape[1]
    fields = [
        ("displacement_std", ("time", "node", "axis"), std.reshape(ntime, -1, 3), "mm",
         "displacement standard deviation due to image noise"),
        ("noise_residual", ("time",), noise_residual, "rad",
         "mean |phase residual| of the sampled image noise"),
        ("equilibrium_step", ("time",), step, "mm",
         "largest Newton step at the rebuilt tracked state"),
        ("penalty_sensitivity", ("time",), sensitivity, "1",
         "RMS displacement change at half the penalty / RMS sd"),
    ]  # fmt: skip
    if keep_samples:
        fields.append(("dof_displacement_samples", ("sample", "time", "dof"), dU, "mm",
                       "sampled displacement change due to image noise"))  # fmt: skip
    out = xr.Dataset(coords={"time": tracked["time"], "axis": tracked["axis"]})
    for name, dims, values, units, long_name in fields:
        out[name] = xr.DataArray(values, dims=dims, attrs={"units": units, "long_name": long_name})
    out.attrs.update(
        samples=int(samples),
        seed=-1 if seed is None else int(seed),
        relative_sampling_error=float(1.0 / np.sqrt(2.0 * samples)),
        noise_model=noise.describe(names),
        excludes=EXCLUDED,
        flags=" | ".join(flags),
    )
    return out


def _check_noise_level(noise: ImageNoise, images: xr.Dataset, measured: bool, flag: Any) -> None:
    """Refuse noise-free images (nothing to propagate); flag tags without noise among noisy
    ones (their phase is then taken as exact)."""
    names = [str(t) for t in images["tag"].values]
    level = np.array([float(std.max(initial=0.0)) for std in noise.plane_std()])
    magnitude = np.asarray(images["magnitude"].isel(time=0).transpose("tag", ...).values)
    peak = np.where(np.isfinite(magnitude), np.abs(magnitude), 0.0).reshape(len(names), -1)
    quiet = level <= _NOISE_FREE * peak.max(axis=1, initial=0.0)
    if not quiet.any():
        return
    source = f"harmonic_noise {_harmonic_noise_values(images)!r}" + (
        " and the tagged images measure none" if measured else ""
    )
    if quiet.all():
        raise ValueError(
            f"the images are noise-free: the image noise of every tag {names!r} is 0 "
            f"({source}; largest plane noise sd {level.max():.3g}), so there is no noise to "
            "propagate and every standard deviation would be 0, which is not the "
            "uncertainty of an acquisition; pass noisy images (e.g. synthesize_tagged(..., "
            "snr=20)), or assume a noise level: images.assign(harmonic_noise=...) on the "
            "phase, without tagged="
        )
    flag(
        f"tag(s) {[n for n, q in zip(names, quiet, strict=True) if q]!r} carry no image "
        f"noise ({source}) while the others do: their phase is taken as exact and the "
        "standard deviations leave out any noise of theirs; if their images are noisy, "
        "give them a harmonic_noise"
    )


def _harmonic_noise_values(images: xr.Dataset) -> list[float] | None:
    """The phase's ``harmonic_noise`` per tag as a list, or None without it."""
    if "harmonic_noise" not in images.variables:
        return None
    return [float(v) for v in np.asarray(images["harmonic_noise"].values).reshape(-1)]


def _penalty_sensitivity(problem: Problem, std: FloatArray) -> FloatArray:
    """Per frame, the root-mean-square displacement change between the equilibria at the
    final penalty and at half of it (both solved from the tracked state with the rebuilt
    images, so that the difference is the penalty's alone), in units of the
    root-mean-square standard deviation (NaN in frame 0 or where a solve fails)."""
    constraint, U = problem.constraint, problem.U
    solver = LinearSolver(problem.linear_solver)
    out = np.full(U.shape[0], np.nan)
    for n in range(1, U.shape[0]):
        constraint.set_frame(n)
        constraint.multipliers[:] = 0.0
        offset = None
        if problem.increment:
            offset = -mechanical_tangent(problem.body, U[n - 1], problem.terms)[1]
        states: list[FloatArray] = []
        try:
            for factor in (1.0, 0.5):
                constraint.penalty = factor * float(problem.penalty[n])
                states.append(equilibrate(
                    problem.body, constraint, states[-1] if states else U[n],
                    dirichlet=problem.dirichlet, terms=problem.terms, solver=solver,
                    tolerance=problem.tolerance, max_iterations=problem.max_iterations,
                    offset=offset,
                ).u)  # fmt: skip
        except HarpxError:  # an inverting step at the lower penalty: no estimate
            continue
        scale = float(np.sqrt(np.mean(std[n] ** 2)))
        if scale > 0:
            out[n] = float(np.sqrt(np.mean((states[1] - states[0]) ** 2))) / scale
    return out


def _check_penalty(sensitivity: FloatArray, flag: Any) -> None:
    """Flag frames whose motion moves by more than ``PENALTY_SENSITIVITY`` standard
    deviations between neighbouring penalty levels."""
    frames = [n for n in range(sensitivity.size) if sensitivity[n] > PENALTY_SENSITIVITY]
    if frames:
        flag(
            f"in frame(s) {frames} half the final penalty moves the motion by up to "
            f"{np.nanmax(sensitivity[frames]):.2g} times its standard deviation (RMS): the "
            "tracker picks the penalty per frame from the data, so another acquisition may "
            "stop at a neighbouring level, and that spread is not in the standard deviations "
            "(see 'penalty_sensitivity'; tracking at a fixed penalty, ramp=1 and "
            "penalty_limit= equal to penalty=, removes the choice)"
        )


def _warn_frames(tracked: xr.Dataset, flag: Any) -> None:
    """Flag frames whose state is not the tracker's converged equilibrium at its target."""
    bad = []
    for name in ("target_reached", "converged"):
        if name in tracked.variables:
            values = np.asarray(tracked[name].values, dtype=bool)
            bad += [n for n in range(1, values.size) if not values[n]]
    if bad:
        flag(
            f"frame(s) {sorted(set(bad))} missed the tracking target or did not converge: "
            "there the linearisation is about a state that is not the tracker's equilibrium"
        )


def _check_result(
    problem: Problem, std: FloatArray, step: FloatArray, noise_residual: FloatArray, flag: Any
) -> None:
    """Flag a rebuilt state out of equilibrium and noise too large for a first-order model."""
    largest = std.max(axis=1)
    period = 2.0 * np.pi / problem.constraint.max_wavenumber
    # recomputing the blur correction from the final motion (module notes) moves the
    # equilibrium by up to a few tenths of a mm on its own: a looser limit then
    recomputed = problem.correction is not None
    limit = max(10.0 * problem.tolerance, period / (8.0 if recomputed else 16.0))
    off = [n for n in range(1, step.size) if step[n] > limit]
    if off:
        flag(
            f"the rebuilt state of frame(s) {off} is not in equilibrium (a Newton step would "
            f"move it by up to {step[off].max():.3g} mm, more than {limit:.3g} mm): body, "
            "Dirichlet conditions, terms or images differ from those tracked"
        )
    rms = np.sqrt(np.pi / 2.0) * np.nan_to_num(noise_residual)  # mean |Gaussian| → its sd
    if rms.max(initial=0.0) > _LINEAR_PHASE_LIMIT or 2.0 * largest.max() > 0.25 * period:
        flag(
            f"the noise is large for a first-order model (phase residual sd up to "
            f"{rms.max():.2g} rad, displacement sd up to {largest.max():.2g} mm against a "
            f"{period:.3g} mm tag period): the standard deviations may be too small"
        )
