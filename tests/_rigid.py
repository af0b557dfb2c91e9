"""Rigid and affine analytic motions with exact inverses, for stability sweeps.

Each motion is prescribed at the frame times by a cumulative profile (an angle, an offset or
a stretch per frame, interpolated linearly in time between frames) and maps a reference
point ``X`` (n, 3) mm to ``x = X + u(X, t)`` in closed form, with the exact inverse
``X(x, t)``. None of them is produced by the finite-element model that tracks them,
so the tracker is never tested on images made by its own model.

:func:`frame_profile` builds the cumulative profiles used by the benchmark: a steady
per-frame step, optionally reached through a linear ramp of smaller steps (so that frame 1
moves less than half a tag period and a motion predictor has history to extrapolate).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from harpx._typing import FloatArray
from harpx.imaging.synth import synthesize_tagged
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import cylinder
from harpx.scenes.phantom import Scene

__all__ = ["RigidRotation", "Stretch", "Translation", "cylinder_scene", "frame_profile"]


def frame_profile(step: float, frames: int, *, ramp: int = 0) -> FloatArray:
    """Cumulative motion at each frame for a per-frame ``step`` reached after a ramp.

    Parameters
    ----------
    step : float
        Steady per-frame increment (mm, rad, … — the unit of the profile).
    frames : int
        Number of frames including the reference frame 0 (>= 1).
    ramp : int, default 0
        Frames over which the increment grows linearly before the steady step: the
        increment of frame ``n`` is ``step * min(1, n / (ramp + 1))``.

    Returns
    -------
    ndarray, shape (frames,)
        Cumulative motion, 0 at frame 0.

    Examples
    --------
    >>> frame_profile(0.75, 5, ramp=2).tolist()
    [0.0, 0.25, 0.75, 1.5, 2.25]
    """
    if int(frames) < 1:
        raise ValueError(f"frames={frames!r} must be at least 1")
    if int(ramp) < 0:
        raise ValueError(f"ramp={ramp!r} must be >= 0")
    n = np.arange(1, int(frames))
    increments = step * np.minimum(1.0, n / (int(ramp) + 1))
    return np.concatenate([[0.0], np.cumsum(increments)])


def _profile(times: Sequence[float], values: Sequence[float]) -> tuple[FloatArray, FloatArray]:
    t = np.asarray(times, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or t.shape != v.shape or t.size == 0:
        raise ValueError(
            f"times ({t.shape}) and the profile ({v.shape}) must be 1D arrays of one value "
            "per frame"
        )
    if np.any(np.diff(t) <= 0):
        raise ValueError(f"times={t.tolist()!r} must be increasing (ms)")
    return t, v


@dataclass(frozen=True)
class RigidRotation:
    """Rigid rotation about an axis parallel to z through ``center``.

    Parameters
    ----------
    times : sequence of float
        Frame times in ms.
    angles : sequence of float
        Rotation angle at each frame, rad (counter-clockwise seen from +z; 0 at the
        reference frame). Linear in time between frames.
    center : (float, float), default (0, 0)
        (x, y) of the axis, mm.

    Examples
    --------
    >>> motion = RigidRotation(times=(0.0, 10.0), angles=(0.0, np.pi))
    >>> X = np.array([[1.0, 0.0, 2.0]])
    >>> np.round(motion(X, 10.0), 12).tolist()
    [[-2.0, 0.0, 0.0]]
    >>> bool(np.allclose(motion.inverse(X + motion(X, 10.0), 10.0), X))
    True
    """

    times: tuple[float, ...]
    angles: tuple[float, ...]
    center: tuple[float, float] = (0.0, 0.0)

    def angle(self, t: float) -> float:
        """Rotation angle at time ``t`` (ms), rad."""
        times, angles = _profile(self.times, self.angles)
        return float(np.interp(t, times, angles))

    def _rotate(self, P: FloatArray, theta: float) -> FloatArray:
        c, s = np.cos(theta), np.sin(theta)
        out = np.array(P, dtype=np.float64, copy=True)
        dx, dy = P[:, 0] - self.center[0], P[:, 1] - self.center[1]
        out[:, 0] = self.center[0] + c * dx - s * dy
        out[:, 1] = self.center[1] + s * dx + c * dy
        return out

    def __call__(self, X: FloatArray, t: float) -> FloatArray:
        """Lagrangian displacement u(X, t) in mm at reference points ``X`` (n, 3) mm."""
        X = np.asarray(X, dtype=np.float64)
        return self._rotate(X, self.angle(t)) - X

    def inverse(self, x: FloatArray, t: float) -> FloatArray:
        """Reference position X(x, t) in mm of the material point at ``x`` (n, 3) mm."""
        return self._rotate(np.asarray(x, dtype=np.float64), -self.angle(t))


@dataclass(frozen=True)
class Translation:
    """Uniform translation along a fixed direction.

    Parameters
    ----------
    times : sequence of float
        Frame times in ms.
    offsets : sequence of float
        Distance travelled at each frame, mm (0 at the reference frame).
    direction : (float, float, float), default (1, 0, 0)
        Direction (x, y, z) of travel, normalised here.

    Examples
    --------
    >>> motion = Translation(times=(0.0, 18.0), offsets=(0.0, 6.0))
    >>> motion(np.zeros((1, 3)), 9.0).tolist()
    [[3.0, 0.0, 0.0]]
    """

    times: tuple[float, ...]
    offsets: tuple[float, ...]
    direction: tuple[float, float, float] = (1.0, 0.0, 0.0)

    def _shift(self, t: float) -> FloatArray:
        times, offsets = _profile(self.times, self.offsets)
        d = np.asarray(self.direction, dtype=np.float64)
        norm = float(np.linalg.norm(d))
        if d.shape != (3,) or not norm > 0:
            raise ValueError(f"direction={self.direction!r} must be a non-zero 3-vector")
        return float(np.interp(t, times, offsets)) * d / norm

    def __call__(self, X: FloatArray, t: float) -> FloatArray:
        """Lagrangian displacement u(X, t) in mm at reference points ``X`` (n, 3) mm."""
        X = np.asarray(X, dtype=np.float64)
        return np.broadcast_to(self._shift(t), X.shape).copy()

    def inverse(self, x: FloatArray, t: float) -> FloatArray:
        """Reference position X(x, t) in mm of the material point at ``x`` (n, 3) mm."""
        return np.asarray(x, dtype=np.float64) - self._shift(t)


@dataclass(frozen=True)
class Stretch:
    """Homogeneous stretch along one axis about a fixed plane: x_a = c_a + λ(t) (X_a − c_a).

    With λ < 1 it is a uniaxial compression whose volume ratio is J = λ (not
    volume-preserving), so λ → 0 drives a model that follows it towards J → 0.

    Parameters
    ----------
    times : sequence of float
        Frame times in ms.
    stretches : sequence of float
        Stretch λ at each frame (1 at the reference frame, > 0), dimensionless.
    axis : int, default 0
        Column (0 = x, 1 = y, 2 = z) that is stretched.
    center : float, default 0
        Coordinate c_a of the plane that stays in place, mm.

    Examples
    --------
    >>> motion = Stretch(times=(0.0, 1.0), stretches=(1.0, 0.5))
    >>> motion(np.array([[4.0, 1.0, 1.0]]), 1.0).tolist()
    [[-2.0, 0.0, 0.0]]
    """

    times: tuple[float, ...]
    stretches: tuple[float, ...]
    axis: int = 0
    center: float = 0.0

    def stretch(self, t: float) -> float:
        """Stretch λ at time ``t`` (ms), dimensionless."""
        times, stretches = _profile(self.times, self.stretches)
        if np.any(stretches <= 0):
            raise ValueError(f"stretches={self.stretches!r} must be positive")
        return float(np.interp(t, times, stretches))

    def __call__(self, X: FloatArray, t: float) -> FloatArray:
        """Lagrangian displacement u(X, t) in mm at reference points ``X`` (n, 3) mm."""
        X = np.asarray(X, dtype=np.float64)
        u = np.zeros_like(X)
        u[:, self.axis] = (self.stretch(t) - 1.0) * (X[:, self.axis] - self.center)
        return u

    def inverse(self, x: FloatArray, t: float) -> FloatArray:
        """Reference position X(x, t) in mm of the material point at ``x`` (n, 3) mm."""
        X = np.array(x, dtype=np.float64, copy=True)
        X[:, self.axis] = self.center + (X[:, self.axis] - self.center) / self.stretch(t)
        return X


def cylinder_scene(
    motion: Callable[[FloatArray, float], FloatArray],
    *,
    times: Sequence[float],
    radius: float = 12.0,
    height: float = 6.0,
    tag_period: float = 8.0,
    spacing: float = 1.5,
    snr: float | None = None,
    sequence: Literal["SPAMM", "CSPAMM"] = "CSPAMM",
    travel: float = 0.0,
    n_radial: int = 2,
    n_circumferential: int = 16,
    n_axial: int = 2,
    c1: float = 1.0,
    kappa: float = 100.0,
    seed: int = 0,
) -> Scene:
    """A gel cylinder moved by an analytic motion, imaged with x, y and z tags.

    The cylinder (axis z, centred on the origin) is imaged on an isotropic grid whose
    in-plane field of view holds it with a voxel of margin, extended by ``travel`` along +x
    for translations; the tracking mesh is an O-grid of the same cylinder.

    Parameters
    ----------
    motion : callable
        ``u(X, t)`` in mm with an ``inverse(x, t)`` method (the exact inverse motion).
    times : sequence of float
        Frame times in ms.
    radius, height : float, default 12, 6
        Cylinder size, mm.
    tag_period : float, default 8
        Tag spacing, mm.
    spacing : float, default 1.5
        Voxel size, mm (isotropic).
    snr : float or None, default None
        Image signal-to-noise ratio (None: noise free).
    sequence : {"SPAMM", "CSPAMM"}, default "CSPAMM"
        Tagging sequence.
    travel : float, default 0
        Extra field of view along +x for the body to travel into, mm.
    n_radial, n_circumferential, n_axial : int
        Mesh divisions (see :func:`harpx.mechanics.mesh.cylinder`).
    c1, kappa : float, default 1, 100
        Neo-Hookean material of the tracking model, kPa.
    seed : int, default 0
        Seed of the image noise.

    Returns
    -------
    Scene
        ``tagged`` (``tagged/1`` with ``displacement_true``), the mesh, the material and
        the motion.

    Examples
    --------
    >>> motion = Translation(times=(0.0, 18.0), offsets=(0.0, 2.0))
    >>> scene = cylinder_scene(motion, times=(0.0, 18.0), radius=3.0, height=3.0,
    ...                        spacing=1.5, travel=2.0, n_radial=1, n_circumferential=4,
    ...                        n_axial=1)
    >>> scene.tagged.image.dims, scene.body().ncell
    (('tag', 'time', 'z', 'y', 'x'), 5)
    """
    inverse = getattr(motion, "inverse", None)
    if inverse is None:
        raise ValueError(f"motion {motion!r} has no exact inverse(x, t) method")
    half = radius + spacing
    ny = int(np.ceil(2 * half / spacing)) + 1
    nx = int(np.ceil((2 * half + travel) / spacing)) + 1
    nz = int(np.ceil((height + 2 * spacing) / spacing)) + 1
    origin = (-0.5 * (nz - 1) * spacing, -0.5 * (ny - 1) * spacing, -half)

    def density(X: FloatArray) -> FloatArray:
        inside = (np.hypot(X[:, 0], X[:, 1]) <= radius) & (np.abs(X[:, 2]) <= height / 2)
        return inside.astype(float)

    tagged = synthesize_tagged(
        motion,
        shape=(nz, ny, nx),
        spacing=(spacing, spacing, spacing),
        origin=origin,
        times=np.asarray(times, dtype=np.float64),
        tag_period=tag_period,
        tags=("x", "y", "z"),
        sequence=sequence,
        snr=snr,
        body=density,
        inverse=inverse,
        oversample=2,
        rng=np.random.default_rng(seed),
    )
    tagged.attrs["scene"] = f"cylinder/{type(motion).__name__}"
    mesh = cylinder(
        radius,
        height,
        n_radial=n_radial,
        n_circumferential=n_circumferential,
        n_axial=n_axial,
        center=(0.0, 0.0, -height / 2),
    )
    info = {"radius": radius, "height": height, "tag_period": tag_period, "snr": snr}
    return Scene(tagged, mesh, NeoHookean(c1=c1, kappa=kappa), motion, info)
