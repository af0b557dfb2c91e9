r"""Uncertainty of AHA segment strains, rotations, twist and torsion from the image noise.

:func:`harpx.tracking.uncertainty.tracking_uncertainty` samples how the image noise moves a
tracked motion: :math:`M` displacement changes :math:`\delta U^{(m)}` (time, dof), joint over
the frames. Each perturbed motion :math:`U + \delta U^{(m)}` is evaluated exactly as the
tracked one, by :func:`harpx.cardiac.strain.cardiac_strain` (cell strains of the body,
local frame and segments of the template), so every measure it reports — segment curves,
peaks over the frames, level rotations, twist, torsion, cell strains in the LV frame — gets
a standard deviation

.. math:: \sigma_q = \Big(\frac1M \sum_m \big(q(U + \delta U^{(m)}) - q(U)\big)^2\Big)^{1/2},

the root mean square about the tracked value (the noise's first-order effect has zero
mean; for a peak it also holds the shift of the extreme over the frames). Its relative
sampling error is about :math:`1/\sqrt{2M}`. What the uncertainty leaves out (model and
regularisation bias, the blur correction's model error, the penalty's choice, the phase
Hessian, tag jumps) is listed in the module notes of :mod:`harpx.tracking.uncertainty` and
in the result's ``excludes`` attribute; the template's own error (segment boundaries, local
frame) is left out too. Where no tag observed a component (``strain_source`` "inferred",
carried into the result), the value comes from the mechanical model: its σ is the noise
that reaches it through the model, not an uncertainty of the model itself.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import FloatArray
from harpx.cardiac.strain import cardiac_strain
from harpx.errors import HarpxWarning
from harpx.tracking.uncertainty import DEFAULT_SAMPLES, tracking_uncertainty

__all__ = ["MEASURES", "cardiac_strain_uncertainty", "segment_uncertainty"]

#: The measures of :func:`~harpx.cardiac.strain.cardiac_strain` that get a ``<name>_std``.
MEASURES = (
    "segment_strain",
    "segment_engineering_strain",
    "peak_strain",
    "peak_engineering_strain",
    "rotation",
    "twist",
    "torsion",
    "strain_lv",
    "engineering_strain_lv",
)
#: Variables of the displacement uncertainty carried into the result.
_CARRIED = ("displacement_std", "noise_residual", "equilibrium_step", "penalty_sensitivity")
#: Variables of a tracked result that cardiac_strain reads besides the motion.
_OBSERVATION = ("observed_fraction", "observed_directions")


def _perturbed(tracked: xr.Dataset, body: Any, U: FloatArray) -> xr.Dataset:
    """The finite-element result ``tracked`` with ``body`` moving by ``U`` (time, dof) instead:
    what cardiac_strain reads (the observation record of the tracked result kept)."""
    strain = np.stack([body.green_strain(u) for u in U])  # a few frames
    variables: dict[str, Any] = {
        "points": tracked["points"],
        "cells": tracked["cells"],
        "displacement": (("time", "node", "axis"), U.reshape(U.shape[0], -1, 3)),
        "green_strain": (("time", "cell", "i", "j"), strain),
    }
    variables.update({name: tracked[name] for name in _OBSERVATION if name in tracked})
    return xr.Dataset(variables, coords={"time": tracked["time"], "axis": tracked["axis"]})


def segment_uncertainty(
    tracked: xr.Dataset,
    body: Any,
    uncertainty: xr.Dataset,
    template: Any,
    **options: Any,
) -> xr.Dataset:
    """Standard deviations of the cardiac measures from sampled displacement changes.

    Parameters
    ----------
    tracked : xarray.Dataset
        The finite-element ``tracked/1`` result.
    body : Body
        The body that was tracked.
    uncertainty : xarray.Dataset
        :func:`~harpx.tracking.uncertainty.tracking_uncertainty` of ``tracked`` with
        ``keep_samples=True`` (``dof_displacement_samples`` (sample, time, dof), mm).
    template : VentricleTemplate
        The fitted ventricle, as for :func:`~harpx.cardiac.strain.cardiac_strain`.
    **options
        Further keywords of :func:`~harpx.cardiac.strain.cardiac_strain` (``anterior``
        …), applied to the tracked and to every perturbed motion alike.

    Returns
    -------
    xarray.Dataset
        ``<measure>_std`` for every measure of :data:`MEASURES`, on the dims and
        coordinates :func:`~harpx.cardiac.strain.cardiac_strain` gives the measure (so
        ``xr.merge([cardiac_strain(...), result])`` lines them up), in its units;
        ``displacement_std``, ``noise_residual``, ``equilibrium_step`` and
        ``penalty_sensitivity`` of ``uncertainty``; ``strain_source`` of the tracked
        result's measures (where it says "inferred" the σ is the noise the model passes
        on, module notes); the attributes of ``uncertainty``.

    Raises
    ------
    ValueError
        If ``uncertainty`` holds no samples, or samples of another shape than ``tracked``;
        and as :func:`~harpx.cardiac.strain.cardiac_strain`.

    Warns
    -----
    HarpxWarning
        As :func:`~harpx.cardiac.strain.cardiac_strain` of the tracked result (once: the
        perturbed motions' evaluations repeat them and are silenced).
    """
    if "dof_displacement_samples" not in uncertainty.variables:
        raise ValueError(
            "uncertainty holds no 'dof_displacement_samples'; compute it with "
            "tracking_uncertainty(..., keep_samples=True)"
        )
    U = np.asarray(tracked["dof_displacement"].transpose("time", "dof").values, dtype=np.float64)
    dU = np.asarray(uncertainty["dof_displacement_samples"].transpose("sample", "time", "dof"))
    if dU.shape[1:] != U.shape:
        raise ValueError(
            f"the samples have (time, dof) {dU.shape[1:]!r} but the tracked result "
            f"{U.shape!r}; pass the uncertainty of this result"
        )
    nominal = cardiac_strain(_perturbed(tracked, body, U), template, **options)
    names = [name for name in MEASURES if name in nominal.variables]
    squares = {name: np.zeros(nominal[name].shape) for name in names}
    with warnings.catch_warnings():  # the nominal evaluation has said it all
        warnings.simplefilter("ignore", HarpxWarning)
        for m in range(dU.shape[0]):  # one evaluation per noise sample
            sample = cardiac_strain(_perturbed(tracked, body, U + dU[m]), template, **options)
            for name in names:
                squares[name] += (sample[name].values - nominal[name].values) ** 2
    out = xr.Dataset()
    for name in names:
        attrs = dict(nominal[name].attrs)
        attrs["long_name"] = (
            f"standard deviation of the {attrs.get('long_name', name)} due to image noise"  # noqa: E501
        )
        out[f"{name}_std"] = nominal[name].copy(data=np.sqrt(squares[name] / dU.shape[0]))
        out[f"{name}_std"].attrs = attrs
    for name in _CARRIED:
        if name in uncertainty.variables:
            out[name] = uncertainty[name]
    if "strain_source" in nominal.variables:
        out["strain_source"] = nominal["strain_source"]
    out.attrs.update(uncertainty.attrs)
    if "anterior_deg" in nominal.attrs:
        out.attrs["anterior_deg"] = nominal.attrs["anterior_deg"]
    return out


def cardiac_strain_uncertainty(
    tracked: xr.Dataset,
    body: Any,
    images: xr.Dataset,
    template: Any,
    *,
    tagged: xr.Dataset | None = None,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    samples: int = DEFAULT_SAMPLES,
    seed: int | None = None,
    **options: Any,
) -> xr.Dataset:
    """Standard deviations of the AHA segment strains (and the other cardiac measures).

    :func:`~harpx.tracking.uncertainty.tracking_uncertainty` followed by
    :func:`segment_uncertainty`; the parameters are theirs.

    Parameters
    ----------
    tracked : xarray.Dataset
        The finite-element ``tracked/1`` result (penalty method).
    body : Body
        The body that was tracked.
    images : xarray.Dataset
        The ``phase/1`` (or ``tagged/1``) dataset that was tracked.
    template : VentricleTemplate
        The fitted ventricle.
    tagged : xarray.Dataset, optional
        The tagged images the phase came from (noise correlation across slices).
    dirichlet, terms : sequence, optional
        The Dirichlet conditions and residual terms given to ``track``.
    samples : int, default 64
        Noise samples.
    seed : int, optional
        Seed of the noise samples.
    **options
        Keywords of :func:`~harpx.cardiac.strain.cardiac_strain` (``anterior`` …).

    Returns
    -------
    xarray.Dataset
        As :func:`segment_uncertainty`.

    Raises
    ------
    ValueError
        As :func:`~harpx.tracking.uncertainty.tracking_uncertainty` and
        :func:`segment_uncertainty`.

    Warns
    -----
    HarpxWarning
        As :func:`~harpx.tracking.uncertainty.tracking_uncertainty` and
        :func:`segment_uncertainty`.
    """
    uncertainty = tracking_uncertainty(
        tracked, body, images, tagged=tagged, dirichlet=dirichlet, terms=terms,
        samples=samples, seed=seed, keep_samples=True,
    )  # fmt: skip
    return segment_uncertainty(tracked, body, uncertainty, template, **options)
