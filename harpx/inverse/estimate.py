r"""Step 1: the direct estimate of muscle activation from tracked fibre stretch (paper §4.3).

The paper estimates the contractile stress of each muscle *directly* from the image-derived
fibre shortening, by solving the active-contraction law of its reference [1] for
:math:`T_{max}` (the "Eq. 4" the paper cites is that law, not its phase equation), instead
of running an optimisation loop of forward simulations: per element, the inversion below;
per muscle, the median (or volume-weighted mean) of the element values with their spread
(:func:`estimate_activation`).

Per-element equation (uniaxial fibre equilibrium)
-------------------------------------------------
The tissue is hyperelastic with an active fibre stress of Guccione--McCulloch type in
second Piola--Kirchhoff form (:class:`harpx.mechanics.fiber_laws.ActiveContraction`),

.. math::

    S = S_{iso}(C) + p\,J C^{-1} + T_a f_0 \otimes f_0, \qquad
    T_a = T_{max}\, g(\lambda), \quad \lambda = |F f_0|,

with :math:`g` the length-dependent calcium factor (:math:`g = 1` for the prescribed law).
In Cauchy form, with the deformed unit fibre :math:`\hat a = F f_0/\lambda`,
:math:`\sigma = \sigma_{iso} + p I + (T_a \lambda^2 / J)\, \hat a \otimes \hat a`.

*Assumption:* each element is a muscle segment in **uniaxial stress along its fibre**: no
traction on planes parallel to the fibre (the mean lateral normal stress vanishes) and no
net fibre traction (an unloaded muscle whose active stress is balanced by its own passive
stress). The lateral condition fixes the hydrostatic pressure,
:math:`p = -\sigma^{iso}_{\perp}` with :math:`\sigma^{iso}_{\perp} = \tfrac12(\operatorname{tr}
\sigma_{iso} - \sigma^{iso}_{ff})` and :math:`\sigma^{iso}_{ff} = \hat a \cdot \sigma_{iso}
\hat a`; the fibre condition then gives

.. math::

    T_a = -\frac{J}{\lambda^2}\,\big(\sigma^{iso}_{ff} - \sigma^{iso}_{\perp}\big), \qquad
    T_{max} = \frac{T_a}{g(\lambda)} ,

evaluated from the tracked deformation gradient at every Gauss point (volume-averaged per
cell) and the tracked cell fibre stretch. Only the *deviatoric* passive stress enters,
which the tracked kinematics determine well; the pressure of a nearly incompressible solid
(:math:`\kappa \ln J / J`), which a tracked :math:`J` cannot resolve, drops out. For the
uncoupled neo-Hookean solid in isochoric uniaxial stretch this is
:math:`T_a = 2 C_1 (\lambda^{-3} - 1)`. The result is exact for a homogeneous muscle in
uniaxial stress (tested to 1e-6), for any bulk modulus.

*Limits.* Inside an organ a muscle is not in uniaxial stress: neighbouring muscles and
the attachments (mandible, hyoid) carry part of the active load, and passive tissue
stretched by other muscles has :math:`T_a < 0` by this formula. The element estimates are
therefore biased low where a muscle works against stiff surroundings and scattered near
muscle borders; they become NaN where :math:`g(\lambda) = 0` (calcium law with
:math:`l_r\lambda \le l_0`, any :math:`T_{max}` fits) and ill-conditioned where
:math:`g` is small. The per-muscle median damps the scatter, not the bias.

References
----------
.. [1] Guccione JM, McCulloch AD. Mechanics of active contraction in cardiac muscle:
   Part I. J Biomech Eng 115:72--81, 1993.
.. [2] Maas SA et al. FEBio theory manual, section 5.12 (active contraction).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx._typing import FloatArray
from harpx.inverse._common import (
    STRETCH_NOTE,
    attrs,
    region_statistics,
    region_table,
    time_index,
    tracked_u,
    warn_doubtful_regions,
)
from harpx.mechanics.body import Body
from harpx.mechanics.fiber_laws import ActiveContraction
from harpx.mechanics.kinematics import split_growth, unit_fibers
from harpx.physiology.active import default_law, fibred_body

__all__ = ["estimate_activation", "uniaxial_active_tension"]

Aggregate = Literal["median", "mean"]


def uniaxial_active_tension(
    material: Any, F: ArrayLike, fiber: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    r"""Active fibre tension that holds a segment in uniaxial stress along its fibre.

    Parameters
    ----------
    material : object
        Passive uncoupled material with ``isochoric_response(F, fiber)`` (e.g.
        :class:`~harpx.mechanics.materials.NeoHookean`).
    F : array_like, shape (..., 3, 3)
        (Elastic) deformation gradients, dimensionless, ``det F > 0``.
    fiber : array_like, shape (..., 3)
        Reference fibre directions (any non-zero length; normalised here), broadcasting
        against ``F``.

    Returns
    -------
    tension : ndarray, shape (...)
        :math:`T_a = -(J/\lambda^2)(\sigma^{iso}_{ff} - \sigma^{iso}_\perp)` in kPa (second
        Piola--Kirchhoff fibre component; see the module docstring).
    stretch : ndarray, shape (...)
        Fibre stretch :math:`\lambda = |F f_0|` (dimensionless).

    Raises
    ------
    ValueError
        If a fibre direction is zero or not finite, or ``fiber`` is not of shape (..., 3).

    Examples
    --------
    >>> from harpx.inverse.estimate import uniaxial_active_tension
    >>> from harpx.mechanics.materials import NeoHookean
    >>> lam = 0.9
    >>> F = np.diag([lam, lam**-0.5, lam**-0.5])
    >>> T, _ = uniaxial_active_tension(NeoHookean(c1=1.0, kappa=120.0), F, [1.0, 0.0, 0.0])
    >>> round(float(T), 12) == round(2.0 * (lam**-3 - 1.0), 12)  # 2 C1 (λ⁻³ - 1)
    True
    """
    F = np.asarray(F, dtype=np.float64)
    f = unit_fibers(fiber)  # names a zero or non-finite direction
    f = np.broadcast_to(f, F.shape[:-1])
    P, _ = material.isochoric_response(F, f)
    J = np.linalg.det(F)
    sigma = np.matmul(P, np.swapaxes(F, -1, -2)) / J[..., None, None]
    a = np.einsum("...iJ,...J->...i", F, f)
    lam2 = np.einsum("...i,...i->...", a, a)
    s_ff = np.einsum("...i,...ij,...j->...", a, sigma, a) / lam2
    s_lat = 0.5 * (np.trace(sigma, axis1=-2, axis2=-1) - s_ff)
    return -(J / lam2) * (s_ff - s_lat), np.sqrt(lam2)


def estimate_activation(
    tracked: xr.Dataset,
    body: Body,
    *,
    time: int = -1,
    law: ActiveContraction | None = None,
    aggregate: Aggregate = "median",
) -> xr.Dataset:
    r"""Direct per-element estimate of :math:`T_{max}` from tracked motion, per muscle.

    Parameters
    ----------
    tracked : xarray.Dataset
        ``tracked/1`` result of :func:`harpx.tracking.track.track` (uses ``points``,
        ``displacement`` and, if present, ``fiber_stretch``).
    body : Body
        The model that was tracked, with fibres and named regions (muscles).
    time : int, default -1
        Index of the frame (along ``time``) to invert, e.g. the activated frame.
    law : ActiveContraction, optional
        Active-contraction law to invert; default ``body.active`` or
        ``ActiveContraction()`` (Guccione--McCulloch calcium law, FEBio defaults).
    aggregate : {"median", "mean"}, default "median"
        Per-region statistic of the cell estimates: median, or volume-weighted mean.

    Returns
    -------
    xarray.Dataset
        ``t_max_cell`` (cell) kPa, NaN where :math:`g(\lambda) = 0`; ``active_tension_cell``
        (cell) kPa; ``fiber_stretch`` (cell), the elastic stretch the law is evaluated at
        (the tracked ``fiber_stretch`` if present, else from the displacement; a body's
        growth divided out, by the cell's elastic-to-total stretch ratio, :math:`1/\vartheta`
        for fibre growth); ``region_label`` (cell); per ``region``: ``t_max`` (the
        aggregate), ``t_max_mean``, ``t_max_q25``, ``t_max_q75`` (kPa), ``valid_cells``,
        ``negative_cells`` (cells with :math:`T_{max} < 0`) and ``out_of_range_cells``
        (cells with :math:`g(\lambda) = 0`, no estimate). attrs record the method, frame
        and law.

    Raises
    ------
    ValueError
        If ``tracked`` does not belong to ``body``, ``time`` is out of range, the body has
        no fibres, ``aggregate`` is unknown or the tracked ``fiber_stretch`` is not one
        value per cell.

    Warns
    -----
    HarpxWarning
        If a region's ``t_max`` is negative (fibres lengthened or passively shortened: not
        the active contraction the estimate assumes; it cannot be simulated), or NaN (the
        message tells fibres shortened past the law's active range from cells without
        data).

    Notes
    -----
    Per element :math:`T_a = -(J/\lambda^2)(\sigma^{iso}_{ff} - \sigma^{iso}_\perp)` (uniaxial
    fibre equilibrium) and :math:`T_{max} = T_a / g(\lambda)`, i.e. the active-contraction
    law solved for :math:`T_{max}` (paper §4.3). Derivation, assumption and limits: module
    docstring.

    Examples
    --------
    A block of 3 × 2 × 2 hexahedra with fibres along x, shortened to 0.9 along them at
    constant volume (one region, ``"body"``); with the prescribed law (:math:`g = 1`) the
    estimate is the uniaxial tension of the neo-Hookean solid, :math:`2 C_1 (\lambda^{-3} - 1)`:

    >>> from harpx.mechanics.body import Body
    >>> from harpx.mechanics.fiber_laws import ActiveContraction
    >>> from harpx.mechanics.materials import NeoHookean
    >>> from harpx.mechanics.mesh import box
    >>> body = Body(box((10.0, 4.0, 4.0), (3, 2, 2)), NeoHookean(c1=1.0, kappa=120.0),
    ...             fibers=[[1.0, 0.0, 0.0]] * 12)
    >>> lam = 0.9
    >>> u = body.dof_points @ (np.diag([lam, lam**-0.5, lam**-0.5]) - np.eye(3))  # mm
    >>> tracked = xr.Dataset({"points": (("node", "axis"), body.dof_points),
    ...                       "displacement": (("time", "node", "axis"), np.stack([0 * u, u]))})
    >>> est = estimate_activation(tracked, body, law=ActiveContraction(law="prescribed"))
    >>> est.region.values.tolist(), est.t_max.round(4).values.tolist()  # kPa
    (['body'], [0.7435])
    >>> bool(np.allclose(est.t_max, 2.0 * (lam**-3 - 1.0)))
    True
    """
    fibred_body(body)
    if aggregate not in ("median", "mean"):
        raise ValueError(f"aggregate={aggregate!r}; expected 'median' or 'mean'")
    law = default_law(body, law)
    index = time_index(tracked, time)
    u = tracked_u(tracked, body, index)
    assert body.fibers_qp is not None  # checked by fibred_body
    F = body.deformation_gradient(u)
    Fe = F if body.growth_tensor is None else split_growth(F, body.growth_tensor)
    T_qp, lam_qp = uniaxial_active_tension(body.material, Fe, body.fibers_qp)
    T_cell = body.cell_average(T_qp)
    lam = body.cell_average(lam_qp)  # elastic fibre stretch |Fe f0|, as in the forward law
    if "fiber_stretch" in tracked:
        lam_tracked = np.asarray(tracked["fiber_stretch"].isel(time=index).values, dtype=np.float64)
        if lam_tracked.shape != (body.ncell,):
            raise ValueError(
                f"tracked 'fiber_stretch' has shape {lam_tracked.shape!r}; expected "
                f"({body.ncell},) cells of the body"
            )
        # the tracked stretch is the total |F f0|; the law acts on the elastic stretch:
        # divide the growth out (the cell's elastic / total ratio; 1/θ for fibre growth)
        lam = (
            lam_tracked if body.growth_tensor is None else lam_tracked * lam / body.fiber_stretch(u)
        )
    t_cell = np.asarray(law.t_max_for_tension(lam, T_cell), dtype=np.float64)
    g = np.asarray(law.activation_factor(lam), dtype=np.float64)
    out_of_range = np.isfinite(lam) & np.isfinite(T_cell) & (g <= 0.0)

    names, label = region_table(body)
    stats = region_statistics(body, names, t_cell, out_of_range, aggregate)
    ds = xr.Dataset(
        {
            "t_max_cell": ("cell", t_cell, attrs("t_max_cell")),
            "active_tension_cell": ("cell", T_cell, attrs("active_tension_cell")),
            "fiber_stretch": ("cell", lam, attrs("fiber_stretch") | STRETCH_NOTE),
            "region_label": (
                "cell",
                label,
                attrs("region_label") | {"flag_meanings": " ".join(names)},
            ),
        }
        | {key: ("region", value, attrs(key)) for key, value in stats.items()},
        coords={"region": ("region", names, {"units": "1", "long_name": "muscle region"})},
        attrs={
            "method": "direct: uniaxial fibre equilibrium per element",
            "aggregate": aggregate,
            "time_index": index,
            "law": repr(law),
        },
    )
    if "time" in tracked.coords:
        ds.attrs["time"] = float(tracked["time"].values[index])
    warn_doubtful_regions(ds, body, law)
    return ds
