r"""Left-ventricle scene: residually stressed myocardium tracked through CSPAMM (paper §4.2).

Ground truth
------------
A systolic sequence is *simulated* on a finer hexahedral mesh of the same truncated
ellipsoid (:func:`harpx.anatomy.ventricle.ventricle`) than the tracking model, so the
tracker never shares the truth's discretisation (no inverse crime):

* passive myocardium: uncoupled transversely isotropic Guccione law with the canine values
  of Guccione et al. (1991, 1995): ``C = 0.88 kPa, bf = 18.5, bt = 3.58, bfs = 1.63`` and a
  bulk modulus ``κ = 350 kPa`` (``κ/C ≈ 400``: nearly incompressible, mean dilatation);
* active fibre stress: the length-dependent calcium law of Guccione & McCulloch (1993)
  (:class:`~harpx.mechanics.fiber_laws.ActiveContraction`) with a level that rises from 0
  to ``t_max`` over the frames;
* cavity pressure on ``"endo"`` (follower load) rising in proportion to the activation
  (isovolumic contraction and ejection lumped into one quasi-static path);
* the base held in z (``Fixed("base", (2,))``) and pinned in-plane at four mid-wall points
  (x-pins at ±y, y-pins at ±x), which removes the in-plane rigid motions.

A regional infarct (``lv(infarct=(7, 8, 13, 14))``: mid anterior, mid anteroseptal,
apical anterior, apical septal, the territory of the left anterior descending artery)
scales the active tension of the truth cells whose centre lies in the given AHA segments by
``scar_activation``. The segments are those :func:`harpx.cardiac.strain.aha_segments`
gives with the scene's exact template (:meth:`LVScene.template`: anterior wall at +y,
:data:`ANTERIOR`; :func:`aha_segment`), the border between infarct and healthy tissue is
sharp (on cell faces of the truth mesh) and the infarct keeps the healthy passive material.
With no active tension at all (``scar_activation=0``) the soft passive myocardium
(C = 0.88 kPa) bulges under the 8 kPa cavity pressure (dyskinesis: peak Ecc about +0.2 in
the infarct at small size); half the tension leaves it hypokinetic (peak Ecc −0.03 to
−0.06 against −0.11 to −0.14 elsewhere).

The activation level :math:`a` (active tension :math:`a\,t_{max}`, cavity pressure
:math:`a\,p_{es}`) is continued from 0 to 1 by Newton's method on the fine mesh; the frame
levels are then chosen so that the ejected volume follows a smooth ejection curve
:math:`(1 - \cos \pi s)/2` over equally spaced frames
(:func:`~harpx.scenes._lv_truth.simulate_systole`). Frame 0 is the stress-free, unloaded
reference (the images' reference geometry).

Images
------
Like the paper's acquisition: CSPAMM, short-axis (SA) slices normal to z carrying the x and
y tags and long-axis (LA) slices normal to y carrying the z tag, with in-plane pixels of
``pixel`` mm and contiguous slices (boxcar profile) covering the heart. Each stack is
synthesised by :func:`harpx.imaging.synth.synthesize_tagged` from the exact finite-element
motion (Eulerian resampling: the reference position of the tissue at every image sample is
found by point location in the deformed fine mesh), then resampled onto one common
isotropic grid by linear interpolation between slice centres, with per-tag masks marking
each stack's slab (as :func:`harpx.io.dicom.read_tagged` does for scanner data). The SA
stack spans the cavity, from its apex to the base; the apical cap below it (AHA segment 17,
which short-axis analyses leave out) is imaged by the LA slices only. There SA slices would
cut the nearly horizontal wall obliquely: averaged over the slice thickness, its x and y
tag phases are off by about a radian at end systole, enough to fold
the model's apex under a high penalty. The model's apical cap is then pulled by the
long-axis tag alone where LA slices image it (a constraint point keeps the tags whose masks
hold it) and otherwise follows the mechanics. The
paper's 256 × 256 matrix (320 mm field of view) is cropped to the region around the heart
(same pixel size and hence same resolution; the rest of the field of view is empty).
``displacement_true`` is the fine-mesh displacement at the voxel centres, NaN outside.

Tracking models
---------------
The coarser tracking mesh carries the same passive material (no active stress: the images
drive it). Two references:

* ``"stress-free"`` (SFR): the image geometry at frame 0 is stress free.
* ``"prestretched"`` (PSR): the same geometry carries residual stress from a growth field
  (:func:`~harpx.physiology.growth.prestretch_growth`): fibres are *compressed in situ* by a
  mean of 5 %
  (``mean=-0.05``: in-situ fibre length / stress-free fibre length − 1, averaged over the
  wall), more at the endocardium than at the epicardium (``gradient``), as residual-strain
  measurements show (Omens & Fung 1990). The growth field is equilibrated with the base
  held (the FEBio-style prestrain update of Maas et al. 2016: grow, equilibrate, pull the
  equilibrium strain back into the growth tensor, repeat) so that the *reference geometry
  stays the image geometry at frame 0* while it is residually stressed; tracking then starts
  from that stressed state (``u = 0`` is its equilibrium).

References
----------
.. [1] Guccione JM, McCulloch AD, Waldman LK. Passive material properties of intact
   ventricular myocardium determined from a cylindrical model. J Biomech Eng 113:42--55,
   1991.
.. [2] Guccione JM, Costa KD, McCulloch AD. Finite element stress analysis of left
   ventricular mechanics in the beating dog heart. J Biomech 28:1167--1177, 1995.
.. [3] Guccione JM, McCulloch AD. Mechanics of active contraction in cardiac muscle.
   J Biomech Eng 115:72--81, 1993.
.. [4] Omens JH, Fung YC. Residual strain in rat left ventricle. Circ Res 66:37--45, 1990.
.. [5] Maas SA, Erdemir A, Halloran JP, Weiss JA. A general framework for application of
   prestrain to computational models of biological materials. J Mech Behav Biomed Mater
   61:499--510, 2016.
.. [6] Cerqueira MD et al. Standardized myocardial segmentation and nomenclature for
   tomographic imaging of the heart. Circulation 105:539--542, 2002.
"""

from __future__ import annotations

import time as _time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import xarray as xr

from harpx._typing import FloatArray, IntArray
from harpx.anatomy.aha import segments_local
from harpx.anatomy.ventricle import VentricleGeometry
from harpx.anatomy.ventricle_fit import VentricleTemplate
from harpx.imaging.synth import AcquisitionOptions, synthesize_tagged
from harpx.mechanics.body import Body
from harpx.mechanics.fiber_laws import ActiveContraction
from harpx.mechanics.loads import Fixed
from harpx.mechanics.materials import Guccione
from harpx.mechanics.mesh import MeshSpec
from harpx.physiology.cut import NodeFixed
from harpx.physiology.growth import GrowthField, fiber_prestretch, prestretch_growth
from harpx.scenes._common import cspamm_dataset
from harpx.scenes._lv_truth import FEMotion, Systole, simulate_systole

__all__ = [
    "ANTERIOR",
    "FEMotion",
    "LVScene",
    "SIZES",
    "Systole",
    "aha_segment",
    "fiber_shortening",
    "lv",
    "myocardium",
    "simulate_systole",
]

Reference = Literal["stress-free", "prestretched"]
Size = Literal["small", "paper"]

#: the ventricle of both sizes (mm): cavity 50 mm wide, wall 8--10 mm, base 10 mm above
#: the equator
GEOMETRY = VentricleGeometry(inner=(25.0, 70.0), outer=(35.0, 78.0), truncation=10.0)
#: direction of the anterior wall, degrees about +z from +x (the scene has no right
#: ventricle; +y puts the 60° sector borders on node lines of both meshes)
ANTERIOR = 90.0


def myocardium(kappa: float = 350.0) -> Guccione:
    """Passive canine myocardium of Guccione et al. (1991, 1995).

    Parameters
    ----------
    kappa : float, default 350
        Bulk modulus in kPa (typical values 100--350 kPa keep ``κ/C`` in the hundreds).

    Returns
    -------
    Guccione
        ``C = 0.88 kPa, bf = 18.5, bt = 3.58, bfs = 1.63``.

    Examples
    --------
    >>> from harpx.scenes.lv import myocardium
    >>> myocardium().c, myocardium().bf
    (0.88, 18.5)
    """
    return Guccione(c=0.88, bf=18.5, bt=3.58, bfs=1.63, kappa=kappa)


@dataclass(frozen=True)
class LVSize:
    """Discretisation and acquisition of one scene size (lengths in mm, times in ms)."""

    tracking: tuple[int, int, int]  # (circumferential, longitudinal, transmural) cells
    truth: tuple[int, int, int]
    frames: int
    frame_interval: float
    pixel: float
    sa_slices: int
    la_slices: int
    tag_period: float
    margin: float
    oversample: int


SIZES: dict[str, LVSize] = {
    # the paper's acquisition: 12 SA and 8 LA slices, 1.25 mm pixels, 6528-cell hex8 model;
    # truth on a mesh 4/3 finer in-plane and 5/4 across the wall (14.7 k cells)
    "paper": LVSize((48, 27, 4), (64, 36, 5), 10, 30.0, 1.25, 12, 8, 8.0, 6.0, 2),
    # reduced for tests and tutorials: same heart and physics, coarser everything; 24 cells
    # around put a cell border on every AHA sector border (anterior +y), the truth 36
    "small": LVSize((24, 6, 2), (36, 9, 3), 5, 60.0, 2.0, 8, 6, 8.0, 6.0, 2),
}


def base_conditions(geometry: VentricleGeometry = GEOMETRY) -> list[Any]:
    """Base held in z plus four in-plane pins at mid-wall (removes the rigid motions).

    Parameters
    ----------
    geometry : VentricleGeometry
        The ventricle (base plane and mid-wall radius there), mm.

    Returns
    -------
    list
        ``[Fixed("base", (2,)), NodeFixed(...)]``: u_y = 0 at the mid-wall base nodes on
        ±x, u_x = 0 at those on ±y.
    """
    a, c = (float(v) for v in geometry.semi_axes(0.5))
    zb = geometry.truncation
    r = a * np.sqrt(max(0.0, 1.0 - (zb / c) ** 2))
    pins = NodeFixed(
        np.array([[r, 0.0, zb], [0.0, r, zb], [-r, 0.0, zb], [0.0, -r, zb]]), (1, 0, 1, 0)
    )
    return [Fixed("base", (2,)), pins]


def aha_segment(points: FloatArray, template: VentricleTemplate) -> IntArray:
    """AHA segment (1--17) of points (:func:`harpx.anatomy.aha.segments_local`).

    :func:`harpx.cardiac.strain.aha_segments` with the template's ``anterior`` angle, which
    the scene layer cannot import: the cavity from the endocardial apex
    :math:`z = -c_{endo}` to the base plane (template coordinates) is cut into thirds;
    segments 1, 7 and 13 are centred on ``anterior`` and the numbers run clockwise about
    the template's +z (counter-clockwise seen from the apex), six 60° sectors in the basal
    and mid thirds, four 90° sectors in the apical third, 17 below the cavity
    (Cerqueira et al. 2002). ``tests/scenes/test_infarct.py`` checks that both agree.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Image points (x, y, z), mm.
    template : VentricleTemplate
        The ventricle (frame and thirds) with its ``anterior`` angle in degrees (None: 0).

    Returns
    -------
    ndarray of int, shape (n,)
        Segment numbers 1..17 (points above the base plane count as basal).

    Examples
    --------
    >>> from harpx.anatomy.ventricle_fit import VentricleTemplate
    >>> from harpx.scenes.lv import GEOMETRY, aha_segment
    >>> t = VentricleTemplate(GEOMETRY, anterior=90.0)  # anterior wall +y, septum +x
    >>> aha_segment(np.array([[1.0, 30.0, 0.0], [30.0, -1.0, -40.0], [0.0, 0.0, -74.0]]), t)
    array([ 1,  9, 17])
    """
    return segments_local(template.to_local(points), template.geometry, template.anterior or 0.0)


def _infarct_tension(
    centres: FloatArray, infarct: Sequence[int], scar_activation: float
) -> FloatArray | None:
    """Per-cell active tension factor: ``scar_activation`` in the infarct, 1 elsewhere."""
    if not infarct:
        return None
    inside = np.isin(aha_segment(centres, _template(GEOMETRY)), np.asarray(infarct))
    return np.where(inside, float(scar_activation), 1.0)


def _template(geometry: VentricleGeometry) -> VentricleTemplate:
    return VentricleTemplate(geometry, anterior=ANTERIOR)


# ------------------------------------------------------------------------------ images


def _acquire(
    motion: FEMotion,
    size: LVSize,
    geometry: VentricleGeometry,
    times: FloatArray,
    snr: float | None,
    rng: np.random.Generator,
) -> xr.Dataset:
    """SA (x, y tags) and LA (z tag) CSPAMM stacks on one common grid (module docstring)."""
    d = size.pixel
    a_epi, c_epi = geometry.outer
    zb = geometry.truncation
    n_xy = 2 * int(np.ceil((a_epi + size.margin) / d))
    xy = (np.arange(n_xy) - 0.5 * (n_xy - 1)) * d
    z0 = -c_epi - size.margin
    n_z = int(np.ceil((zb + 0.5 * size.margin - z0) / d)) + 1
    z = z0 + d * np.arange(n_z)
    # SA slices from the cavity's apex to the base; the apical cap below it is left to the
    # LA slices (module docstring)
    c_endo = geometry.inner[1]
    h_sa = (zb + c_endo) / size.sa_slices
    z_sa = -c_endo + h_sa * (np.arange(size.sa_slices) + 0.5)
    h_la = 2.0 * a_epi / size.la_slices
    y_la = -a_epi + h_la * (np.arange(size.la_slices) + 0.5)
    common = AcquisitionOptions(
        times=times,
        tag_period=size.tag_period,
        sequence="CSPAMM",
        snr=snr,
        body=motion.density,
        inverse=motion.inverse,
        oversample=size.oversample,
        rng=rng,
    )
    sa = synthesize_tagged(
        motion,
        shape=(size.sa_slices, n_xy, n_xy),
        spacing=(h_sa, d, d),
        origin=(z_sa[0], xy[0], xy[0]),
        tags=("x", "y"),
        slice_axis="z",
        slice_thickness=h_sa,
        **common,
    )
    la = synthesize_tagged(
        motion,
        shape=(n_z, size.la_slices, n_xy),
        spacing=(d, h_la, d),
        origin=(z[0], y_la[0], xy[0]),
        tags=("z",),
        slice_axis="y",
        slice_thickness=h_la,
        **common,
    )
    shape = (n_z, n_xy, n_xy)
    Zg, Yg, Xg = np.meshgrid(z, xy, xy, indexing="ij")
    voxels = np.stack([Xg.ravel(), Yg.ravel(), Zg.ravel()], axis=1)
    truth = motion.displacement(voxels)  # (time, n, 3)
    truth = truth.reshape(times.size, *shape, 3).transpose(0, 4, 1, 2, 3)
    attrs: dict[str, Any] = {
        "noise_sigma": float(sa.attrs["noise_sigma"]),
        "t1": float(sa.attrs["t1"]),
        "flip_angle": float(sa.attrs["flip_angle"]),
        "oversample": int(size.oversample),
        "sa_slice_positions_mm": z_sa,
        "la_slice_positions_mm": y_la,
        "sa_slice_thickness_mm": h_sa,
        "la_slice_thickness_mm": h_la,
    }
    return cspamm_dataset(
        [sa, la], (z, xy, xy), truth, attrs, snr, body=np.isfinite(truth[0, 0]).astype(np.float64)
    )


# ---------------------------------------------------------------------------- analysis


def fiber_shortening(tracked: xr.Dataset, body: Body, *, frame: int = -1) -> dict[str, float]:
    """Volume-weighted mean fibre shortening of a tracked frame, per reference.

    Parameters
    ----------
    tracked : xarray.Dataset
        ``tracked/1`` with ``fiber_stretch`` (time, cell).
    body : Body
        The tracked body (cell volumes; its growth field gives the prestretch).
    frame : int, default -1
        Frame index (end systole by default).

    Returns
    -------
    dict
        ``reference``: 1 − mean fibre stretch relative to the tracking reference;
        ``stress_free``: the same relative to the stress-free fibre length (the stretch
        times the in-situ prestretch :math:`1/|F_g f_0|`; equal to ``reference`` without
        growth); ``prestretch``: mean in-situ prestretch − 1. Dimensionless.
    """
    lam = np.asarray(tracked["fiber_stretch"].isel(time=frame).values, dtype=np.float64)
    w = body.cell_volume / body.cell_volume.sum()
    pre = fiber_prestretch(body)
    return {
        "reference": float(1.0 - (w * lam).sum()),
        "stress_free": float(1.0 - (w * lam * pre).sum()),
        "prestretch": float((w * (pre - 1.0)).sum()),
    }


# ------------------------------------------------------------------------------ scene


@dataclass
class LVScene:
    """The left-ventricle scene: images with ground truth and the tracking models.

    Attributes
    ----------
    tagged : xarray.Dataset
        ``tagged/1`` CSPAMM images on the common grid with per-tag masks,
        ``displacement_true`` and ``body``.
    mesh : MeshSpec
        Tracking mesh (the image geometry at frame 0), mm.
    material : Guccione
        Passive material of the tracking models.
    reference : {"stress-free", "prestretched"}
        Default reference of :meth:`body`.
    truth : FEMotion
        The fine-mesh forward simulation (``truth.body``, ``truth.U``; with an infarct,
        ``truth.body.t_max`` holds the reduced tension of its cells).
    geometry : VentricleGeometry
        The analytic ventricle.
    info : dict
        Settings and timings.
    infarct : tuple of int
        AHA segments (1--17) whose active tension is scaled by ``scar_activation``;
        empty for the healthy ventricle.
    scar_activation : float
        Factor of the active tension in the infarct (dimensionless, in [0, 1]).
    """

    tagged: xr.Dataset
    mesh: MeshSpec
    material: Any
    reference: Reference
    truth: FEMotion
    geometry: VentricleGeometry = GEOMETRY
    info: dict = field(default_factory=dict)
    infarct: tuple[int, ...] = ()
    scar_activation: float = 1.0
    _growth: GrowthField | None = None

    def template(self) -> VentricleTemplate:
        """The scene's exact ventricle as a template (image and template coordinates agree).

        Returns
        -------
        VentricleTemplate
            ``VentricleTemplate(self.geometry, anterior=ANTERIOR)``: centre at the origin,
            long axis +z (apex to base), anterior wall at +y; its AHA segments are those the
            infarct was placed by.
        """
        return _template(self.geometry)

    def truth_result(self) -> xr.Dataset:
        """The forward simulation as a ``tracked/1`` result on the fine truth mesh.

        Returns
        -------
        xarray.Dataset
            :meth:`FEMotion.as_tracked` on the images' grid: displacement (mm) and
            Green--Lagrange strain of every truth cell and frame. The true segment strains
            are ``harpx.cardiac.strain.cardiac_strain(scene.truth_result(), template)``
            with the template the estimates are analysed with.
        """
        return self.truth.as_tracked(self.tagged)

    def dirichlet(self) -> list[Any]:
        """Tracking boundary conditions: base held in z and pinned in-plane (as the truth).

        Returns
        -------
        list
            ``[Fixed("base", (2,)), NodeFixed(...)]``: :func:`base_conditions` of the
            scene's geometry.
        """
        return base_conditions(self.geometry)

    def growth(self) -> GrowthField:
        """The prestretch growth field of the prestretched reference, computed once.

        The first call runs :func:`~harpx.physiology.growth.prestretch_growth` on the
        tracking mesh with :meth:`dirichlet` (settings from
        ``info["prestretch_settings"]``, if any) and stores its report in
        ``info["prestretch"]``; later calls return the same field.

        Returns
        -------
        GrowthField
            :math:`F_g` (dimensionless) at the Gauss points of a hex8 body on ``mesh``.
        """
        if self._growth is None:
            self._growth, info = prestretch_growth(
                self.mesh,
                self.material,
                self.dirichlet(),
                transmural=self.geometry.transmural,
                **self.info.get("prestretch_settings", {}),
            )
            self.info["prestretch"] = info
        return self._growth

    def body(self, reference: Reference | None = None) -> Body:
        """The hex8 tracking model for a reference (default: the scene's).

        Parameters
        ----------
        reference : {"stress-free", "prestretched"}, optional
            ``"stress-free"``: no residual stress; ``"prestretched"``: residually stressed
            by :meth:`growth`, in equilibrium at ``u = 0`` with :meth:`dirichlet`.

        Returns
        -------
        Body
            hex8 body on ``mesh`` with the passive ``material``; with ``"prestretched"``
            also the growth field of :meth:`growth`.

        Raises
        ------
        ValueError
            For an unknown reference.
        """
        reference = self.reference if reference is None else reference
        if reference == "stress-free":
            return Body(self.mesh, self.material)
        if reference == "prestretched":
            return Body(self.mesh, self.material, growth=self.growth())
        raise ValueError(f"reference={reference!r}; expected 'stress-free' or 'prestretched'")


def _ventricle_mesh(
    geometry: VentricleGeometry, divisions: tuple[int, int, int], *, segments: bool = True
) -> MeshSpec:
    """The scene's ventricle meshed with (circumferential, longitudinal, transmural) cells.

    The scene template's mesh: its ``aha_XX`` regions are the segments of the scene's
    anterior direction (+y).
    """
    nc, nl, nt = divisions
    return _template(geometry).mesh(
        n_circumferential=nc, n_longitudinal=nl, n_transmural=nt, segments=segments
    )


def lv(
    reference: Reference = "stress-free",
    size: Size = "paper",
    *,
    snr: float | None = 20.0,
    seed: int = 0,
    systole: Systole | None = None,
    infarct: Sequence[int] = (),
    scar_activation: float = 0.0,
    linear_solver: str = "auto",
) -> LVScene:
    """Build the left-ventricle scene (paper §4.2), optionally with a regional infarct.

    Parameters
    ----------
    reference : {"stress-free", "prestretched"}, default "stress-free"
        Default reference of ``scene.body()`` (both are available from the same scene; the
        images and the truth do not depend on it).
    size : {"paper", "small"}, default "paper"
        ``"paper"``: 10 frames, 12 SA + 8 LA slices of 1.25 mm pixels, a 6528-cell
        tracking model and a 14.7 k-cell truth; ``"small"``: 5 frames, 8 SA + 6 LA slices of
        2 mm pixels, 456 and 1539 cells, for tests and tutorials.
    snr : float or None, default 20
        Image signal-to-noise ratio (None: noise free).
    seed : int, default 0
        Seed of the image noise.
    systole : Systole, optional
        Loading of the forward simulation (default ``Systole()``: active tension parameter
        60 kPa, end-systolic pressure 8 kPa).
    infarct : sequence of int, default ()
        AHA segments (1--17, :func:`aha_segment`) of an infarct: the truth cells whose
        centre lies in them develop ``scar_activation`` times the active tension (module
        docstring). Empty: the healthy ventricle.
    scar_activation : float, default 0
        Factor of the active tension in the infarct, in [0, 1] (0: no active tension,
        the infarct is stretched passively by the cavity pressure; 1: no infarct).
    linear_solver : str, default "auto"
        Linear solver of the forward simulation.

    Returns
    -------
    LVScene
        The CSPAMM images with ``displacement_true``, the tracking mesh and material, the
        fine forward simulation (``truth``), the geometry, the infarct and the settings
        and timings (``info``).

    Raises
    ------
    ValueError
        For an unknown size or reference, an infarct segment outside 1--17 or repeated,
        or ``scar_activation`` outside [0, 1].
    ConvergenceError
        If the forward simulation stalls (lower ``Systole.pressure``).
    """
    if size not in SIZES:
        raise ValueError(f"size={size!r}; expected one of {sorted(SIZES)}")
    if reference not in ("stress-free", "prestretched"):
        raise ValueError(f"reference={reference!r}; expected 'stress-free' or 'prestretched'")
    segments = tuple(int(k) for k in infarct)
    if any(not 1 <= k <= 17 for k in segments) or len(set(segments)) != len(segments):
        raise ValueError(f"infarct={infarct!r}; expected distinct AHA segments in 1..17")
    if not 0.0 <= float(scar_activation) <= 1.0:
        raise ValueError(f"scar_activation={scar_activation!r}; expected a factor in [0, 1]")
    g = SIZES[size]
    systole = Systole() if systole is None else systole
    material = myocardium()
    geometry = GEOMETRY
    fine = _ventricle_mesh(geometry, g.truth, segments=False)
    truth_body = Body(fine, material, active=ActiveContraction(t_max=0.0))
    tension = _infarct_tension(
        truth_body.nodes[truth_body.cells[:, :8]].mean(axis=1), segments, float(scar_activation)
    )
    times = g.frame_interval * np.arange(g.frames, dtype=np.float64)
    U, forward = simulate_systole(
        truth_body,
        g.frames,
        systole,
        base_conditions(geometry),
        linear_solver=linear_solver,
        tension=tension,
    )
    motion = FEMotion(truth_body, U, times)
    start = _time.perf_counter()
    tagged = _acquire(motion, g, geometry, times, snr, np.random.default_rng(seed))
    tagged.attrs["scene"] = f"lv/{size}"
    if segments:
        tagged.attrs["infarct_segments"] = list(segments)
        tagged.attrs["scar_activation"] = float(scar_activation)
    imaging_time = _time.perf_counter() - start
    mesh = _ventricle_mesh(geometry, g.tracking)
    info = {
        "size": size,
        "settings": g,
        "systole": systole,
        "snr": snr,
        "seed": seed,
        "forward": forward,
        "imaging_time": imaging_time,
        "truth_cells": truth_body.ncell,
        "tracking_cells": int(mesh.mesh.nelements),
        "infarct_cells": 0 if tension is None else int((tension < 1.0).sum()),
    }
    return LVScene(
        tagged,
        mesh,
        material,
        reference,
        motion,
        geometry,
        info,
        segments,
        float(scar_activation) if segments else 1.0,
    )
