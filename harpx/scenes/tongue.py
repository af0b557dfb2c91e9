"""Tongue scene: five activated muscles imaged with CSPAMM (paper §4.3).

A tongue-like body (:func:`harpx.anatomy.tongue_mesh.tongue`: genioglossus, inferior and
superior longitudinal, transverse and verticalis, each with its fibre directions; mandible
and hyoid/base attachments fixed) made of the paper's neo-Hookean solid (C1 = 1.0 kPa,
κ = 120 kPa) plus a Guccione--McCulloch active fibre stress whose level ``t_max`` is known
per muscle. The ground truth is a *forward* simulation
(:func:`harpx.physiology.active.simulate_activation`, Newton with cut-back) of the
activation rising linearly over the frames, run on a **finer** mesh than the 280-cell
tracking model (no inverse crime: other discretisation, other boundary polygon).

The motion is imaged like the paper's volunteer: CSPAMM, ten coronal slices carrying the y
and z tags and eight sagittal slices carrying the x tag, 1.9 mm pixels, 6 mm tags (the paper
does not state its tag spacing; 6 mm is the finest that 1.9 mm pixels resolve with the
half-frequency band-pass filter), four frames over which the activation rises, SNR 20, each stack
synthesised on its own slice lattice (partial volume, slice profile as thick as the slice
spacing, T1 fading, Gaussian noise; :func:`harpx.imaging.synth.synthesize_tagged`) and then
resampled onto one 1.9 mm grid by linear interpolation between slice centres (the
convention of :mod:`harpx.io.dicom`). The paper's 256 × 256 matrix spans a 486 mm field of
view; only its part around the tongue (plus a margin) holds tagged tissue, so the scene keeps
that part at the same 1.9 mm resolution. ``displacement_true`` is the fine finite-element
displacement at the voxel centres (NaN outside the tongue).

Axes: x posterior → anterior (tip at +x), y right → left, z inferior → superior; mm, ms.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Literal

import numpy as np
import xarray as xr

from harpx._typing import FloatArray
from harpx.anatomy.tongue_mesh import MUSCLES, tongue_inside
from harpx.anatomy.tongue_mesh import tongue as tongue_mesh
from harpx.imaging.harp import extract_phase
from harpx.imaging.synth import AcquisitionOptions, synthesize_tagged, voxel_density
from harpx.mechanics.body import Body, ElementName
from harpx.mechanics.fiber_laws import ActiveContraction
from harpx.mechanics.loads import Fixed
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import MeshSpec
from harpx.physiology.active import simulate_activation
from harpx.scenes._common import MeshScene, cspamm_dataset
from harpx.schema import standard_attrs
from harpx.tracking.resample import interpolate_displacement
from harpx.tracking.track import track

__all__ = ["ACTIVATIONS", "GEOMETRIES", "TongueGeometry", "TongueScene", "tongue"]

Size = Literal["small", "paper"]

#: ground-truth activation per muscle, kPa: a retraction with dorsum grooving that moves the
#: tip by ~8 mm and shortens every muscle by 3-10 % (fibre stretch 0.90-0.97)
ACTIVATIONS: dict[str, float] = {"GG": 2.0, "IL": 1.2, "SL": 1.5, "T": 1.0, "V": 0.8}


@dataclass(frozen=True)
class TongueGeometry:
    """Sizes of one tongue-scene variant (lengths in mm, times in ms).

    Parameters
    ----------
    length, width, height : float
        Tongue size (x, y, z), mm.
    divisions : tuple of int
        Cells of the tracking model along (ξ, η, ζ).
    truth_divisions : tuple of int
        Cells of the ground-truth mesh (a refinement with the same muscle map).
    truth_element : str
        Element of the ground-truth mesh.
    frames : int
        Frames, the activation rising linearly from 0 (rest) to the target.
    frame_interval : float
        Time between frames, ms.
    coronal_slices, sagittal_slices : int
        Slices of the two stacks (coronal: normal x, y and z tags; sagittal: normal y,
        x tag).
    pixel : float
        In-plane pixel size (and common grid spacing), mm.
    matrix : int
        Nominal in-plane matrix of the acquisition (its field of view is cropped to the
        tongue plus ``margin``).
    margin : float
        Field-of-view margin around the tongue, mm.
    tag_period : float
        Tag spacing, mm.
    oversample : int
        Sub-samples per voxel and axis of the image synthesis (partial volume).
    field_spacing : float
        Grid spacing of the ground-truth displacement handed to the image synthesis, mm.
    """

    length: float
    width: float
    height: float
    divisions: tuple[int, int, int]
    truth_divisions: tuple[int, int, int]
    truth_element: ElementName
    frames: int
    frame_interval: float
    coronal_slices: int
    sagittal_slices: int
    pixel: float
    matrix: int
    margin: float
    tag_period: float
    oversample: int
    field_spacing: float


GEOMETRIES: dict[str, TongueGeometry] = {
    # the paper's protocol; truth on the 2x refined mesh (2240 hex20)
    "paper": TongueGeometry(
        length=70.0,
        width=50.0,
        height=40.0,
        divisions=(10, 7, 4),
        truth_divisions=(20, 14, 8),
        truth_element="hex20",
        frames=4,
        frame_interval=60.0,
        coronal_slices=10,
        sagittal_slices=8,
        pixel=1.9,
        matrix=256,
        margin=10.0,
        tag_period=6.0,
        oversample=3,
        field_spacing=1.0,
    ),  # fmt: skip
}
# same protocol and tracking model; truth refined 2x along the length only (560 hex20),
# coarser partial-volume sampling
GEOMETRIES["small"] = replace(
    GEOMETRIES["paper"], truth_divisions=(20, 7, 4), oversample=2, field_spacing=1.5
)


@dataclass
class TongueScene(MeshScene):
    """A synthetic tongue scene: tagged images with ground truth and a model to track them.

    Attributes
    ----------
    tagged : xarray.Dataset
        ``tagged/1`` CSPAMM images with ``displacement_true``.
    mesh : MeshSpec
        The tracking mesh (280 cells, muscles as regions, fibres), mm.
    material : NeoHookean
        Passive material of the tracking model.
    law : ActiveContraction
        Active law of the ground truth (its ``t_max`` unused: see ``t_max``).
    t_max : dict of str to float
        True activation per muscle, kPa.
    dirichlet : tuple
        Boundary conditions of the tongue (mandible and hyoid/base attachments fixed).
    truth_body : Body
        The fine ground-truth model.
    truth_displacement : ndarray, shape (ntime, ndof)
        Its displacement per frame, mm.
    info : dict
        Scene settings.
    """

    tagged: xr.Dataset
    mesh: MeshSpec
    material: Any
    law: ActiveContraction
    t_max: dict[str, float]
    dirichlet: tuple[Any, ...]
    truth_body: Body
    truth_displacement: FloatArray
    info: dict = field(default_factory=dict)

    default_element: ClassVar[ElementName] = "hex20"

    def acquire(
        self,
        body: Body,
        displacement: FloatArray,
        *,
        snr: float | None | Literal["same"] = "same",
        seed: int = 1,
    ) -> xr.Dataset:
        """Image any motion of a tongue model with this scene's CSPAMM protocol.

        Parameters
        ----------
        body : Body
            Model whose dofs ``displacement`` refers to (e.g. the tracking model).
        displacement : ndarray, shape (ntime, ndof)
            Displacement per frame (frame 0 at rest), mm; frames at the scene's times.
        snr : float, None or "same", default "same"
            Image SNR; "same" uses the scene's.
        seed : int, default 1
            Noise seed (use one different from the scene's).

        Returns
        -------
        xarray.Dataset
            ``tagged/1`` on the scene's grid, with ``displacement_true`` of ``body``.
        """
        U = np.atleast_2d(np.asarray(displacement, dtype=np.float64))
        g = self.info["geometry"]
        times = np.asarray(self.tagged["time"].values[: U.shape[0]], dtype=np.float64)
        level = self.info["snr"] if snr == "same" else snr
        return _acquire(
            g, body, U, times, level, np.random.default_rng(seed), f"{self.info['size']}/acquired"
        )

    def track(self, body: Body, tagged: xr.Dataset | None = None, **settings: Any) -> xr.Dataset:
        """Phase extraction and tracking under the scene's boundary conditions.

        Parameters
        ----------
        body : Body
            The tracking model.
        tagged : xarray.Dataset, optional
            Images to track; default the scene's.
        **settings
            Tracking settings passed to :func:`harpx.tracking.track.track` (default: the
            tracker's defaults, as for every scene).

        Returns
        -------
        xarray.Dataset
            ``tracked/1``.
        """
        phase = extract_phase(self.tagged if tagged is None else tagged)
        return track(phase, body, dirichlet=list(self.dirichlet), **settings)

    def measure(
        self, body: Body, displacement: FloatArray, *, seed: int = 1, **settings: Any
    ) -> xr.Dataset:
        """Image a motion of ``body`` like the scene's data and track it the same way.

        The measurement chain for :func:`harpx.inverse.calibration.calibrate_activation`:
        ``self.track(body, self.acquire(body, displacement, seed=seed), **settings)``; pass
        the settings the data were tracked with.

        Parameters
        ----------
        body : Body
            Model whose dofs ``displacement`` refers to; it is also the tracking model.
        displacement : ndarray, shape (ntime, ndof)
            Displacement per frame (frame 0 at rest), mm, as in :meth:`acquire`.
        seed : int, default 1
            Noise seed of the images (use one different from the scene's).
        **settings
            Tracking settings passed to :func:`harpx.tracking.track.track`, as in
            :meth:`track`.

        Returns
        -------
        xarray.Dataset
            ``tracked/1`` of the imaged motion.
        """
        return self.track(body, self.acquire(body, displacement, seed=seed), **settings)

    def true_fiber_stretch(self, body: Body) -> xr.DataArray:
        """Fibre stretch per cell of ``body`` under the true motion, (time, cell).

        The fine ground-truth displacement is interpolated at ``body``'s dof nodes: the
        stretch a perfect tracker would report on that model.

        Parameters
        ----------
        body : Body
            Model with fibres over the scene's tongue (e.g. the tracking model); its dof
            nodes just outside the fine mesh take the displacement of the nearest node
            inside.

        Returns
        -------
        xarray.DataArray, shape (time, cell)
            Fibre stretch of each cell of ``body`` (dimensionless) at the scene's frame
            times (ms).
        """
        values, inside = interpolate_displacement(
            self.truth_body, self.truth_displacement, body.dof_points
        )
        if not inside.all():  # nodes on the coarse boundary polygon just outside the fine one
            near = _nearest_inside(body.dof_points, inside)
            values[:, ~inside] = values[:, near]
        lam = np.stack([body.fiber_stretch(u.ravel()) for u in values])
        return xr.DataArray(
            lam,
            dims=("time", "cell"),
            coords={"time": self.tagged["time"].values},
            attrs=standard_attrs("fiber_stretch"),
        )

    def true_stretch_by_muscle(self, body: Body, time: int = -1) -> dict[str, float]:
        """Volume-weighted mean true fibre stretch of each muscle on ``body``'s cells.

        Parameters
        ----------
        body : Body
            Model with fibres whose regions are the muscles, as in
            :meth:`true_fiber_stretch`.
        time : int, default -1
            Frame index (the last, full activation, by default).

        Returns
        -------
        dict of str to float
            Mean fibre stretch (dimensionless) per region of ``body``, weighted by the
            reference cell volumes.
        """
        lam = self.true_fiber_stretch(body).isel(time=time).values
        w = body.cell_volume
        return {
            name: float(np.average(lam[ids], weights=w[ids])) for name, ids in body.regions.items()
        }


def _nearest_inside(points: FloatArray, inside: np.ndarray) -> np.ndarray:
    from scipy.spatial import cKDTree

    idx = np.nonzero(inside)[0]
    _, k = cKDTree(points[idx]).query(points[~inside])
    return idx[k]


def _ground_truth(
    g: TongueGeometry,
    t_max: Mapping[str, float],
    material: Any,
    law: ActiveContraction,
    dirichlet: tuple[Any, ...],
) -> tuple[Body, FloatArray]:
    """Forward simulation of the activation ramp on the fine mesh: (body, U (frames, ndof)).

    Cached per process (all arguments are immutable), so a test module and a tutorial in
    one session solve it once; the displacement is returned as a fresh copy.
    """
    body, U = _ground_truth_cached(g, tuple(sorted(t_max.items())), material, law, dirichlet)
    return body, U.copy()


@functools.lru_cache(maxsize=4)
def _ground_truth_cached(
    g: TongueGeometry,
    t_max: tuple[tuple[str, float], ...],
    material: Any,
    law: ActiveContraction,
    dirichlet: tuple[Any, ...],
) -> tuple[Body, FloatArray]:
    spec = tongue_mesh(length=g.length, width=g.width, height=g.height, divisions=g.truth_divisions)
    body = Body(spec, material, element=g.truth_element, active=law, t_max=0.0)
    U = np.zeros((g.frames, body.ndof))
    target = dict(t_max)
    for n in range(1, g.frames):  # each frame continues from the previous one
        f0, f1 = (n - 1) / (g.frames - 1), n / (g.frames - 1)
        result = simulate_activation(
            body,
            {k: f1 * v for k, v in target.items()},
            loads=dirichlet,
            steps=1,
            u0=U[n - 1],
            t_start={k: f0 * v for k, v in target.items()},
        )
        U[n] = result.u
    return body, U


def _smooth_extension(values: np.ndarray, inside: np.ndarray, width: float = 2.0) -> np.ndarray:
    """Extend a field (..., z, y, x) from ``inside`` voxels continuously to the whole grid.

    Nearest-voxel fill, then a Gaussian blur (``width`` voxels) of the outside voxels only
    (the inside values are kept): a slowly varying extension, so that the image synthesis
    can invert the motion everywhere (a nearest fill alone leaves jumps that fold).
    """
    from scipy import ndimage

    idx = ndimage.distance_transform_edt(~inside, return_distances=False, return_indices=True)
    filled = values[(..., *idx)]
    lead = filled.ndim - 3
    blurred = ndimage.gaussian_filter(filled, sigma=(0,) * lead + (width,) * 3, mode="nearest")
    return np.where(inside, filled, blurred)


def _interpolate_truth(
    body: Body, U: FloatArray, points: FloatArray
) -> tuple[FloatArray, np.ndarray]:
    """FE displacement (ntime, n, 3) at points, NaN outside; only points near the mesh located."""
    lo = body.nodes.min(axis=0) - 1e-6
    hi = body.nodes.max(axis=0) + 1e-6
    near = np.nonzero(np.all((points >= lo) & (points <= hi), axis=1))[0]
    out = np.full((U.shape[0], points.shape[0], 3), np.nan)
    inside = np.zeros(points.shape[0], dtype=bool)
    out[:, near], inside[near] = interpolate_displacement(body, U, points[near])
    return out, inside


def _axis_lattice(lo: float, hi: float, step: float) -> FloatArray:
    """Voxel centres with spacing ``step`` covering [lo, hi] symmetrically, mm."""
    n = int(np.ceil((hi - lo) / step)) + 1
    mid = 0.5 * (lo + hi)
    return mid + step * (np.arange(n, dtype=np.float64) - 0.5 * (n - 1))


def _slice_centres(lo: float, hi: float, count: int) -> tuple[FloatArray, float]:
    spacing = (hi - lo) / count
    return lo + spacing * (np.arange(count, dtype=np.float64) + 0.5), spacing


def _acquire(
    g: TongueGeometry,
    truth_body: Body,
    U: FloatArray,
    times: FloatArray,
    snr: float | None,
    rng: np.random.Generator,
    size: str,
) -> xr.Dataset:
    """Image the motion ``U`` of ``truth_body`` with the scene's CSPAMM protocol (tagged/1)."""
    # common 1.9 mm grid around the tongue and the two slice stacks
    m = g.margin
    x = _axis_lattice(-m, g.length + m, g.pixel)
    y = _axis_lattice(-0.5 * g.width - m, 0.5 * g.width + m, g.pixel)
    z = _axis_lattice(-m, g.height + m, g.pixel)
    cor, dx_cor = _slice_centres(-2.0, g.length + 2.0, g.coronal_slices)
    sag, dy_sag = _slice_centres(-0.5 * g.width - 2.0, 0.5 * g.width + 2.0, g.sagittal_slices)

    # the motion as a gridded field for the image synthesis, extended smoothly outside the mesh
    fine = {
        d: _axis_lattice(lo, hi, g.field_spacing)
        for d, (lo, hi) in {
            "x": (-m, g.length + m),
            "y": (-0.5 * g.width - m, 0.5 * g.width + m),
            "z": (-m, g.height + m),
        }.items()
    }
    Zf, Yf, Xf = np.meshgrid(fine["z"], fine["y"], fine["x"], indexing="ij")
    pts = np.column_stack([Xf.ravel(), Yf.ravel(), Zf.ravel()])
    uf, known = _interpolate_truth(truth_body, U, pts)
    grid_u = _smooth_extension(
        uf.reshape(U.shape[0], *Zf.shape, 3).transpose(0, 4, 1, 2, 3), known.reshape(Zf.shape)
    )
    field_ = xr.DataArray(
        grid_u,
        dims=("time", "axis", "z", "y", "x"),
        coords={"time": times, "axis": ["x", "y", "z"], **fine},
    )

    def density(X: FloatArray) -> FloatArray:
        return tongue_inside(X, g.length, g.width, g.height).astype(np.float64)

    common = AcquisitionOptions(
        times=times,
        tag_period=g.tag_period,
        sequence="CSPAMM",
        snr=snr,
        body=density,
        rng=rng,
        oversample=g.oversample,
    )
    coronal = synthesize_tagged(
        field_,
        shape=(z.size, y.size, cor.size),
        spacing=(g.pixel, g.pixel, dx_cor),
        origin=(z[0], y[0], cor[0]),
        tags=("y", "z"),
        slice_axis="x",
        **common,
    )
    sagittal = synthesize_tagged(
        field_,
        shape=(z.size, sag.size, x.size),
        spacing=(g.pixel, dy_sag, g.pixel),
        origin=(z[0], sag[0], x[0]),
        tags=("x",),
        slice_axis="y",
        **common,
    )
    rho = voxel_density(density, (z, y, x), (g.pixel,) * 3, oversample=2)
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    vox = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    ut, _ = _interpolate_truth(truth_body, U, vox)
    truth = ut.reshape(U.shape[0], *Z.shape, 3).transpose(0, 4, 1, 2, 3)
    truth[:, :, rho < 0.5] = np.nan
    attrs: dict[str, Any] = {
        "scene": f"tongue/{size}",
        "noise_sigma": float(coronal.attrs["noise_sigma"]),
        "coronal_slices": int(cor.size),
        "sagittal_slices": int(sag.size),
        "coronal_slice_spacing": float(dx_cor),
        "sagittal_slice_spacing": float(dy_sag),
    }
    return cspamm_dataset([sagittal, coronal], (z, y, x), truth, attrs, snr, body=rho)


def tongue(
    size: Size = "paper",
    *,
    snr: float | None = 20.0,
    seed: int = 0,
    activations: Mapping[str, float] | None = None,
) -> TongueScene:
    """Build the tongue scene: known muscle activations, their motion, CSPAMM images.

    Parameters
    ----------
    size : {"paper", "small"}, default "paper"
        ``"paper"``: ground truth on a 2x refined mesh (2240 hex20 cells);
        ``"small"``: ground truth refined 2x along the length only (560 hex20 cells).
        Both image the paper's protocol (10 coronal + 8 sagittal CSPAMM slices,
        1.9 mm pixels) and track with the paper's 280-cell hex20 model.
    snr : float or None, default 20
        Signal-to-noise ratio of the CSPAMM images (None: noise free).
    seed : int, default 0
        Seed of the image noise.
    activations : dict of str to float, optional
        True ``t_max`` per muscle in kPa (keys among ``"GG", "IL", "SL", "T", "V"``);
        default :data:`ACTIVATIONS`.

    Returns
    -------
    TongueScene
        The CSPAMM images with ``displacement_true``, the 280-cell tracking mesh and its
        neo-Hookean material, the active law, the true ``t_max`` per muscle (kPa), the
        boundary conditions, the ground-truth model and its displacement, and ``info``.

    Raises
    ------
    ValueError
        For an unknown size, muscle name or a negative activation.

    Examples
    --------
    >>> from harpx.scenes.tongue import ACTIVATIONS, GEOMETRIES
    >>> sorted(ACTIVATIONS), GEOMETRIES["paper"].coronal_slices
    (['GG', 'IL', 'SL', 'T', 'V'], 10)
    """
    if size not in GEOMETRIES:
        raise ValueError(f"size={size!r}; expected one of {sorted(GEOMETRIES)}")
    t_max = dict(ACTIVATIONS if activations is None else activations)
    for name, value in t_max.items():
        if name not in MUSCLES:
            raise ValueError(f"activations names {name!r}, which is not one of {sorted(MUSCLES)!r}")
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"activation {name!r}={value!r} must be a non-negative number (kPa)")
    g = GEOMETRIES[size]
    material = NeoHookean(c1=1.0, kappa=120.0)
    law = ActiveContraction(t_max=0.0)
    dirichlet = (Fixed("mandible"), Fixed("base"))
    truth_body, U = _ground_truth(g, t_max, material, law, dirichlet)
    times = np.arange(g.frames, dtype=np.float64) * g.frame_interval

    tagged = _acquire(g, truth_body, U, times, snr, np.random.default_rng(seed), size)
    mesh = tongue_mesh(length=g.length, width=g.width, height=g.height, divisions=g.divisions)
    info = {"size": size, "geometry": g, "snr": snr, "seed": seed}
    return TongueScene(tagged, mesh, material, law, t_max, dirichlet, truth_body, U, info)
