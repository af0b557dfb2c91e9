r"""The tag frequency the images show, against the one the dataset states.

The band-pass of :func:`harpx.imaging.harp.extract_phase` is a disk centred on the stated
tag frequency vector :math:`f\,d` (``tag_frequency`` × ``tag_direction``). A wrong
``tag_frequency`` (a tag period typed by hand for a scanner's files, which do not record
it) moves the disk off the tag peak, so the phase is filtered differently from what the
tracker's blur correction models. Tracking still meets its residual, so the result looks
plausible; benchmarks/tag_period_error.py measures what it costs.

:func:`measure_tag_frequency` finds the tag peak in the images themselves, independently
of any filter: per tag, the first frame's slices in the tag's acquisition plane (those
inside its ``mask``), each less its mean and under a separable Hann window, are Fourier
transformed on a grid padded to :data:`PAD` times the field of view; the power spectra are
summed over the slices, and the largest peak within :data:`SEARCH` × :math:`f` of the stated
in-plane vector is located to a fraction of a bin by a parabola through the log-power of
its neighbours along each axis. The window keeps a field of view that holds a non-integer
number of tag periods (tissue up to its edges) from smearing the peak; the phase itself is
bent there, so its steps would not do. The frequency is the peak's distance from the
origin: the tag frequency in the tag's plane (paper eq. 1, the undeformed pattern
:math:`\cos(2\pi f\,d\cdot X)` of the first frame).

The tissue must span enough tag periods for the peak to be placed within
:data:`FREQUENCY_TOLERANCE` (benchmarks/tag_frequency_span.py measures it on discs of
tissue): along an in-plane axis ``a`` the peak is placed to about :math:`1/L_a` (``L_a``
the tissue's span along it), which moves the frequency :math:`|k|` by the share
:math:`|k_a|/|k|` of that, so the tag is measured only where
:math:`L_a |k|^2 / |k_a| \ge` :data:`MIN_PERIODS` along both axes: :data:`MIN_PERIODS` tag
periods across the tissue for a tag along a grid axis, fewer along an axis the wave only
grazes (an oblique tag). Elsewhere it is not measured (NaN). The tissue's span is where the
slices' summed signal power, averaged over one tag period, exceeds :data:`SUPPORT_LEVEL` of
its largest value; it is at most the field of view. If the largest value in the search disk
lies on its rim (no tag pattern near the stated vector), the largest peak at least
(1 − :data:`SEARCH`) × :math:`f` from the origin is taken instead: the tags are elsewhere,
which the comparison then reports (NaN if even that lies on the edge of the DC).

The peak's direction is compared too (:func:`direction_error`): a ``tag_direction`` that
misses the tags' direction in their plane (a wrong in-plane rotation of the scanner's row
and column axes) moves the disk off the peak sideways, and tracking meets its residual all
the same. Tissue spanning :data:`MIN_PERIODS` periods places the peak's angle to tenths of
a degree, so :data:`DIRECTION_TOLERANCE` (5 degrees) stands well clear of what the
measurement scatters; at it the disk centre sits :math:`2 \sin(2.5°) = 8.7\,\%` of
:math:`f` off the peak, sideways. The tags whose frequency could not be measured
(:func:`tags_unmeasured`) are the ones nothing checks: the trackers record them.
"""

from __future__ import annotations

import warnings

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx._typing import FloatArray
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.imaging.fft import fft2
from harpx.schema import AXES, GRID_DIMS, grid_step

__all__ = [
    "DIRECTION_TOLERANCE",
    "FREQUENCY_TOLERANCE",
    "MIN_PERIODS",
    "PAD",
    "SEARCH",
    "SUPPORT_LEVEL",
    "direction_error",
    "measure_tag_frequency",
    "measure_tag_peak",
    "tag_frequency_flag",
    "tag_frequency_mismatch",
    "tags_off_direction",
    "tags_off_frequency",
    "tags_unmeasured",
]

#: Relative difference between the measured and the stated tag frequency above which
#: :func:`tag_frequency_mismatch` reports it
FREQUENCY_TOLERANCE = 0.02
#: Angle (degrees) between the measured tag peak and the stated ``tag_direction`` in the
#: tag's plane above which :func:`tag_frequency_mismatch` reports it (module notes)
DIRECTION_TOLERANCE = 5.0
#: Tag periods the tissue must span along a grid axis of the tag's plane for the frequency
#: to be measured, scaled by the wave's share of that axis (module notes)
MIN_PERIODS = 4.0
#: Fraction of the largest period-averaged signal power that marks tissue along an axis
SUPPORT_LEVEL = 0.1
#: Zero padding of each slice before its Fourier transform (finer spectral sampling)
PAD = 2
#: Radius of the disk around the stated frequency vector searched for the tag peak, as a
#: fraction of the stated frequency (it excludes the origin and a grid's other tag)
SEARCH = 0.6


def _in_plane_frequency(phase: xr.Dataset, tag: int) -> float:
    """The stated frequency projected on the tag's acquisition plane (cycles/mm)."""
    direction = np.asarray(phase["tag_direction"].isel(tag=tag).values, dtype=np.float64)
    slice_axis = AXES.index(str(np.asarray(phase["slice_axis"].values).ravel()[tag]))
    frequency = float(np.asarray(phase["tag_frequency"].values).ravel()[tag])
    return frequency * float(np.linalg.norm(np.delete(direction, slice_axis)))


def _plane(tagged: xr.Dataset, tag: int, time_index: int) -> tuple[np.ndarray, list[str]]:
    """One frame's slices of one tag inside its mask, (slice, a, b), and the axes a, b."""
    slice_axis = str(np.asarray(tagged["slice_axis"].values).ravel()[tag])
    plane = [d for d in GRID_DIMS if d != slice_axis]
    image = tagged["image"].isel(tag=tag, time=time_index).transpose(slice_axis, *plane)
    values = np.asarray(image.values, dtype=np.float64)
    if "mask" in tagged.variables:
        mask = tagged["mask"].isel(tag=tag).transpose(slice_axis, *plane).values
        values = values[np.asarray(mask, bool).any(axis=(1, 2))]
    return values[np.isfinite(values).all(axis=(1, 2))], plane


def _parabola(log_power: np.ndarray) -> float:
    """Sub-bin offset of the middle of three log-power values from their parabola's vertex."""
    left, mid, right = log_power
    curvature = left - 2.0 * mid + right
    return 0.0 if curvature >= 0 else float(0.5 * (left - right) / curvature)


def _tissue_span(values: np.ndarray, axis: int, step: float, frequency: float) -> float:
    """Extent (mm) along in-plane ``axis`` (1 or 2) of where the slices ``values`` have
    signal: their power summed over the slices and the other axis, averaged over one tag
    period, above :data:`SUPPORT_LEVEL` of its largest value."""
    power = (values**2).sum(axis=(0, 3 - axis))
    width = max(1, int(round(1.0 / (frequency * step))))
    smooth = np.convolve(power, np.ones(width) / width, mode="same")
    if not smooth.max() > 0.0:
        return 0.0
    above = np.flatnonzero(smooth > SUPPORT_LEVEL * smooth.max())
    return float(above[-1] - above[0] + 1) * step


def _spans_enough(values: np.ndarray, steps: list[float | None], stated: FloatArray) -> bool:
    """Whether the tissue spans enough tag periods to place the peak of ``stated``.

    Along in-plane axis ``a`` the peak is placed to about ``1 / span_a``; that moves the
    frequency :math:`|k|` by the share :math:`|k_a| / |k|` of it. The relative error is then
    :math:`|k_a| / (span_a |k|^2)`, which must stay below ``1 / MIN_PERIODS``: a tag along
    the axis needs ``MIN_PERIODS`` periods across the tissue, an oblique one the periods
    along its wave, scaled by its direction's share of the axis.
    """
    norm = float(np.hypot(*stated))
    for axis, step, component in zip((1, 2), steps, stated, strict=True):
        if component == 0.0:
            continue
        if step is None:
            return False
        span = _tissue_span(values, axis, abs(step), norm)
        if span * norm * norm < MIN_PERIODS * abs(component):
            return False
    return True


def _peak(
    power: np.ndarray, axes: list[np.ndarray], spacing: list[float], inside: np.ndarray
) -> FloatArray | None:
    """Sub-bin position (cycles/mm, 2) of the largest ``power`` inside the region ``inside``;
    None if it lies on the region's rim (no peak inside)."""
    shape = power.shape
    a, b = np.unravel_index(np.argmax(np.where(inside, power, -np.inf)), shape)
    rows = [(a - 1) % shape[0], a, (a + 1) % shape[0]]
    cols = [(b - 1) % shape[1], b, (b + 1) % shape[1]]
    if not (inside[rows, b].all() and inside[a, cols].all()):
        return None
    log_power = np.log(np.maximum(power, np.finfo(float).tiny))
    return np.array(
        [
            axes[0][a] + _parabola(log_power[rows, b]) / (shape[0] * spacing[0]),
            axes[1][b] + _parabola(log_power[a, cols]) / (shape[1] * spacing[1]),
        ]
    )


def _measure_one(tagged: xr.Dataset, tag: int, time_index: int) -> FloatArray:
    """Frequency vector (x, y, z) of one tag's spectral peak in its plane (cycles/mm; 0
    along the slice axis, NaN where it cannot be measured)."""
    found = np.full(3, np.nan)
    values, plane = _plane(tagged, tag, time_index)
    if values.shape[0] == 0:
        return found
    direction = np.asarray(tagged["tag_direction"].isel(tag=tag).values, dtype=np.float64)
    frequency = float(np.asarray(tagged["tag_frequency"].values).ravel()[tag])
    steps = [grid_step(tagged, d) for d in plane]
    stated = np.array([frequency * direction[AXES.index(d)] for d in plane])
    if not _spans_enough(values, steps, stated):
        return found  # the wave spans too few periods of tissue to resolve its peak
    values = values - values.mean(axis=(1, 2), keepdims=True)
    values *= np.hanning(values.shape[1])[:, None] * np.hanning(values.shape[2])[None, :]
    shape = [PAD * n for n in values.shape[1:]]
    padded = np.zeros((values.shape[0], *shape))
    padded[:, : values.shape[1], : values.shape[2]] = values
    power = (np.abs(fft2(padded)) ** 2).sum(axis=0)
    spacing = [abs(step) if step else 1.0 for step in steps]
    axes = [np.fft.fftfreq(m, d) for m, d in zip(shape, spacing, strict=True)]
    ka, kb = np.meshgrid(*axes, indexing="ij")
    norm = float(np.hypot(*stated))
    peak = _peak(power, axes, spacing, np.hypot(ka - stated[0], kb - stated[1]) <= SEARCH * norm)
    if peak is None:  # nothing near the stated vector: the largest peak above the DC
        peak = _peak(power, axes, spacing, np.hypot(ka, kb) >= (1.0 - SEARCH) * norm)
        if peak is None:
            return found  # no peak above the DC at all: no tag pattern
        peak *= 1.0 if peak @ stated >= 0 else -1.0  # the peak at -k is the same pattern
    for d, value in zip(plane, peak, strict=True):
        found[AXES.index(d)] = value
    found[AXES.index(str(np.asarray(tagged["slice_axis"].values).ravel()[tag]))] = 0.0
    return found


def measure_tag_peak(tagged: xr.Dataset, time_index: int = 0) -> FloatArray:
    """Frequency vector of each tag's spectral peak in its acquisition plane, in one frame.

    Parameters
    ----------
    tagged : xarray.Dataset
        ``tagged/1`` dataset (``image``, ``mask`` if any, and the tag coordinates).
    time_index : int, default 0
        The frame to read; the first (the tagging's reference) shows the undeformed pattern.

    Returns
    -------
    numpy.ndarray, shape (tag, 3)
        Columns (x, y, z), cycles/mm, 0 along each tag's ``slice_axis``, on the side of the
        stated frequency vector (the peaks at ±k are one pattern). Its norm is
        :func:`measure_tag_frequency`. The peak is the largest within :data:`SEARCH` × the
        stated in-plane frequency of the stated vector; if that lies on the searched disk's
        rim (nothing there), the largest peak at least (1 − :data:`SEARCH`) × the stated
        frequency from the origin (the tags are elsewhere). NaN rows where it cannot be
        measured: no slice inside the mask, tissue spanning too few tag periods (module
        notes), or no peak away from the origin.
    """
    return np.array(
        [_measure_one(tagged, t, time_index) for t in range(tagged.sizes["tag"])], dtype=float
    ).reshape(-1, 3)


def measure_tag_frequency(tagged: xr.Dataset, time_index: int = 0) -> FloatArray:
    """Tag frequency of each tag as its images show it in one frame.

    Parameters
    ----------
    tagged : xarray.Dataset
        As for :func:`measure_tag_peak`.
    time_index : int, default 0
        As for :func:`measure_tag_peak`.

    Returns
    -------
    numpy.ndarray, shape (tag,)
        In cycles/mm, in each tag's acquisition plane (compare with the stated frequency
        projected on the plane, as :func:`tags_off_frequency` does). NaN where it cannot be
        measured: no slice inside the mask, tissue spanning fewer than :data:`MIN_PERIODS`
        tag periods along an axis the wave runs along, or no peak inside the searched disk.

    Examples
    --------
    >>> from harpx.imaging.synth import synthesize_tagged
    >>> tagged = synthesize_tagged(
    ...     lambda X, t: 0 * X, shape=(2, 32, 32), spacing=(2.0, 1.5, 1.5), times=[0.0],
    ...     tags=("x",), tag_period=6.0, snr=None, oversample=1)
    >>> bool(abs(measure_tag_frequency(tagged)[0] * 6.0 - 1) < 0.01)
    True
    """
    return np.asarray(np.linalg.norm(measure_tag_peak(tagged, time_index), axis=1), float)


def _off_frequency(phase: xr.Dataset, measured: ArrayLike | None) -> list[tuple[str, float, float]]:
    """(tag, measured, stated in-plane frequency) of each tag off by more than the tolerance."""
    if measured is None:
        if "tag_frequency_measured" not in phase.variables:
            return []
        measured = phase["tag_frequency_measured"].values
    seen = np.asarray(measured, dtype=np.float64).ravel()
    labels = [str(v) for v in np.asarray(phase["tag"].values).ravel()]
    off = []
    for t, tag in enumerate(labels):
        stated = _in_plane_frequency(phase, t)
        if np.isfinite(seen[t]) and stated > 0 and abs(seen[t] / stated - 1) > FREQUENCY_TOLERANCE:
            off.append((tag, float(seen[t]), stated))
    return off


def direction_error(phase: xr.Dataset, peak: ArrayLike | None = None) -> FloatArray:
    """Angle between each tag's measured peak and its stated direction, in its plane.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` (or ``tagged/1``) dataset with the tag coordinates.
    peak : array_like, shape (tag, 3), optional
        :func:`measure_tag_peak` of it, cycles/mm; default its ``tag_peak_measured`` (none
        there: NaN throughout).

    Returns
    -------
    numpy.ndarray, shape (tag,)
        Degrees in [0, 90] between the measured frequency vector and the stated
        ``tag_direction`` projected on the tag's acquisition plane (the tag lines' tilt);
        NaN where the peak was not measured or the stated direction is normal to the plane.
    """
    if peak is None:
        if "tag_peak_measured" not in phase.variables:
            return np.full(phase.sizes["tag"], np.nan)
        peak = phase["tag_peak_measured"].transpose("tag", "axis").values
    seen = np.asarray(peak, dtype=np.float64).reshape(-1, 3)
    stated = np.asarray(phase["tag_direction"].transpose("tag", "axis").values, np.float64)
    axes = [AXES.index(str(a)) for a in np.asarray(phase["slice_axis"].values).ravel()]
    stated = stated.copy()
    stated[np.arange(len(axes)), axes] = 0.0  # projected on each tag's plane
    norms = np.linalg.norm(seen, axis=1) * np.linalg.norm(stated, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cosine = np.abs(np.einsum("ti,ti->t", seen, stated)) / norms
    cosine = np.where(norms > 0, np.minimum(cosine, 1.0), np.nan)
    return np.asarray(np.degrees(np.arccos(cosine)), dtype=np.float64)


def _off_direction(phase: xr.Dataset, peak: ArrayLike | None) -> list[tuple[str, float]]:
    """(tag, angle in degrees) of each tag whose peak is off its stated direction."""
    angle = direction_error(phase, peak)
    labels = [str(v) for v in np.asarray(phase["tag"].values).ravel()]
    return [
        (tag, float(a))
        for tag, a in zip(labels, angle, strict=True)
        if np.isfinite(a) and a > DIRECTION_TOLERANCE
    ]


def tags_off_frequency(phase: xr.Dataset, measured: ArrayLike | None = None) -> list[str]:
    """The tags whose measured frequency misses the stated one.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` (or ``tagged/1``) dataset with the stated ``tag_frequency`` (tag),
        cycles/mm, and the tag coordinates.
    measured : array_like, shape (tag,), optional
        :func:`measure_tag_frequency` of it; default its ``tag_frequency_measured`` (none
        there: no tag is reported). NaN entries are skipped.

    Returns
    -------
    list of str
        Labels of the tags whose measured frequency differs from the stated one projected
        on their acquisition plane by more than :data:`FREQUENCY_TOLERANCE` (relative).
    """
    return [tag for tag, _, _ in _off_frequency(phase, measured)]


def tags_off_direction(phase: xr.Dataset, peak: ArrayLike | None = None) -> list[str]:
    """The tags whose measured peak lies off their stated direction.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` (or ``tagged/1``) dataset with the tag coordinates.
    peak : array_like, shape (tag, 3), optional
        As in :func:`direction_error`.

    Returns
    -------
    list of str
        Labels of the tags whose :func:`direction_error` exceeds
        :data:`DIRECTION_TOLERANCE`.
    """
    return [tag for tag, _ in _off_direction(phase, peak)]


def tags_unmeasured(phase: xr.Dataset) -> list[str]:
    """The tags whose frequency was not measured (``tag_frequency_measured`` NaN).

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` dataset (its ``tag_frequency_measured`` is read; computed, if lazy).

    Returns
    -------
    list of str
        Labels of the tags whose stated frequency and direction nothing checked: too little
        tissue along their wave, no slice in their mask, or no tag peak in the images. All
        tags when the dataset has no ``tag_frequency_measured``.
    """
    labels = [str(v) for v in np.asarray(phase["tag"].values).ravel()]
    if "tag_frequency_measured" not in phase.variables:
        return labels
    seen = np.asarray(phase["tag_frequency_measured"].values, dtype=np.float64).ravel()
    return [tag for tag, value in zip(labels, seen, strict=True) if not np.isfinite(value)]


def tag_frequency_mismatch(
    phase: xr.Dataset, measured: ArrayLike | None = None, peak: ArrayLike | None = None
) -> str:
    """The warning for the tags of :func:`tags_off_frequency` and :func:`tags_off_direction`.

    Parameters
    ----------
    phase : xarray.Dataset
        A ``phase/1`` dataset, as :func:`tags_off_frequency` takes it.
    measured : array_like, optional
        As in :func:`tags_off_frequency`.
    peak : array_like, shape (tag, 3), optional
        As in :func:`direction_error`.

    Returns
    -------
    str
        Per tag off its stated frequency, the frequency and period the images show and the
        stated ones; per tag off its stated direction, the angle; and what to check (the tag
        period and directions given for scanner files); "" when every tag is where it is
        stated to be.
    """
    off = _off_frequency(phase, measured)
    turned = _off_direction(phase, peak)
    if not off and not turned:
        return ""
    found = [
        f"tag {tag!r} shows its tags at {seen:.4g} cycles/mm (a {1 / seen:.3g} mm period) in "
        f"the first frame, but its tag_frequency says {stated:.4g} cycles/mm "
        f"({1 / stated:.3g} mm)"
        for tag, seen, stated in off
    ]
    found += [
        f"tag {tag!r} shows its tag peak {angle:.3g} degrees off its tag_direction in the "
        f"plane of its slices (more than {DIRECTION_TOLERANCE:g})"
        for tag, angle in turned
    ]
    return (
        f"{'; '.join(found)}. The band-pass is centred on the stated frequency vector, off the "
        "images' tag peak, and the blur correction of tracking models that filter too. Check "
        "the tag period (read_tagged(..., tag_period=...), the dataset's tag_frequency) and "
        "the tag directions (tag_direction) and extract the phase again"
    )


def tag_frequency_flag(phase: xr.Dataset, tracker: str) -> str:
    """Warn that ``tracker`` tracks from phase whose tags miss their frequency; the flag.

    Parameters
    ----------
    phase : xarray.Dataset
        The ``phase/1`` dataset about to be tracked (its ``tag_frequency_measured`` and
        ``tag_peak_measured`` are read; computed, if dask-backed).
    tracker : str
        Who tracks, for the message (e.g. ``"FE tracking"``).

    Returns
    -------
    str
        The value of the tracked result's ``attrs["tags_off_frequency"]``: the labels of
        :func:`tags_off_frequency` and :func:`tags_off_direction` (their frequency vector
        misses the stated one) separated by spaces, or ``"none"``.

    Warns
    -----
    HarpxWarning
        If some tag is off (names them).
    """
    off_frequency, off_direction = tags_off_frequency(phase), tags_off_direction(phase)
    labels = [str(v) for v in np.asarray(phase["tag"].values).ravel()]
    off = [tag for tag in labels if tag in off_frequency or tag in off_direction]
    if off:
        turned = f" (direction off by more than {DIRECTION_TOLERANCE:g} degrees: {off_direction})"
        warnings.warn(
            f"{tracker} from harmonic phase whose tag(s) {off} have images whose tags miss "
            "their tag_frequency (tag_frequency_measured) or tag_direction (tag_peak_measured)"
            f"{turned if off_direction else ''}: the band-pass was centred off the tag peak, so "
            "the motion tracked from it is biased (attrs['tags_off_frequency'])",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return " ".join(off) or "none"
