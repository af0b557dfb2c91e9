"""Brain-phantom scene: a gel cylinder in a container that turns suddenly (paper §4.1).

A Sylgard-like cylinder (neo-Hookean, C1 = 1.0 kPa, κ = 120 kPa) sits in a container whose
base receives a sudden rotational acceleration; it is imaged like the paper's phantom
(13 frames, TR 18 ms, 13 axial slices, 160 × 160 pixels of 1.5 mm, SPAMM, three tag
directions; the z tag, which axial slices cannot see, is acquired in coronal slices normal
to y on the same grid). The ground truth is an analytic, volume-preserving lagged rotation
(:class:`harpx.scenes._motion.RotationalImpact`) that the finite-element model does not
share: its surface is traction free in reality, its edge moves more than a tag period, and
near the wall one frame moves more than half a tag period.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import xarray as xr

from harpx.imaging.synth import synthesize_tagged
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import MeshSpec, cylinder
from harpx.scenes._common import MeshScene
from harpx.scenes._motion import RotationalImpact

__all__ = ["PhantomGeometry", "Scene", "phantom"]

Size = Literal["small", "paper"]


@dataclass(frozen=True)
class PhantomGeometry:
    """Sizes of one phantom variant (lengths in mm, times in ms).

    Parameters
    ----------
    radius : float
        Radius of the gel cylinder (the container's inner radius), mm.
    height : float
        Height of the cylinder, mm; it spans z from ``-height/2`` to ``height/2``.
    frames : int
        Number of frames, the first at t = 0 (rest).
    repetition_time : float
        Time between frames, ms.
    slices : int
        Axial slices (normal to z) of the image stack.
    slice_spacing : float
        Slice spacing along z, mm.
    matrix : int
        In-plane matrix: ``matrix × matrix`` pixels.
    pixel : float
        In-plane pixel size, mm.
    tag_period : float
        Tag spacing of the three tags (x, y, z), mm.
    n_circumferential, n_radial, n_axial : int
        Cells of the tracking mesh (:func:`~harpx.mechanics.mesh.cylinder`): around the
        circumference (a multiple of 4), in the rings between the square core and the
        circle, and along z.
    angle : float
        Final rotation of the container, rad.
    rise_time : float
        Duration of the container's acceleration ramp, ms.
    """

    radius: float
    height: float
    frames: int
    repetition_time: float
    slices: int
    slice_spacing: float
    matrix: int
    pixel: float
    tag_period: float
    n_circumferential: int
    n_radial: int
    n_axial: int
    angle: float
    rise_time: float


GEOMETRIES: dict[str, PhantomGeometry] = {
    # the paper's acquisition (1.5 mm isotropic voxels); 48 x 6 rings + 12 x 12 core,
    # 10 layers: 4320 hexahedra
    # the container turns 0.2 rad over 72 ms: the edge moves 12 mm (1.5 tag periods),
    # 4.2 mm (> half a period) in its fastest frame
    "paper": PhantomGeometry(60.0, 15.0, 13, 18.0, 13, 1.5, 160, 1.5, 8.0, 48, 6, 10, 0.2, 72.0),
    # a reduced scene for tests and tutorials with the same difficulty: 6 mm tags, the
    # container turns 0.3 rad over 36 ms, so the edge steps 3.6 and 4.6 mm (> half a
    # period) in consecutive frames
    "small": PhantomGeometry(24.0, 7.5, 5, 18.0, 7, 1.5, 48, 1.5, 6.0, 24, 3, 4, 0.3, 36.0),
}


@dataclass
class Scene(MeshScene):
    """A synthetic scene: tagged images with ground truth and a model to track them.

    Attributes
    ----------
    tagged : xarray.Dataset
        ``tagged/1`` images with ``displacement_true``.
    mesh : MeshSpec
        The tracking mesh (reference configuration, mm).
    material : object
        The tracking model's material.
    motion : object
        The analytic ground-truth motion, ``motion(X, t)`` in mm.
    info : dict
        Scene settings.
    """

    tagged: xr.Dataset
    mesh: MeshSpec
    material: Any
    motion: Any
    info: dict = field(default_factory=dict)


def phantom(
    size: Size = "paper",
    *,
    sequence: Literal["SPAMM", "CSPAMM"] = "SPAMM",
    snr: float | None = 20.0,
    c1: float = 1.0,
    kappa: float = 120.0,
    motion: RotationalImpact | None = None,
    seed: int = 0,
) -> Scene:
    """Build the brain-phantom scene.

    Parameters
    ----------
    size : {"paper", "small"}, default "paper"
        ``"paper"``: 13 frames × 13 slices × 160² voxels of 1.5 mm and a 4320-cell model;
        ``"small"``: 5 frames × 7 slices × 48² and a 432-cell model, for tests.
    sequence : {"SPAMM", "CSPAMM"}, default "SPAMM"
        Tagging sequence (the paper's phantom used SPAMM).
    snr : float or None, default 20
        Signal-to-noise ratio of the images (None: noise free).
    c1, kappa : float
        Material of the tracking model, kPa (paper: 1.0 and 120).
    motion : RotationalImpact, optional
        Ground-truth motion; default: for ``"paper"`` the container turns 0.2 rad (11.5°)
        in 72 ms, so the edge moves 12 mm (1.5 tag periods), 4.2 mm in its fastest frame;
        for ``"small"`` it turns 0.3 rad in 36 ms with 6 mm tags (edge steps of 4.6 mm).
    seed : int, default 0
        Seed of the image noise.

    Returns
    -------
    Scene
        The SPAMM or CSPAMM ``tagged`` images (tags x, y, z) with ``displacement_true``,
        the tracking ``mesh`` (a cylinder of the phantom's size), its neo-Hookean
        ``material``, the ground-truth ``motion`` and the settings in ``info``.

    Raises
    ------
    ValueError
        If ``size`` is not one of the geometries' names.

    Examples
    --------
    The small scene without noise: its images, its tracking mesh and the largest true
    displacement of each frame, in tag periods:

    >>> from harpx.scenes.phantom import phantom
    >>> scene = phantom("small", snr=None)
    >>> dict(scene.tagged["image"].sizes), scene.mesh.mesh.nelements, sorted(scene.mesh.boundaries)
    ({'tag': 3, 'time': 5, 'z': 7, 'y': 48, 'x': 48}, 432, ['bottom', 'outer', 'top'])
    >>> u = scene.tagged["displacement_true"]  # (time, axis, z, y, x) mm, NaN outside the gel
    >>> reach = ((u**2).sum("axis") ** 0.5).max(["z", "y", "x"])
    >>> (reach / scene.info["geometry"].tag_period).round(1).values.tolist()
    [0.0, 0.6, 1.2, 1.2, 1.2]
    """
    if size not in GEOMETRIES:
        raise ValueError(f"size={size!r}; expected one of {sorted(GEOMETRIES)}")
    g = GEOMETRIES[size]
    base = -g.height / 2
    if motion is None:
        motion = RotationalImpact(
            radius=g.radius, base=base, height=g.height, angle=g.angle, rise_time=g.rise_time
        )
    times = np.arange(g.frames) * g.repetition_time
    radius, z0, z1 = g.radius, base, base + g.height

    def density(X: np.ndarray) -> np.ndarray:
        inside = (np.hypot(X[:, 0], X[:, 1]) <= radius) & (X[:, 2] >= z0) & (X[:, 2] <= z1)
        return inside.astype(float)

    spacing = (g.slice_spacing, g.pixel, g.pixel)
    shape = (g.slices, g.matrix, g.matrix)
    tagged = synthesize_tagged(
        motion,
        shape=shape,
        spacing=spacing,
        times=times,
        tag_period=g.tag_period,
        tags=("x", "y", "z"),
        sequence=sequence,
        snr=snr,
        body=density,
        inverse=motion.inverse,
        oversample=2,
        rng=np.random.default_rng(seed),
    )
    tagged.attrs["scene"] = f"phantom/{size}"
    mesh = cylinder(g.radius, g.height, n_radial=g.n_radial,
                    n_circumferential=g.n_circumferential, n_axial=g.n_axial,
                    center=(0.0, 0.0, base))  # fmt: skip
    info = {"size": size, "geometry": g, "sequence": sequence, "snr": snr, "seed": seed}
    return Scene(tagged, mesh, NeoHookean(c1=c1, kappa=kappa), motion, info)
