r"""The tag frequency the images show, against the one the dataset states.

The band-pass of :func:`harpx.imaging.harp.extract_phase` is a disk centred on the stated
tag frequency vector :math:`f\,d` (``tag_frequency`` × ``tag_direction``). A wrong
``tag_frequency`` (a tag period typed by hand for a scanner's files, which do not record
it) moves the disk off the tag peak, so the phase is filtered differently from what the
tracker's blur correction models. Tracking still meets its residual, so the result looks
plausible; benchmarks/tag_period_error.py measures what it costs.

The phase of an undeformed tag pattern advances by :math:`2\pi f\,d\cdot\Delta X` (paper
eq. 1), whatever filter extracted it. :func:`measure_tag_frequency` reads that rate off one
frame: per in-plane axis of the tag (the axes other than its ``slice_axis``), the median of
the wrapped phase step between neighbouring voxels where the harmonic magnitude is in its
upper quarter (the tissue), over the axis's step; the frequency is the norm of those
components over :math:`2\pi`. The wrapped step is the true step while :math:`2\pi f s < \pi`,
which holds on any grid that resolves the tags (the images' own sampling limit); the median
ignores the noise and the few steps across a tag jump or the tissue's edge.

The same check catches a band-pass that does not isolate the tag peak for another reason:
a ``radius`` that takes in the DC peak of SPAMM images, whose phase then follows the
tissue's edges rather than the tags.

Band-passed noise advances at the filter's centre, the stated frequency: the measurement
follows the images' tags where they stand above the noise, and images of noise alone read
as the stated frequency (this check does not tell them apart; ``extract_phase`` reports
blank frames itself).

Along an axis whose field of view holds fewer than :data:`MIN_PERIODS` tag periods, the
band-pass's periodic extension and the tissue's edges bend the phase, so a tag that varies
along such an axis is not measured (NaN).
"""

from __future__ import annotations

import warnings

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx._typing import FloatArray
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.imaging._kernels import wrap
from harpx.schema import AXES, GRID_DIMS, grid_step

__all__ = [
    "FREQUENCY_TOLERANCE",
    "MIN_PAIRS",
    "MIN_PERIODS",
    "measure_tag_frequency",
    "tag_frequency_flag",
    "tag_frequency_mismatch",
    "tags_off_frequency",
]

#: Relative difference between the measured and the stated tag frequency above which
#: :func:`tag_frequency_mismatch` reports it
FREQUENCY_TOLERANCE = 0.03
#: Tag periods the field of view must hold along an axis that carries the tag's wave
#: (direction component >= 0.1) for the frequency to be measured
MIN_PERIODS = 4.0
#: Pairs of neighbouring tissue voxels needed along each in-plane axis
MIN_PAIRS = 50
#: Percentile of the harmonic magnitude above which a voxel counts as tissue
TISSUE_PERCENTILE = 75.0


def _in_plane_frequency(phase: xr.Dataset, tag: int) -> float:
    """The stated frequency projected on the tag's acquisition plane (cycles/mm)."""
    direction = np.asarray(phase["tag_direction"].isel(tag=tag).values, dtype=np.float64)
    slice_axis = AXES.index(str(np.asarray(phase["slice_axis"].values).ravel()[tag]))
    frequency = float(np.asarray(phase["tag_frequency"].values).ravel()[tag])
    return frequency * float(np.linalg.norm(np.delete(direction, slice_axis)))


def _measure_one(phase: xr.Dataset, tag: int, time_index: int) -> float:
    """Measured in-plane tag frequency of one tag and frame (cycles/mm), NaN if unmeasurable."""
    frame = phase.isel(tag=tag, time=time_index)
    values = np.asarray(frame["phase"].transpose(*GRID_DIMS).values, dtype=np.float64)
    magnitude = np.asarray(frame["magnitude"].transpose(*GRID_DIMS).values, dtype=np.float64)
    tissue = np.isfinite(values) & np.isfinite(magnitude) & (magnitude > 0)
    if "mask" in phase.variables:
        tissue &= np.asarray(phase["mask"].isel(tag=tag).transpose(*GRID_DIMS).values, bool)
    if not tissue.any():
        return np.nan
    tissue &= magnitude >= np.percentile(magnitude[tissue], TISSUE_PERCENTILE)
    direction = np.asarray(phase["tag_direction"].isel(tag=tag).values, dtype=np.float64)
    frequency = float(np.asarray(phase["tag_frequency"].values).ravel()[tag])
    slice_axis = str(np.asarray(phase["slice_axis"].values).ravel()[tag])
    wave = np.zeros(3)
    for g, dim in enumerate(GRID_DIMS):
        if dim == slice_axis:
            continue
        step = grid_step(phase, dim)
        component = abs(direction[AXES.index(dim)])
        if step is None:
            if component >= 0.1:
                return np.nan  # the wave runs along an axis with one plane
            continue
        if component >= 0.1 and values.shape[g] * step * frequency * component < MIN_PERIODS:
            return np.nan
        n = values.shape[g]
        both = np.take(tissue, range(n - 1), axis=g) & np.take(tissue, range(1, n), axis=g)
        if np.count_nonzero(both) < MIN_PAIRS:
            return np.nan
        wave[AXES.index(dim)] = float(np.median(wrap(np.diff(values, axis=g))[both])) / step
    return float(np.linalg.norm(wave)) / (2.0 * np.pi)


def measure_tag_frequency(phase: xr.Dataset, time_index: int = 0) -> FloatArray:
    """Tag frequency of each tag as its harmonic phase shows it in one frame.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` dataset held in memory (a dask-backed one is computed frame by frame).
    time_index : int, default 0
        The frame to read; the first (the tagging's reference) shows the undeformed pattern.

    Returns
    -------
    numpy.ndarray, shape (tag,)
        In cycles/mm, in each tag's acquisition plane (the component along its
        ``slice_axis`` is not seen by in-plane phase steps; compare with the stated
        frequency projected on the plane, as :func:`tag_frequency_mismatch` does). NaN
        where it cannot be measured: no tissue signal, fewer than :data:`MIN_PAIRS` pairs
        of tissue voxels along an in-plane axis, or fewer than :data:`MIN_PERIODS` tag
        periods in the field of view along an axis the wave runs along.

    Examples
    --------
    >>> from harpx.imaging.synth import synthesize_tagged
    >>> from harpx.imaging.harp import extract_phase
    >>> tagged = synthesize_tagged(
    ...     lambda X, t: 0 * X, shape=(2, 32, 32), spacing=(2.0, 1.5, 1.5), times=[0.0],
    ...     tags=("x",), tag_period=6.0, snr=None, oversample=1)
    >>> bool(abs(measure_tag_frequency(extract_phase(tagged))[0] * 6.0 - 1) < 0.01)
    True
    """
    return np.array(
        [_measure_one(phase, t, time_index) for t in range(phase.sizes["tag"])], dtype=float
    )


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


def tags_off_frequency(phase: xr.Dataset, measured: ArrayLike | None = None) -> list[str]:
    """The tags whose measured frequency misses the stated one.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` dataset with the stated ``tag_frequency`` (tag), cycles/mm.
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


def tag_frequency_mismatch(phase: xr.Dataset, measured: ArrayLike | None = None) -> str:
    """The warning for the tags of :func:`tags_off_frequency` (same arguments), or "".

    It quotes, per tag, the frequency and period the phase shows and the stated ones, and
    says what to check: the tag period given for scanner files, and for SPAMM images a
    band-pass radius that keeps the DC peak out.
    """
    off = _off_frequency(phase, measured)
    if not off:
        return ""
    found = [
        f"tag {tag!r} advances its phase at {seen:.4g} cycles/mm (a {1 / seen:.3g} mm tag "
        f"period) but its tag_frequency says {stated:.4g} cycles/mm ({1 / stated:.3g} mm)"
        for tag, seen, stated in off
    ]
    return (
        f"{'; '.join(found)}, at the first frame. The band-pass did not isolate the tag "
        "peak: it was centred on the stated frequency, and the blur correction of tracking "
        "models that filter too. Check the tag period (read_tagged(..., tag_period=...), the "
        "dataset's tag_frequency) and, for SPAMM images, that the band-pass radius keeps "
        "the DC peak out (radius 0.5), then extract the phase again"
    )


def tag_frequency_flag(phase: xr.Dataset, tracker: str) -> str:
    """Warn that ``tracker`` tracks from phase whose tags miss their frequency; the flag.

    Parameters
    ----------
    phase : xarray.Dataset
        The ``phase/1`` dataset about to be tracked (its ``tag_frequency_measured`` is read;
        computed, if dask-backed).
    tracker : str
        Who tracks, for the message (e.g. ``"FE tracking"``).

    Returns
    -------
    str
        The value of the tracked result's ``attrs["tags_off_frequency"]``: the labels of
        :func:`tags_off_frequency` separated by spaces, or ``"none"``.

    Warns
    -----
    HarpxWarning
        If some tag is off (names them).
    """
    off = tags_off_frequency(phase)
    if off:
        warnings.warn(
            f"{tracker} from harmonic phase whose tag(s) {off} do not advance at their "
            "tag_frequency (tag_frequency_measured): the band-pass missed the tag peak, so the "
            "motion tracked from it is biased (attrs['tags_off_frequency'])",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return " ".join(off) or "none"
