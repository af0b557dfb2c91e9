r"""Short-axis scene: a contracting, twisting, shortening tube seen by in-plane tags only.

The commonest clinical tagging protocol: a stack of short-axis (SA) slices normal to z, each
carrying x and y tags (CSPAMM), and nothing that sees motion along z. The scene is built to
show whether a tracker stays put along the direction no tag sees.

Ground truth
------------
A thick-walled tube (inner radius :math:`R_i`, outer :math:`R_o`, along z from its bottom
plane :math:`Z_0` over a length :math:`L`) deforms in closed form (:class:`ContractingTube`).
With the activation :math:`s(t) = \tfrac12(1 - \cos \pi t / T)` rising over the frames,
a reference point at cylindrical :math:`(R, \Theta, Z)` moves to

.. math::

    r = \sqrt{\frac{R^2 - a}{1 - e}}, \qquad
    \theta = \Theta + \tau \frac{Z - Z_0}{L}, \qquad
    z = Z_0 + (1 - e)(Z - Z_0),

with :math:`e = e_{max}\, s` the axial shortening, :math:`\tau = \tau_{max}\, s` the twist
at the top and :math:`a = R_i^2 - (1 - e)(R_i - c\, s)^2` chosen so that the inner wall
moves in by :math:`c\, s` mm. The map is volume preserving (:math:`\det F = 1`: the radial
map scales areas by :math:`1/(1 - e)`, the axial one lengths by :math:`1 - e`, the twist is
a shear), so the wall thickens as it contracts, as myocardium does, and a nearly
incompressible model can infer the through-plane shortening from the in-plane contraction.
The bottom plane :math:`Z = Z_0` does not move along z (the tube shortens towards it, as
the base of a ventricle descends towards a fixed apex); the scene states it as a boundary
condition (``scene.dirichlet``: the ``"bottom"`` face held in z). The exact inverse is used
to synthesise the images, so no numerical inversion is involved.

Images
------
CSPAMM, ``slices`` SA slices of ``slice_thickness`` mm (contiguous, boxcar profile) covering
the tube, tags along x and y with ``tag_period`` mm, ``pixel`` mm in plane, SNR 20, T1
fading: each slice synthesised on its own lattice by
:func:`harpx.imaging.synth.synthesize_tagged` and then resampled onto one isotropic grid of
``pixel`` mm by :func:`harpx.imaging.stacks.resample_stacks` (linear between slice centres,
nearest slice out to the slab faces). The ``mask`` of both tags is the slab of the stack (the
whole in-plane field of view, between the slab faces along z); the tissue at frame 0 is
``body``. ``displacement_true`` is the analytic motion at the voxel centres (NaN outside).

The tracking model is a hex8 tube mesh of the reference geometry with the paper's
neo-Hookean solid (C1 = 1 kPa, κ = 120 kPa).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import xarray as xr

from harpx._typing import FloatArray
from harpx.imaging.stacks import SliceStack, common_grid
from harpx.imaging.synth import synthesize_tagged, voxel_density
from harpx.mechanics.loads import Fixed
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import MeshSpec, tube
from harpx.scenes._common import MeshScene, cspamm_dataset
from harpx.scenes._motion import smooth_step
from harpx.tracking.results import tracking_error

__all__ = ["GEOMETRIES", "ContractingTube", "ShortAxisGeometry", "ShortAxisScene", "short_axis"]

Size = Literal["small", "paper"]


@dataclass(frozen=True)
class ContractingTube:
    """Closed-form contraction, twist and shortening of a tube along z (module notes).

    Parameters
    ----------
    inner_radius : float
        Reference inner radius :math:`R_i`, mm.
    bottom : float
        z of the bottom plane :math:`Z_0` (held along z), mm.
    length : float
        Reference length :math:`L`, mm.
    contraction : float
        Final inward motion :math:`c` of the inner wall, mm.
    shortening : float
        Final axial shortening :math:`e_{max}` (fraction of the length, in [0, 1)).
    twist : float
        Final rotation :math:`\\tau_{max}` of the top relative to the bottom about z, rad.
    duration : float
        Time :math:`T` over which the activation rises from 0 to 1, ms.
    """

    inner_radius: float = 20.0
    bottom: float = -14.0
    length: float = 28.0
    contraction: float = 5.0
    shortening: float = 0.12
    twist: float = 0.2
    duration: float = 300.0

    def _state(self, t: float) -> tuple[float, float, float]:
        s = float(smooth_step(np.asarray(t / self.duration)))
        e = self.shortening * s
        r_in = self.inner_radius - self.contraction * s
        a = self.inner_radius**2 - (1.0 - e) * r_in**2
        return e, self.twist * s, a

    def __call__(self, X: FloatArray, t: float) -> FloatArray:
        """Lagrangian displacement u(X, t) in mm at reference points ``X`` (n, 3) mm.

        Inside the cavity (:math:`R^2 < a`, no tissue) the radial map is clamped to the axis.
        """
        X = np.asarray(X, dtype=np.float64)
        e, tau, a = self._state(t)
        R2 = X[:, 0] ** 2 + X[:, 1] ** 2
        r = np.sqrt(np.maximum(R2 - a, 0.0) / (1.0 - e))
        theta = np.arctan2(X[:, 1], X[:, 0]) + tau * (X[:, 2] - self.bottom) / self.length
        x = np.column_stack(
            [
                r * np.cos(theta),
                r * np.sin(theta),
                self.bottom + (1.0 - e) * (X[:, 2] - self.bottom),
            ]
        )
        return np.asarray(x - X, dtype=np.float64)

    def inverse(self, x: FloatArray, t: float) -> FloatArray:
        """Reference position X(x, t) of the material point at ``x``.

        Parameters
        ----------
        x : ndarray, shape (n, 3)
            Spatial (deformed) positions, mm.
        t : float
            Time, ms.

        Returns
        -------
        ndarray, shape (n, 3)
            Reference positions, mm (exact for points in the deformed wall).
        """
        x = np.asarray(x, dtype=np.float64)
        e, tau, a = self._state(t)
        Z = self.bottom + (x[:, 2] - self.bottom) / (1.0 - e)
        R = np.sqrt((x[:, 0] ** 2 + x[:, 1] ** 2) * (1.0 - e) + a)
        theta = np.arctan2(x[:, 1], x[:, 0]) - tau * (Z - self.bottom) / self.length
        return np.column_stack([R * np.cos(theta), R * np.sin(theta), Z])


@dataclass(frozen=True)
class ShortAxisGeometry:
    """Sizes of one short-axis scene variant (lengths in mm, times in ms, angles in rad).

    Parameters
    ----------
    inner_radius, outer_radius, length : float
        Reference tube, mm (centred on z = 0 along z).
    slices : int
        Short-axis slices covering the tube.
    slice_thickness : float
        Slice thickness = slice spacing (contiguous slices), mm.
    pixel : float
        In-plane pixel and common grid spacing, mm.
    tag_period : float
        Tag spacing of both tags, mm.
    margin : float
        In-plane field of view beyond the outer radius, mm.
    frames, frame_interval : int, float
        Frame count and spacing, ms; the activation rises over all frames.
    contraction, shortening, twist : float
        Final motion (:class:`ContractingTube`).
    n_radial, n_circumferential, n_axial : int
        Cells of the tracking mesh.
    oversample : int
        Sub-samples per voxel and axis of the image synthesis.
    """

    inner_radius: float
    outer_radius: float
    length: float
    slices: int
    slice_thickness: float
    pixel: float
    tag_period: float
    margin: float
    frames: int
    frame_interval: float
    contraction: float
    shortening: float
    twist: float
    n_radial: int
    n_circumferential: int
    n_axial: int
    oversample: int


GEOMETRIES: dict[str, ShortAxisGeometry] = {
    # the clinical protocol: 4 SA slices of 8 mm, 1.17 mm pixels, 7 mm tags, 16 frames over
    # 300 ms; an LV-sized ring (cavity 40 mm, wall 10 mm) whose inner wall moves in 5 mm,
    # twisting 0.2 rad and shortening 12 % (3.4 mm at the top)
    "paper": ShortAxisGeometry(
        20.0, 30.0, 28.0, 4, 8.0, 1.17, 7.0, 6.0, 16, 20.0, 5.0, 0.12, 0.2, 3, 32, 4, 2
    ),
    # for tests: the same protocol on a smaller ring and 5 frames (the inner wall moves at
    # most 2 mm per frame, below half a tag period)
    "small": ShortAxisGeometry(
        12.0, 19.0, 28.0, 4, 8.0, 1.17, 7.0, 4.0, 5, 40.0, 3.0, 0.10, 0.15, 2, 16, 3, 2
    ),
}


@dataclass
class ShortAxisScene(MeshScene):
    """The short-axis scene: images, truth, tracking model and its boundary conditions.

    Attributes
    ----------
    tagged : xarray.Dataset
        ``tagged/1`` images (tags x and y) with ``mask`` (the slab), ``body`` and
        ``displacement_true``.
    mesh : MeshSpec
        The tracking tube (reference configuration, mm), facets ``"inner"``, ``"outer"``,
        ``"bottom"``, ``"top"``.
    material : object
        The tracking model's material.
    motion : ContractingTube
        The analytic ground truth, ``motion(X, t)`` in mm.
    dirichlet : tuple
        Boundary conditions the truth justifies: the bottom plane held along z.
    info : dict
        Scene settings.
    """

    tagged: xr.Dataset
    mesh: MeshSpec
    material: Any
    motion: ContractingTube
    dirichlet: tuple[Any, ...]
    info: dict = field(default_factory=dict)

    def error_split(self, tracked: xr.Dataset) -> xr.Dataset:
        """Tracking error split into the in-plane (x, y) and through-plane (z) parts.

        Parameters
        ----------
        tracked : xarray.Dataset
            ``tracked/1`` with ``displacement_grid`` (FE tracking or conventional HARP on
            the scene's grid).

        Returns
        -------
        xarray.Dataset
            ``in_plane_{mean,p95,max}`` and ``through_plane_{mean,p95,max}`` (time) with
            their ``*_all`` over frames 1.. (:func:`harpx.tracking.results.tracking_error`
            of the x-y and the z components, mm), and ``drift`` (time): the mean tracked
            z displacement minus the mean true one over the body voxels both cover, mm
            (a rigid drift along z shows here).
        """
        truth = self.tagged["displacement_true"]
        grid = tracked["displacement_grid"]
        out = xr.Dataset(coords={"time": truth["time"]})
        for part, axes in (("in_plane", ["x", "y"]), ("through_plane", ["z"])):
            err = tracking_error(
                xr.Dataset({"displacement_grid": grid.sel(axis=axes)}),
                xr.Dataset({"displacement_true": truth.sel(axis=axes)}),
            )
            for stat in ("mean", "p95", "max"):
                out[f"{part}_{stat}"] = err[stat]
                out[f"{part}_{stat}_all"] = err[f"{stat}_all"]
        est = grid.sel(axis="z").interp(z=truth.z, y=truth.y, x=truth.x)
        true = truth.sel(axis="z")
        both = np.isfinite(est.values) & np.isfinite(true.values)
        dims = tuple(range(1, true.ndim))
        count = both.sum(axis=dims)
        mean_est = np.where(both, est.values, 0.0).sum(axis=dims) / np.maximum(count, 1)
        mean_true = np.where(both, true.values, 0.0).sum(axis=dims) / np.maximum(count, 1)
        out["drift"] = xr.DataArray(
            np.where(count > 0, mean_est - mean_true, np.nan),
            dims="time",
            attrs={"units": "mm", "long_name": "mean tracked minus true z displacement"},
        )
        return out


def short_axis(size: Size = "paper", *, snr: float | None = 20.0, seed: int = 0) -> ShortAxisScene:
    """Build the short-axis scene: a contracting tube imaged by SA slices with x, y tags.

    Parameters
    ----------
    size : {"paper", "small"}, default "paper"
        ``"paper"``: an LV-sized ring, 16 frames, 1.17 mm pixels;
        ``"small"``: a smaller ring and 5 frames, for tests.
    snr : float or None, default 20
        Signal-to-noise ratio of the CSPAMM images (None: noise free).
    seed : int, default 0
        Seed of the image noise.

    Returns
    -------
    ShortAxisScene
        The CSPAMM images (tags x and y) with ``mask``, ``body`` and
        ``displacement_true``, the tracking tube and its neo-Hookean material, the
        analytic ``motion``, the boundary conditions (bottom held in z) and ``info``.

    Raises
    ------
    ValueError
        For an unknown size.

    Examples
    --------
    >>> from harpx.scenes.short_axis import GEOMETRIES
    >>> g = GEOMETRIES["paper"]
    >>> g.slices, g.slice_thickness, g.tag_period, g.pixel
    (4, 8.0, 7.0, 1.17)
    """
    if size not in GEOMETRIES:
        raise ValueError(f"size={size!r}; expected one of {sorted(GEOMETRIES)}")
    g = GEOMETRIES[size]
    times = np.arange(g.frames) * g.frame_interval
    bottom = -0.5 * g.length
    motion = ContractingTube(
        inner_radius=g.inner_radius,
        bottom=bottom,
        length=g.length,
        contraction=g.contraction,
        shortening=g.shortening,
        twist=g.twist,
        duration=float(times[-1]),
    )

    def density(X: FloatArray) -> FloatArray:
        R = np.hypot(X[:, 0], X[:, 1])
        inside = (R >= g.inner_radius) & (R <= g.outer_radius)
        inside &= (X[:, 2] >= bottom) & (X[:, 2] <= bottom + g.length)
        return inside.astype(np.float64)

    n_xy = 2 * int(np.ceil((g.outer_radius + g.margin) / g.pixel))
    xy0 = -0.5 * (n_xy - 1) * g.pixel
    z_sa = g.slice_thickness * (np.arange(g.slices) - 0.5 * (g.slices - 1))
    stack = synthesize_tagged(
        motion,
        shape=(g.slices, n_xy, n_xy),
        spacing=(g.slice_thickness, g.pixel, g.pixel),
        origin=(float(z_sa[0]), xy0, xy0),
        times=times,
        tag_period=g.tag_period,
        tags=("x", "y"),
        slice_axis="z",
        slice_thickness=g.slice_thickness,
        sequence="CSPAMM",
        snr=snr,
        body=density,
        inverse=motion.inverse,
        oversample=g.oversample,
        rng=np.random.default_rng(seed),
    )
    x, y, z = common_grid([SliceStack.axis_aligned(stack, "z")], g.pixel)
    body = voxel_density(density, (z, y, x), (g.pixel,) * 3, oversample=g.oversample)
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    voxels = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    truth = np.stack([motion(voxels, float(t)).T.reshape(3, *Z.shape) for t in times])
    truth[:, :, body < 0.5] = np.nan
    attrs: dict[str, Any] = {
        "scene": f"short_axis/{size}",
        "noise_sigma": float(stack.attrs["noise_sigma"]),
        "t1": float(stack.attrs["t1"]),
        "flip_angle": float(stack.attrs["flip_angle"]),
        "oversample": int(g.oversample),
        "sa_slice_positions_mm": z_sa,
        "sa_slice_thickness_mm": float(g.slice_thickness),
    }
    tagged = cspamm_dataset([stack], (z, y, x), truth, attrs, snr, body=body)
    mesh = tube(
        g.inner_radius,
        g.outer_radius,
        g.length,
        n_radial=g.n_radial,
        n_circumferential=g.n_circumferential,
        n_axial=g.n_axial,
        center=(0.0, 0.0, bottom),
    )
    info = {"size": size, "geometry": g, "snr": snr, "seed": seed}
    dirichlet = (Fixed("bottom", (2,)),)
    return ShortAxisScene(tagged, mesh, NeoHookean(c1=1.0, kappa=120.0), motion, dirichlet, info)
