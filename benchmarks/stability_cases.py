"""The cases of the stability report (benchmarks/stability.py, issue 7): scenes, the
measurement of one tracking run, and one generator of cases per group.

Each case is ``(group, label, run)``; ``run()`` returns rows (dicts of the report's
columns). An exception inside ``run`` becomes a ``raised`` row (:func:`_guard`).

Sweeps (small scenes so the whole report takes about 7 min on two shared cores):

* ``stiffness``: κ/C1 = 10 … 10⁵, hex8 and hex20, on the small phantom (lagged rotation).
* ``motion``: per-frame edge displacement 0.25 … 1.0 tag period. A uniform translation
  along the x tag (nothing moves less) from rest or after a two-frame ramp, with the motion
  predictor as shipped (``"linear"``: α ∈ {0, ½, 1}, α = 1 unless a smaller α lowers the
  phase residual by more than 5 %; :class:`~harpx.tracking.settings.SolverTuning`), off
  (``"none"``) and forced to α = 1;
  a rigid rotation about the axis of a 24 mm cylinder
  (its centre moves less) in one frame, where no predictor exists; a rigid rotation of a
  12 mm cylinder to 180° in 15° frames with the band-pass radius 0.5 (default) and 1.0,
  with the phase error of the images themselves. Conventional HARP beside each.
* ``penalty``: λ pinned (penalty = penalty_limit) from 10⁻³ to 10⁶ times its default with
  an unreachable ε target, so ε(λ) shows whether it is non-increasing; on the small
  phantom and on a benign one-frame rotation.
* ``noise`` / ``voxel`` / ``tag period``: the small phantom at SNR 50 … 3, voxels ×1, ×1.5,
  ×2 and tag periods 4 … 12 mm (FE and HARP).
* ``inversion``: a pressed cube (:func:`harpx.mechanics.newton.solve`, follower pressure
  1 … 1000 C1), tracking static images with a squeezing pressure term, and images of a
  uniaxial compression (J = stretch) tracked by a compressible model.
* ``degenerate``: empty, tiny and one-tag masks, an all-zero frame, NaNs in one slice, a field
  of view that cuts off part of the mesh, a single frame.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from harpx.errors import ConvergenceError, ElementInversionError
from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import track_harp
from harpx.imaging.sample import PhaseSampler, wrap
from harpx.imaging.synth import synthesize_tagged
from harpx.mechanics.body import Body
from harpx.mechanics.loads import Fixed, Pressure
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import box, cylinder
from harpx.mechanics.newton import solve
from harpx.scenes._motion import RotationalImpact
from harpx.scenes.phantom import GEOMETRIES, Scene, phantom
from harpx.tracking.results import tracking_error
from harpx.tracking.settings import SolverTuning
from harpx.tracking.track import track

# the analytic rigid/affine motions are shared with tests/test_stability.py: one copy, in
# tests/_rigid.py, importable once the repository root is on the path
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests._rigid import (  # noqa: E402
    RigidRotation,
    Stretch,
    Translation,
    cylinder_scene,
    frame_profile,
)

OUT = Path(__file__).resolve().parent / "results"
TAG_PERIOD = 8.0  # mm
FRAME = 18.0  # ms between frames
STEPS = (0.25, 0.5, 0.75, 1.0)  # per-frame displacement, tag periods
Row = dict[str, Any]
Case = tuple[str, str, Callable[[], list[Row]]]  # (group, label, run)


# ------------------------------------------------------------------------------ measuring
class _Halvings:
    """Counts Gauss–Newton trial steps that would invert an element (each one is halved)."""

    count = 0

    @classmethod
    def install(cls) -> None:
        import harpx.tracking.equilibrium as eq

        real = eq.internal_forces

        def counted(*args: Any, **kwargs: Any) -> Any:
            out = real(*args, **kwargs)
            if out.r is None:
                cls.count += 1
            return out

        eq.internal_forces = counted


def _finite(*arrays: Any) -> bool:
    return all(np.all(np.isfinite(np.asarray(a, dtype=float))) for a in arrays)


def run_fe(scene_tagged: Any, phase: Any, body: Body, **kwargs: Any) -> tuple[Row, Any]:
    """Track with the FE method and summarise (error, ε, iterations, halvings, time)."""
    _Halvings.count = 0
    start = time.perf_counter()
    out = track(phase, body, **kwargs)
    wall = time.perf_counter() - start
    err = tracking_error(out, scene_tagged)
    U = out["dof_displacement"].values
    min_j = min(float(body.jacobian(u).min()) for u in U)
    finite = _finite(U, out.epsilon.values[1:], err["mean"].values[1:])
    reached = bool(out.target_reached.values[1:].all())
    row = {
        "method": f"FE {body.element}",
        "status": "nan" if not finite else ("converged" if reached else "not reached"),
        "mean": float(err.mean_all),
        "p95": float(err.p95_all),
        "max": float(err.max_all),
        "epsilon": float(np.max(out.epsilon.values[1:])),
        "iterations": int(out.iterations.sum()),
        "halvings": _Halvings.count,
        "penalty": float(np.max(out.penalty.values)),
        "min_J": min_j,
        "coverage": float(err.coverage),
        "cells_without_data": int(np.isnan(out.epsilon_cell.values[1:]).all(axis=0).sum()),
        "wall_time": wall,
        "frames": int(out.sizes["time"]),
    }
    return row, (out, err)


def run_harp(tagged: Any, phase: Any) -> tuple[Row, Any]:
    """Conventional HARP on the acquired voxel centres."""
    start = time.perf_counter()
    out = track_harp(phase, points=tagged)
    wall = time.perf_counter() - start
    err = tracking_error(out, tagged)
    row = {
        "method": "HARP",
        "status": "converged" if _finite(err["mean"].values[1:]) else "nan",
        "mean": float(err.mean_all),
        "p95": float(err.p95_all),
        "max": float(err.max_all),
        "epsilon": float(np.nanmax(out.epsilon.values[1:])),
        "iterations": int(out.iterations.sum()),
        "coverage": float(err.coverage),
        "wall_time": wall,
        "frames": int(out.sizes["time"]),
    }
    return row, (out, err)


def fe_and_harp(
    scene: Any, phase: Any, group: str, case: str, parameter: str, value: Any, **extra: Any
) -> list[Row]:
    """One row for FE tracking and one for conventional HARP of the same scene and phase."""
    return [
        _row(group, case, parameter, value, **summary, **extra)
        for summary, _ in (
            run_fe(scene.tagged, phase, scene.body()),
            run_harp(scene.tagged, phase),
        )
    ]


def image_phase_error(phase: Any, motion: Any, points: np.ndarray) -> np.ndarray:
    """Image quality: mean |W(φ(x, t) − 2π f d·X(x, t))| per frame at body points x, rad.

    Over the tags acquired on z slices (x and y): the z tag of the small phantom spans only
    1.25 periods across its 7.5 mm and carries 0.43 rad of edge error even without noise,
    which would hide the trends.
    """
    k = 2 * np.pi * phase["tag_frequency"].values[:, None] * phase["tag_direction"].values
    in_plane = np.asarray(phase["slice_axis"].values == "z")
    out = []
    for n, t in enumerate(phase["time"].values):
        phi, _, valid = PhaseSampler(phase, n).sample(points)
        exact = motion.inverse(points, float(t)) @ k.T
        e = np.abs(wrap(phi - exact))[valid][:, in_plane]
        out.append(float(e.mean()) if e.size else np.nan)
    return np.array(out)


def _body_points(radius: float, height: float, n: int = 3000) -> np.ndarray:
    rng = np.random.default_rng(1)
    pts = rng.uniform(-1.0, 1.0, (n, 3)) * [radius, radius, 0.4 * height]
    return pts[np.hypot(pts[:, 0], pts[:, 1]) < 0.85 * radius]


def _describe(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0] if lines else ''}"


def _guard(
    run: Callable[[], list[Row]], group: str, case: str, parameter: str, value: Any
) -> Callable[[], list[Row]]:
    """Turn an exception of ``run`` into a ``raised`` row that names it."""

    def guarded() -> list[Row]:
        start = time.perf_counter()
        try:
            return run()
        except Exception as exc:  # noqa: BLE001 - reported as data, that is the point
            return [
                _row(
                    group,
                    case,
                    parameter,
                    value,
                    method="FE hex8",
                    status="raised",
                    error=_describe(exc),
                    wall_time=time.perf_counter() - start,
                )
            ]

    return guarded


# ------------------------------------------------------------------------------ scenes
def phantom_like(
    *, snr: float | None = 20.0, voxel: float = 1.0, tag_period: float | None = None, seed: int = 0
) -> Scene:
    """The small phantom (lagged rotational impact) with another voxel size or tag period.

    ``voxel`` scales its voxels in all three directions (field of view kept); with the
    defaults this is :func:`harpx.scenes.phantom.phantom` ``("small", snr=snr)``.
    """
    g = GEOMETRIES["small"]
    if voxel == 1.0 and tag_period in (None, g.tag_period):
        return phantom("small", snr=snr, seed=seed)
    base = -g.height / 2
    motion = RotationalImpact(
        radius=g.radius,
        base=base,
        height=g.height,
        angle=getattr(g, "angle", 0.2),
        rise_time=getattr(g, "rise_time", 72.0),
    )
    pixel, dz = g.pixel * voxel, g.slice_spacing * voxel
    matrix = int(np.ceil(g.matrix * g.pixel / pixel))
    slices = int(np.ceil(g.slices * g.slice_spacing / dz))

    def density(X: np.ndarray) -> np.ndarray:
        inside = (np.hypot(X[:, 0], X[:, 1]) <= g.radius) & (X[:, 2] >= base)
        return (inside & (X[:, 2] <= base + g.height)).astype(float)

    tagged = synthesize_tagged(
        motion,
        shape=(slices, matrix, matrix),
        spacing=(dz, pixel, pixel),
        times=np.arange(g.frames) * g.repetition_time,
        tag_period=g.tag_period if tag_period is None else tag_period,
        tags=("x", "y", "z"),
        sequence="SPAMM",
        snr=snr,
        body=density,
        inverse=motion.inverse,
        oversample=2,
        rng=np.random.default_rng(seed),
    )
    mesh = cylinder(
        g.radius,
        g.height,
        n_radial=g.n_radial,
        n_circumferential=g.n_circumferential,
        n_axial=g.n_axial,
        center=(0.0, 0.0, base),
    )
    return Scene(tagged, mesh, NeoHookean(c1=1.0, kappa=120.0), motion, {})


def translation_scene(step: float, frames: int = 5, *, ramp: int = 0) -> Scene:
    """12 mm cylinder translating along the x tag by ``step`` tag periods per frame."""
    times = np.arange(frames) * FRAME
    offsets = frame_profile(step * TAG_PERIOD, frames, ramp=ramp)
    motion = Translation(times=tuple(times), offsets=tuple(offsets))
    return cylinder_scene(motion, times=times, travel=float(offsets[-1]))


def rotation_scene(
    step: float,
    frames: int = 2,
    *,
    radius: float = 24.0,
    snr: float | None = None,
    degrees_per_frame: float | None = None,
) -> Scene:
    """Cylinder turning rigidly about its axis; the edge moves ``step`` tag periods a frame."""
    times = np.arange(frames) * FRAME
    rate = np.deg2rad(degrees_per_frame) if degrees_per_frame else step * TAG_PERIOD / radius
    motion = RigidRotation(times=tuple(times), angles=tuple(frame_profile(rate, frames)))
    mesh = {"n_radial": 3, "n_circumferential": 24} if radius >= 20 else {}
    return cylinder_scene(motion, times=times, radius=radius, snr=snr, **mesh)


# ------------------------------------------------------------------------------ cases
def _row(group: str, case: str, parameter: str, value: Any, **fields: Any) -> Row:
    return {"group": group, "case": case, "parameter": parameter, "value": value, **fields}


def stiffness_cases() -> Iterable[Case]:
    for element in ("hex8", "hex20"):
        for ratio in (1e1, 1e2, 1e3, 1e4, 1e5):

            def run(element: str = element, ratio: float = ratio) -> list[Row]:
                scene = phantom("small")
                phase = extract_phase(scene.tagged)
                body = scene.body(element, material=NeoHookean(c1=1.0, kappa=ratio))
                row, _ = run_fe(scene.tagged, phase, body)
                return [_row("stiffness", f"phantom {element}", "kappa/C1", ratio, **row)]

            yield "stiffness", f"{element} kappa/C1={ratio:g}", run


def motion_cases() -> Iterable[Case]:
    for ramp, shape in ((0, "from rest"), (2, "ramped")):
        for step in STEPS:

            def run(step: float = step, ramp: int = ramp, shape: str = shape) -> list[Row]:
                scene = translation_scene(step, ramp=ramp)
                phase = extract_phase(scene.tagged)
                rows = []
                for predictor in ("linear", "none", "linear α=1"):
                    case = f"translation {shape}, predictor {predictor}"
                    factors = (
                        (1.0,) if predictor == "linear α=1" else SolverTuning().predictor_factors
                    )

                    def fe(
                        predictor: str = predictor, factors: tuple = factors, case: str = case
                    ) -> list[Row]:
                        row, _ = run_fe(
                            scene.tagged,
                            phase,
                            scene.body(),
                            predictor="none" if predictor == "none" else "linear",
                            tuning=SolverTuning(predictor_factors=factors),
                        )
                        return [_row("motion", case, "step/period", step, **row)]

                    # each predictor on its own: one that raises (the body left behind where
                    # the images have no signal) is a row of its own, not the whole case's
                    rows += _guard(fe, "motion", case, "step/period", step)()
                row, _ = run_harp(scene.tagged, phase)
                rows.append(_row("motion", f"translation {shape}", "step/period", step, **row))
                return rows

            yield "motion", f"translation {shape} {step}", run
    for step in STEPS:

        def run_rot(step: float = step) -> list[Row]:
            scene = rotation_scene(step)
            phase = extract_phase(scene.tagged)
            row, _ = run_fe(scene.tagged, phase, scene.body())
            rows = [_row("motion", "rotation R=24 mm, one frame", "step/period", step, **row)]
            row, _ = run_harp(scene.tagged, phase)
            rows.append(_row("motion", "rotation R=24 mm, one frame", "step/period", step, **row))
            return rows

        yield "motion", f"rotation one frame {step}", run_rot
    for radius in (0.5, 1.0):

        def run_180(radius: float = radius) -> list[Row]:
            scene = rotation_scene(0.0, frames=13, radius=12.0, degrees_per_frame=15.0)
            phase = extract_phase(scene.tagged, radius=radius)
            angles = np.rad2deg([scene.motion.angle(t) for t in phase.time.values])
            quality = image_phase_error(phase, scene.motion, _body_points(12.0, 6.0))
            rows = []
            fe, (out, err) = run_fe(scene.tagged, phase, scene.body())
            harp, (hout, herr) = run_harp(scene.tagged, phase)
            for n in range(1, len(angles)):
                for summary, o, e in ((fe, out, err), (harp, hout, herr)):
                    per_frame = {k: float(e[k].values[n]) for k in ("mean", "p95", "max")}
                    per_frame["epsilon"] = float(o.epsilon.values[n])
                    per_frame["iterations"] = int(o.iterations.values[n])
                    per_frame["wall_time"] = float(o.wall_time.values[n])
                    if "target_reached" in o:
                        reached = bool(o.target_reached.values[n])
                        per_frame["status"] = "converged" if reached else "not reached"
                    rows.append(
                        _row(
                            "rotation to 180",
                            f"rotation 15°/frame, filter radius {radius}",
                            "angle (deg)",
                            round(float(angles[n]), 1),
                            **{**summary, **per_frame, "phase_error": float(quality[n])},
                        )
                    )
            return rows

        yield "motion", f"rotation to 180 radius {radius}", run_180


PENALTY_SCENES: dict[str, Callable[[], Scene]] = {
    "phantom (edge steps > half a period), λ pinned": lambda: phantom("small"),
    "rotation 0.25 period, one frame, SNR 10, λ pinned": lambda: rotation_scene(0.25, snr=10.0),
}


def penalty_cases() -> Iterable[Case]:
    for label, make in PENALTY_SCENES.items():
        for scale in (1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6):

            def run(
                scale: float = scale, label: str = label, make: Callable[[], Scene] = make
            ) -> list[Row]:
                scene = make()
                phase = extract_phase(scene.tagged)
                # pinned λ and an unreachable target: every frame ends at exactly this λ
                row, (out, _) = run_fe(
                    scene.tagged,
                    phase,
                    scene.body(),
                    penalty=scale,
                    penalty_limit=scale,
                    epsilon=1e-6,
                )
                row["status"] = "nan" if row["status"] == "nan" else "pinned"
                row["epsilon_frames"] = " ".join(f"{e:.4f}" for e in out.epsilon.values[1:])
                return [_row("penalty", label, "penalty/default", scale, **row)]

            yield "penalty", f"{label} {scale:g}", run


def noise_cases() -> Iterable[Case]:
    sweeps: list[tuple[str, str, float, dict[str, float]]] = []
    sweeps += [("noise", "SNR", s, {"snr": s}) for s in (50.0, 20.0, 10.0, 5.0, 3.0)]
    sweeps += [("voxel", "voxel scale", v, {"voxel": v}) for v in (1.0, 1.5, 2.0)]
    sweeps += [
        ("tag period", "tag period (mm)", p, {"tag_period": p}) for p in (4.0, 6.0, 8.0, 10.0, 12.0)
    ]
    for group, parameter, value, kwargs in sweeps:

        def run(
            group: str = group,
            parameter: str = parameter,
            value: float = value,
            kwargs: dict[str, float] = kwargs,
        ) -> list[Row]:
            scene = phantom_like(**kwargs)
            phase = extract_phase(scene.tagged)
            g = GEOMETRIES["small"]
            quality = image_phase_error(phase, scene.motion, _body_points(g.radius, g.height))
            return fe_and_harp(
                scene, phase, group, "phantom", parameter, value,
                phase_error=float(np.nanmean(quality[1:])),
            )  # fmt: skip

        yield group, f"{parameter}={value:g}", run


SQUEEZE = "static images + pressure squeezing top and bottom"


def inversion_cases() -> Iterable[Case]:
    for pressure in (1.0, 10.0, 100.0, 1000.0):

        def run_solve(pressure: float = pressure) -> list[Row]:
            body = Body(box((10.0, 10.0, 10.0), (3, 3, 3)), NeoHookean(c1=1.0, kappa=100.0))
            loads = [Fixed("bottom"), Pressure("top", pressure)]
            start = time.perf_counter()
            row: Row = {"method": "newton.solve hex8"}
            try:
                res = solve(body, loads, steps=4)
                row.update(
                    status="converged",
                    min_J=res.min_jacobian,
                    iterations=res.iterations,
                    halvings=res.cutbacks,
                    line_search=res.line_search_steps,
                )
            except ConvergenceError as exc:  # ElementInversionError names the cells
                row.update(
                    status="raised",
                    error=_describe(exc),
                    cells=len(exc.cells) if isinstance(exc, ElementInversionError) else "",
                )
            row["wall_time"] = time.perf_counter() - start
            return [
                _row(
                    "inversion",
                    "pressed cube (Fixed bottom, Pressure top)",
                    "pressure/C1",
                    pressure,
                    **row,
                )
            ]

        yield "inversion", f"solve pressure {pressure:g}", run_solve
    for pressure in (1.0, 10.0, 100.0, 1e3, 1e4):

        def run_track(pressure: float = pressure) -> list[Row]:
            scene = rotation_scene(0.0, frames=3, radius=12.0)  # static images
            phase = extract_phase(scene.tagged)
            body = Body(scene.mesh, scene.material)
            squeeze = [Pressure("top", pressure), Pressure("bottom", pressure)]
            row, _ = run_fe(scene.tagged, phase, body, terms=squeeze)
            return [_row("inversion", SQUEEZE, "pressure/C1", pressure, **row)]

        yield (
            "inversion",
            f"track pressure {pressure:g}",
            _guard(run_track, "inversion", SQUEEZE, "pressure/C1", pressure),
        )
    for stretch in (0.8, 0.6, 0.4):

        def run_stretch(stretch: float = stretch) -> list[Row]:
            times = np.arange(4) * FRAME
            motion = Stretch(times=tuple(times), stretches=tuple(np.linspace(1.0, stretch, 4)))
            scene = cylinder_scene(motion, times=times, kappa=1.0)  # compressible model
            phase = extract_phase(scene.tagged)
            return fe_and_harp(
                scene, phase, "inversion", "images of uniaxial compression (J = stretch)",
                "final stretch", stretch,
            )  # fmt: skip

        yield "inversion", f"compression {stretch:g}", run_stretch


OUTSIDE = "mesh partly outside the field of view (x > 4 mm cropped)"


def degenerate_cases() -> Iterable[Case]:
    def scene_and_phase() -> tuple[Scene, Any]:
        scene = translation_scene(0.25, frames=4)
        return scene, extract_phase(scene.tagged)

    def masked(
        edit: Callable[[Any], None],
        make_scene: Callable[[], Scene] = lambda: translation_scene(0.25, frames=4),
    ) -> Callable[[], Any]:
        def run() -> Any:
            scene = make_scene()
            ds = scene.tagged.copy(deep=True)
            edit(ds)
            return scene, ds

        return run

    def empty(ds: Any) -> None:
        ds["mask"][:] = False

    def tiny(ds: Any) -> None:  # 2 x 2 x 2 voxels on the axis of the rotating cylinder
        ds["mask"][:] = False
        cz, cy, cx = (ds.sizes[d] // 2 for d in ("z", "y", "x"))
        ds["mask"][:, cz - 1 : cz + 1, cy - 1 : cy + 1, cx - 1 : cx + 1] = True

    def tiny_moving(ds: Any) -> None:  # the same 8 voxels, but the body translates away
        ds["mask"][:] = False
        cz, cy, cx = (ds.sizes[d] // 2 for d in ("z", "y", "x"))
        ds["mask"][:, cz - 1 : cz + 1, cy - 1 : cy + 1, 9:11] = True

    def one_tag(ds: Any) -> None:
        ds["mask"][2] = False

    def zero_frame(ds: Any) -> None:
        ds["image"][:, 2] = 0.0

    def nan_slice(ds: Any) -> None:
        ds["image"][0, :, 2] = np.nan

    variants: list[tuple[str, Callable[[], Any]]] = [
        ("empty mask", masked(empty)),
        (
            "tiny mask (8 voxels on the axis of a rotation)",
            masked(tiny, lambda: rotation_scene(0.25, frames=3)),
        ),
        ("tiny mask (8 voxels the translating body leaves)", masked(tiny_moving)),
        ("one tag fully masked", masked(one_tag)),
        ("all-zero frame 2", masked(zero_frame)),
        ("NaNs in one slice", masked(nan_slice)),
    ]
    for label, make in variants:

        def run(label: str = label, make: Callable[[], Any] = make) -> list[Row]:
            scene, ds = make()
            row, _ = run_fe(scene.tagged, ds, scene.body())
            return [_row("degenerate", label, "", "", **row)]

        yield "degenerate", label, _guard(run, "degenerate", label, "", "")

    def outside() -> list[Row]:
        scene = translation_scene(0.25, frames=4)
        cropped = scene.tagged.sel(x=slice(None, 4.0))  # a third of the body is cut off
        row, _ = run_fe(cropped, extract_phase(cropped), scene.body())
        return [_row("degenerate", OUTSIDE, "", "", **row)]

    def single() -> list[Row]:
        scene, phase = scene_and_phase()
        start = time.perf_counter()
        out = track(phase.isel(time=[0]), scene.body())
        ok = _finite(out.displacement.values) and float(abs(out.displacement).max()) == 0.0
        return [
            _row(
                "degenerate",
                "a single frame",
                "",
                "",
                method="FE hex8",
                status="converged" if ok else "nan",
                frames=1,
                wall_time=time.perf_counter() - start,
            )
        ]

    yield "degenerate", "partly outside", _guard(outside, "degenerate", OUTSIDE, "", "")
    yield "degenerate", "single frame", _guard(single, "degenerate", "a single frame", "", "")


GROUPS: dict[str, Callable[[], Iterable[Case]]] = {
    "stiffness": stiffness_cases,
    "motion": motion_cases,
    "penalty": penalty_cases,
    "noise": noise_cases,
    "inversion": inversion_cases,
    "degenerate": degenerate_cases,
}
