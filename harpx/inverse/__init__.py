r"""Inverse problems on tracked motion: muscle activation from tracked fibre stretch (§4.3).

The paper estimates the contractile stress of each tongue muscle *directly* from the
image-derived fibre shortening, by solving the active-contraction law for :math:`T_{max}`,
instead of running an optimisation loop of forward simulations. This subpackage does that,
plus two optional closed-form corrections, as plain functions, one module per step:

1. :mod:`~harpx.inverse.estimate` (:func:`estimate_activation`): the paper's direct
   estimate; per element, uniaxial fibre equilibrium solved for :math:`T_{max}`; per
   muscle, the median (or volume-weighted mean) of the element values with their spread.
2. :mod:`~harpx.inverse.correction` (:func:`correct_activation`): *one* linear
   equilibrium correction at the tracked configuration for the load that neighbouring
   muscles and attachments carry (a linear system of the size of the number of muscles).
3. :mod:`~harpx.inverse.calibration` (:func:`calibrate_activation`): *one* per-muscle
   scaling for the attenuation of the measurement chain (imaging, phase filtering,
   regularised tracking), measured by passing a re-simulation with the estimate through
   the same chain.
4. :mod:`~harpx.inverse.comparison` (:func:`resimulate`): a forward simulation of the
   tracking model with the per-muscle estimates, compared with the tracked fibre stretch
   element by element and per muscle (paper Fig. 3c;
   :func:`harpx.plotting.plot_stretch_agreement`).

None of them iterates: there is no objective function and no search.

The chain reads per-element fibre stretch, which is noisier than the displacement it comes
from: track the data (and, in the calibration's ``measure``, the re-simulated images) with
:data:`ACTIVATION_TRACKING`, the tracker's defaults with the target at twice the
phase-noise floor and without the blur correction's second pass: fitted to the floor
itself the element stretches carry the noise and the estimates fall short
(``benchmarks/results/README.md``, tongue).

The forward simulations they use live in :mod:`harpx.physiology.active`
(``simulate_activation``, ``simulate_history``), the figure in :mod:`harpx.plotting`.
"""

from __future__ import annotations

from harpx._moved import moved_getattr
from harpx.inverse.calibration import calibrate_activation
from harpx.inverse.comparison import resimulate
from harpx.inverse.correction import correct_activation
from harpx.inverse.estimate import estimate_activation, uniaxial_active_tension
from harpx.tracking.settings import TrackingSettings

#: Tracking settings for the activation chain (module notes): target ε twice the floor,
#: no blur-correction pass (it leaves the tongue's error as it is at twice the time).
ACTIVATION_TRACKING = TrackingSettings(epsilon_factor=2.0, blur_passes=0)

__all__ = [
    "ACTIVATION_TRACKING",
    "calibrate_activation",
    "correct_activation",
    "estimate_activation",
    "resimulate",
    "uniaxial_active_tension",
]


__getattr__ = moved_getattr(__name__)
