r"""Step 3: undo the measurement chain's attenuation of an activation estimate, per muscle.

One forward simulation with the estimate (:func:`harpx.physiology.active.simulate_history`),
one pass through the same chain of imaging, phase extraction and tracking, and a closed-form
per-muscle scaling (:func:`calibrate_activation`); no optimisation loop.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import FloatArray
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.inverse._common import (
    attrs,
    matching_regions,
)
from harpx.inverse.correction import correct_activation
from harpx.inverse.estimate import estimate_activation
from harpx.mechanics.body import Body
from harpx.mechanics.fiber_laws import ActiveContraction
from harpx.physiology.active import default_law, fibred_body, simulate_history

__all__ = ["calibrate_activation"]


def calibrate_activation(
    estimate: xr.Dataset,
    tracked: xr.Dataset,
    body: Body,
    *,
    measure: Callable[[Any, FloatArray], xr.Dataset],
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    law: ActiveContraction | None = None,
) -> xr.Dataset:
    r"""Undo the measurement chain's attenuation of an activation estimate, per muscle.

    Imaging, harmonic-phase filtering and regularised tracking all smooth the motion, so the
    tracked fibre shortening — and every activation estimate built on it — is smaller than
    the truth (by 20--45 % per muscle in the tongue scene). This step measures that
    attenuation on a motion whose activations are known: the model is run forward with the
    estimate :math:`t` itself, the result is passed through the same chain (``measure``:
    image synthesis, phase extraction and tracking with the same settings), the same
    estimator is applied to it, giving :math:`t^{cal}`, and each muscle's estimate is
    divided by its transfer :math:`r_m = t^{cal}_m / t_m`:

    .. math::

        t^{(2)}_m = t_m / r_m = t_m^2 / t^{cal}_m .

    One forward simulation and one pass through the chain; a closed-form per-muscle
    scaling, not repeated (no optimisation loop).

    Parameters
    ----------
    estimate : xarray.Dataset
        Output of :func:`estimate_activation`, or of :func:`correct_activation` (then the
        calibration run is corrected the same way).
    tracked : xarray.Dataset
        The ``tracked/1`` data the estimate came from (frames and times are reused).
    body : Body
        The tracked model.
    measure : callable
        ``measure(body, U) -> tracked/1``: images the displacement history ``U``
        (ntime, ndof) of ``body`` with the acquisition of the data (same grid, tags,
        slices, SNR) and tracks it with the same settings as the data.
    dirichlet, terms : sequence, optional
        Boundary conditions and loads of the model (as for tracking).
    law : ActiveContraction, optional
        Active law; default ``body.active`` or ``ActiveContraction()``.

    Returns
    -------
    xarray.Dataset
        ``estimate`` with ``t_max`` replaced by the calibrated values, the input values in
        ``t_max_uncalibrated``, the transfer in ``chain_transfer`` (region) and the
        calibration run's estimate in ``t_max_calibration_run``; attrs ``method`` updated
        and ``calibration_epsilon`` (the calibration run's last tracking residual, rad);
        ``t_max_missing`` (region, bool) marks the regions without an estimate, which rest in
        the calibration run and stay NaN.

    Raises
    ------
    ValueError
        If ``measure`` does not return a tracked dataset of ``body`` with the data's frames.

    Warns
    -----
    HarpxWarning
        If a region has no estimate (``t_max`` NaN), naming it.

    Notes
    -----
    Exact if the chain maps activations linearly and without mixing muscles; its
    attenuation is measured at the estimate's own amplitude and pattern, which keeps the
    error of that assumption small when the estimate is close (e.g. after
    :func:`correct_activation`). A muscle whose transfer is not positive keeps its input.
    """
    fibred_body(body)
    law = default_law(body, law)
    names = matching_regions(estimate, body)
    index = int(estimate.attrs.get("time_index", tracked.sizes["time"] - 1))
    t1 = np.asarray(estimate["t_max"].values, dtype=np.float64)
    missing = np.isnan(t1)
    if missing.any():
        warnings.warn(
            f"calibrate_activation: region(s) {np.asarray(names)[missing].tolist()!r} have no "
            "estimate (t_max NaN): they rest in the calibration run and stay NaN "
            "(out['t_max_missing'])",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    frames = int(tracked.sizes["time"])
    U = simulate_history(
        body,
        dict(zip(names, np.nan_to_num(t1).tolist(), strict=True)),
        frames,
        dirichlet=dirichlet,
        terms=terms,
        law=law,
    )
    observed = measure(body, U)
    if not isinstance(observed, xr.Dataset) or observed.sizes.get("time") != frames:
        raise ValueError(
            f"measure(body, U) must return a tracked/1 dataset with the data's {frames} "
            "frames (image U with the data's acquisition and track it like the data)"
        )
    # what the estimator says of the calibration run (e.g. a resting muscle passively
    # lengthened by its neighbours reads negative) is about the model's own motion, not the
    # user's data: kept in t_max_calibration_run, not warned about
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HarpxWarning)
        run = estimate_activation(
            observed, body, time=index, law=law, aggregate=estimate.attrs.get("aggregate", "median")
        )
        if "t_max_direct" in estimate:
            run = correct_activation(run, observed, body, dirichlet=dirichlet, terms=terms, law=law)
    t_cal = np.asarray(run["t_max"].values, dtype=np.float64)
    transfer = np.full_like(t1, np.nan)
    np.divide(t_cal, t1, out=transfer, where=t1 > 0)
    ok = np.isfinite(transfer) & (transfer > 0)
    t2 = np.where(ok, t1 / np.where(ok, transfer, 1.0), t1)
    out = estimate.copy()
    out["t_max_uncalibrated"] = ("region", t1, attrs("t_max_uncalibrated"))
    out["t_max_calibration_run"] = ("region", t_cal, attrs("t_max_calibration_run"))
    out["chain_transfer"] = ("region", transfer, attrs("chain_transfer"))
    out["t_max"] = ("region", t2, attrs("t_max"))
    out["t_max_missing"] = ("region", missing, attrs("t_max_missing"))
    out.attrs["method"] = str(estimate.attrs.get("method", "direct")) + (
        " + calibration of the measurement chain with one re-simulation"
    )
    if "epsilon" in observed:
        out.attrs["calibration_epsilon"] = float(observed["epsilon"].values[-1])
    return out
