"""Analytic ground-truth motions for synthetic scenes.

The motions here are written in closed form with their exact inverses, so synthetic images
need no numerical inversion and the tracked result can be compared with the truth at any
material point. They are *not* produced by the finite-element model that tracks them, which
keeps the validation free of inverse crimes (a tracker tested on images made by its own
model and discretisation would look better than it is).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from harpx._typing import FloatArray


def smooth_step(s: ArrayLike) -> FloatArray:
    """C¹ ramp from 0 (s ≤ 0) to 1 (s ≥ 1): ½(1 − cos πs) in between (dimensionless)."""
    s = np.clip(np.asarray(s, dtype=np.float64), 0.0, 1.0)
    return 0.5 * (1.0 - np.cos(np.pi * s))


@dataclass(frozen=True)
class RotationalImpact:
    """Lagged axial rotation of a gel cylinder whose container turns suddenly.

    The container (side wall at radius ``radius`` and base at ``z = base``) turns about the
    z axis by the angle Θ(t) = ``angle`` · S((t − ``onset``)/``rise_time``), S a C¹ ramp.
    Gel at distance from the container lags behind it: a material point at cylindrical
    position (R, ϑ, Z) is at (R, ϑ + θ(R, Z, t), Z + w(R, t)) with

    .. math::

        θ(R, Z, t) = Θ\\bigl(t − τ(R, Z)\\bigr)
        + a\\,\\Bigl(1 − \\frac{R^2}{R_0^2}\\Bigr)\\frac{Z − Z_b}{H}\\,
          S\\Bigl(\\frac{t − t_0}{T_r}\\Bigr)\\sin\\frac{2π(t − t_0)}{T_b},\\qquad
        τ = τ_{max}\\,\\Bigl(1 − \\frac{R^2}{R_0^2}\\Bigr)\\,\\frac{Z − Z_b}{H},\\qquad
        w = w_{max}\\,\\frac{R^2}{R_0^2}\\Bigl(1 − \\frac{R^2}{R_0^2}\\Bigr)\\,S(t).

    The second term of θ is the gel's elastic rebound (amplitude a = ``rebound``, period
    T_b = ``rebound_period``) about the container's final angle. The map keeps R, shifts ϑ
    by a function of (R, Z, t) and Z by a function of (R, t): its Jacobian in cylindrical
    coordinates is triangular with unit diagonal, so det F = 1
    exactly (volume preserving). The wall and the base follow the container (τ = 0, w = 0
    there) while the free top surface lags most; the FE model, which knows none of this,
    sees only the images.

    Parameters
    ----------
    radius : float
        Gel radius R₀ in mm.
    base : float
        z of the container base in mm.
    height : float
        Gel height H in mm.
    angle : float
        Final container rotation Θ_max in rad.
    rise_time : float
        Duration of the container's acceleration ramp in ms.
    onset : float
        Time at which the container starts turning in ms.
    lag : float
        Maximum delay τ_max of the gel behind the container in ms.
    axial : float
        Peak axial displacement w_max in mm (a small secondary motion for the z tag).
    rebound : float
        Amplitude a of the gel's elastic rebound in rad.
    rebound_period : float
        Period T_b of the rebound in ms.
    """

    radius: float = 60.0
    base: float = -15.0
    height: float = 30.0
    angle: float = 0.2
    rise_time: float = 72.0
    onset: float = 0.0
    lag: float = 40.0
    axial: float = 1.0
    rebound: float = 0.04
    rebound_period: float = 120.0

    def _angle(self, R: FloatArray, Z: FloatArray, t: float) -> FloatArray:
        rho2 = np.clip(R / self.radius, 0.0, None) ** 2
        height_fraction = np.clip((Z - self.base) / self.height, 0.0, 1.0)
        delay = self.lag * np.clip(1.0 - rho2, 0.0, 1.0) * height_fraction
        lagged = self.angle * smooth_step((t - self.onset - delay) / self.rise_time)
        started = smooth_step((t - self.onset) / self.rise_time)
        phase = 2.0 * np.pi * (t - self.onset) / self.rebound_period
        interior = np.clip(1.0 - rho2, 0.0, 1.0) * height_fraction
        return lagged + self.rebound * interior * started * np.sin(phase)

    def _axial(self, R: FloatArray, t: float) -> FloatArray:
        rho2 = (R / self.radius) ** 2
        profile = np.clip(rho2 * (1.0 - rho2), 0.0, None)
        return self.axial * profile * smooth_step((t - self.onset) / self.rise_time)

    def __call__(self, X: FloatArray, t: float) -> FloatArray:
        """Lagrangian displacement u(X, t) in mm at reference points ``X`` (n, 3) mm."""
        X = np.asarray(X, dtype=float)
        R = np.hypot(X[:, 0], X[:, 1])
        theta = self._angle(R, X[:, 2], t)
        c, s = np.cos(theta), np.sin(theta)
        u = np.empty_like(X)
        u[:, 0] = c * X[:, 0] - s * X[:, 1] - X[:, 0]
        u[:, 1] = s * X[:, 0] + c * X[:, 1] - X[:, 1]
        u[:, 2] = self._axial(R, t)
        return u

    def inverse(self, x: FloatArray, t: float) -> FloatArray:
        """Reference position X(x, t) in mm of the material point at ``x`` (n, 3) mm."""
        x = np.asarray(x, dtype=float)
        R = np.hypot(x[:, 0], x[:, 1])
        Z = x[:, 2] - self._axial(R, t)
        theta = self._angle(R, Z, t)
        c, s = np.cos(theta), np.sin(theta)
        X = np.empty_like(x)
        X[:, 0] = c * x[:, 0] + s * x[:, 1]
        X[:, 1] = -s * x[:, 0] + c * x[:, 1]
        X[:, 2] = Z
        return X
