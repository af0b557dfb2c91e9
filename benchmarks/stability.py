"""Numerical stability on stiff and extreme cases, with error and run time for each (issue 7).

Every case runs in its own forked process with a wall-time bound, so a hang becomes a
``timeout`` row instead of a stuck report, and records: whether it converged (ε target met
in every frame), how it failed otherwise (exception class and first line), the error
against the analytic truth (mean and 95th percentile, mm), the largest ε reached (rad),
Gauss–Newton iterations, step halvings (trial steps that would have inverted an element),
the smallest det F reached and the wall time of the tracking call. A result that holds NaN
is reported as ``nan`` (it must never happen).

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

Writes ``benchmarks/results/stability.{csv,md}`` and ``stability_<group>.png``; with
``--previous`` an earlier ``stability.csv`` is compared and the rows that changed carry its
status and errors beside the new ones (``--compare-only`` compares an existing run).

Usage::

    python benchmarks/stability.py                  # everything
    python benchmarks/stability.py --groups motion degenerate --timeout 120
    python benchmarks/stability.py --out /tmp/stab --previous benchmarks/results/stability.csv
    python benchmarks/stability.py --out /tmp/stab --previous old.csv --compare-only
"""

from __future__ import annotations

import argparse
import csv
import multiprocessing as mp
import sys
import time
import traceback
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
            rows = []
            for summary, _ in (
                run_fe(scene.tagged, phase, scene.body()),
                run_harp(scene.tagged, phase),
            ):
                rows.append(
                    _row(
                        group,
                        "phantom",
                        parameter,
                        value,
                        **summary,
                        phase_error=float(np.nanmean(quality[1:])),
                    )
                )
            return rows

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
            rows = []
            for summary, _ in (
                run_fe(scene.tagged, phase, scene.body()),
                run_harp(scene.tagged, phase),
            ):
                rows.append(
                    _row(
                        "inversion",
                        "images of uniaxial compression (J = stretch)",
                        "final stretch",
                        stretch,
                        **summary,
                    )
                )
            return rows

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


# ------------------------------------------------------------------------------ running
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


def _child(run: Callable[[], list[Row]], conn: Any) -> None:
    _Halvings.install()
    try:
        rows = run()
    except Exception as exc:  # noqa: BLE001
        rows = [
            {
                "status": "raised",
                "error": _describe(exc),
                "traceback": traceback.format_exc(limit=3),
            }
        ]
    conn.send(rows)
    conn.close()


def run_bounded(group: str, label: str, run: Callable[[], list[Row]], timeout: float) -> list[Row]:
    """Run one case in a forked process; a case that exceeds ``timeout`` s is killed."""
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(run, send), daemon=True)
    start = time.perf_counter()
    proc.start()
    send.close()
    rows: list[Row]
    if recv.poll(timeout):
        try:
            rows = recv.recv()
        except EOFError:
            rows = [{"status": "crashed", "error": f"worker exited with code {proc.exitcode}"}]
    else:
        proc.terminate()
        rows = [{"status": "timeout", "error": f"no result within {timeout:g} s (killed)"}]
    proc.join(10)
    if proc.is_alive():
        proc.kill()
        proc.join()
    elapsed = time.perf_counter() - start
    for row in rows:
        row.setdefault("group", group)
        row.setdefault("case", label)
        row.setdefault("case_seconds", round(elapsed, 1))
    return rows


# ------------------------------------------------------------------------------ output
COLUMNS = [
    "group",
    "case",
    "parameter",
    "value",
    "method",
    "status",
    "error",
    "mean",
    "p95",
    "max",
    "epsilon",
    "iterations",
    "halvings",
    "penalty",
    "min_J",
    "coverage",
    "cells_without_data",
    "phase_error",
    "wall_time",
    "frames",
    "epsilon_frames",
    "line_search",
    "cells",
    "case_seconds",
    "previous_status",
    "previous_mean",
    "previous_p95",
]


def _fmt(value: Any, digits: int = 3) -> str:
    if value is None or value == "":
        return ""
    if isinstance(value, float):
        if not np.isfinite(value):
            return "nan"
        if abs(value) >= 1e3 or abs(value) < 1e-2:
            return f"{value:.{digits}g}"
        return f"{value:.{digits}f}"
    return str(value)


def write_csv(rows: list[Row], path: Path) -> None:
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)


def check_monotone_epsilon(rows: list[Row]) -> str:
    """Is ε non-increasing in the pinned penalty λ, frame by frame (per penalty scene)?"""
    verdicts = []
    cases = sorted(
        {r["case"] for r in rows if r.get("group") == "penalty" and r.get("epsilon_frames")}
    )
    for case in cases:
        pinned = sorted(
            (r for r in rows if r.get("case") == case and r.get("epsilon_frames")),
            key=lambda r: float(r["value"]),
        )
        if len(pinned) < 2:
            continue
        eps = np.array([[float(e) for e in str(r["epsilon_frames"]).split()] for r in pinned])
        lam = [float(r["value"]) for r in pinned]
        rises = np.diff(eps, axis=0)
        # monotone up to which λ? (the first rise above 1e-3 rad, the Gauss–Newton tolerance)
        bad = np.nonzero((rises > 1e-3).any(axis=1))[0]
        if bad.size == 0:
            verdict = f"non-increasing over the whole sweep ({lam[0]:g} … {lam[-1]:g} × default)"
        else:
            i = int(bad[0])
            frame = int(np.argmax(rises[i])) + 1
            verdict = (
                f"non-increasing up to {lam[i]:g} × default; it rises by "
                f"{rises[i].max():.2g} rad from {lam[i]:g} to {lam[i + 1]:g} (frame {frame})"
                f", largest rise {rises.max():.2g} rad"
            )
        verdicts.append(f"ε against pinned λ, {case}: {verdict}.")
    return "\n".join(verdicts)


def headline(rows: list[Row]) -> list[str]:
    """One line per swept series: value → mean error, marking the frames that failed."""
    series: dict[tuple[str, str, str], list[Row]] = {}
    for r in rows:
        if r.get("parameter") and r.get("mean") not in (None, ""):
            series.setdefault((r["group"], r["case"], r.get("method", "")), []).append(r)
    out = []
    for (group, case, method), rs in series.items():
        rs = sorted(rs, key=lambda r: float(r["value"]))
        points = ", ".join(
            f"{_fmt(r['value'])} → {_fmt(r['mean'])}"
            + ("" if r.get("status") in ("converged", "pinned") else f" ({r.get('status')})")
            for r in rs
        )
        out.append(f"- **{group}**, {case}, {method} — {rs[0]['parameter']}: {points}")
    return out


def _number(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def _key(row: Row) -> tuple[str, str, str, str]:
    value = _number(row.get("value"))
    shown = f"{value:g}" if np.isfinite(value) else str(row.get("value", ""))
    return (str(row.get("group", "")), str(row.get("case", "")), shown, str(row.get("method", "")))


def mark_changes(
    rows: list[Row], previous: list[Row], *, relative: float = 0.1, absolute: float = 0.005
) -> int:
    """Put an earlier record's status and errors beside each row that changed; return how many.

    Rows match by group, case, value and method. A row changed if its status differs, or
    its mean error moved by more than ``relative`` of the larger of the two and more than
    ``absolute`` mm (or is now finite and was not, or the reverse).
    """
    before = {_key(r): r for r in previous}
    changed = 0
    for row in rows:
        for column in ("previous_status", "previous_mean", "previous_p95"):
            row.pop(column, None)
        old = before.get(_key(row))
        if old is None:
            continue
        now, then = _number(row.get("mean")), _number(old.get("mean"))
        moved = bool(np.isfinite(now)) != bool(np.isfinite(then)) or (
            bool(np.isfinite(now) and np.isfinite(then))
            and abs(now - then) > max(absolute, relative * max(abs(now), abs(then)))
        )
        if moved or row.get("status") != old.get("status"):
            row["previous_status"] = old.get("status", "")
            row["previous_mean"] = old.get("mean", "")
            row["previous_p95"] = old.get("p95", "")
            changed += 1
    return changed


def _changes(rows: list[Row], previous: str) -> list[str]:
    """Markdown section: the rows that changed against ``previous``, before and after."""
    changed = [r for r in rows if r.get("previous_status") not in (None, "")]
    lines = [
        "## Changed against the previous record",
        "",
        f"{len(changed)} of {len(rows)} rows changed against `{previous}` (status, or mean "
        "error by more than 10 % and 0.005 mm); the CSV carries the previous numbers in "
        "`previous_status`, `previous_mean`, `previous_p95`.",
        "",
        "| group | case | value | method | before: status | mean | p95 | now: status | mean | "
        "p95 |",
        "|" + "---|" * 10,
    ]
    for r in changed:
        cells = [
            r.get("group", ""),
            r.get("case", ""),
            _fmt(r.get("value", "")),
            r.get("method", ""),
            r.get("previous_status", ""),
            _fmt(_number(r.get("previous_mean"))),
            _fmt(_number(r.get("previous_p95"))),
            r.get("status", ""),
            _fmt(_number(r.get("mean"))),
            _fmt(_number(r.get("p95"))),
        ]
        lines.append("| " + " | ".join(str(c).replace("|", "/") for c in cells) + " |")
    return [*lines, ""]


def write_markdown(
    rows: list[Row], path: Path, generated: str, previous: str | None = None
) -> None:
    """Write the report; ``generated`` says when, by which command and how long it took."""
    lines = [
        "# Stability report (issue 7)",
        "",
        f"{generated} Errors are "
        "|u − u_true| in mm over the body voxels and all frames after the reference "
        "(per frame for the rotation to 180°); ε is the largest per-frame tracking residual "
        "(rad); halvings are Gauss–Newton steps that would have inverted an element "
        "(cut-backs for `newton.solve`); time is the wall time of the tracking call (s).",
        "",
    ]
    verdict = check_monotone_epsilon(rows)
    if verdict:
        lines += [v + "  " for v in verdict.splitlines()] + [""]
    if previous is not None:
        lines += _changes(rows, previous)
    lines += ["## Headline: mean error (mm) against each swept parameter", ""]
    lines += headline(rows) + ["", "## All cases", ""]
    header = (
        "| group | case | parameter | value | method | status | mean | p95 | ε | "
        "GN it. | halvings | min J | time (s) | note |"
    )
    lines += [header, "|" + "---|" * 14]
    for r in rows:
        note = r.get("error", "")
        if r.get("phase_error") not in (None, ""):
            note = (note + " " if note else "") + (
                f"image phase error (x, y tags) {_fmt(r['phase_error'])} rad"
            )
        if r.get("cells_without_data"):
            note = (note + " " if note else "") + f"{r['cells_without_data']} cells without data"
        cells = [
            r.get("group", ""),
            r.get("case", ""),
            r.get("parameter", ""),
            _fmt(r.get("value", "")),
            r.get("method", ""),
            r.get("status", ""),
            _fmt(r.get("mean")),
            _fmt(r.get("p95")),
            _fmt(r.get("epsilon")),
            _fmt(r.get("iterations")),
            _fmt(r.get("halvings")),
            _fmt(r.get("min_J")),
            _fmt(r.get("wall_time"), 2),
            str(note).replace("|", "/"),
        ]
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    path.write_text("\n".join(lines) + "\n")


def plot(rows: list[Row], out: Path) -> list[Path]:
    """Error (mean, p95) and wall time against each swept parameter, one PNG per group."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    groups: dict[str, list[Row]] = {}
    for r in rows:
        swept = r.get("parameter") and isinstance(r.get("value"), int | float)
        if swept and r.get("mean") is not None:
            groups.setdefault(str(r["group"]), []).append(r)
    for group, members in groups.items():
        series: dict[str, list[Row]] = {}
        for r in members:
            series.setdefault(f"{r['case']} — {r.get('method', '')}", []).append(r)
        height = 4.0 + 0.17 * ((len(series) + 1) // 2)
        fig, (ax_e, ax_t) = plt.subplots(1, 2, figsize=(11, height), layout="constrained")
        for label, rs in series.items():
            rs = sorted(rs, key=lambda r: float(r["value"]))
            x = [float(r["value"]) for r in rs]
            (line,) = ax_e.plot(x, [r["mean"] for r in rs], "o-", label=label)
            ax_e.plot(x, [r.get("p95", np.nan) for r in rs], "x:", color=line.get_color())
            if any(r.get("wall_time") is not None for r in rs):
                ax_t.plot(x, [r.get("wall_time", np.nan) for r in rs], "o-", color=line.get_color())
        parameter = members[0]["parameter"]
        for ax in (ax_e, ax_t):
            ax.set_xlabel(parameter)
            values = [float(r["value"]) for r in members]
            if min(values) > 0 and max(values) / min(values) >= 100:
                ax.set_xscale("log")
            ax.grid(alpha=0.3)
        ax_e.set_yscale("log")
        ax_e.set_ylabel("error (mm): mean (o), p95 (x)")
        ax_t.set_ylabel("wall time (s)")
        ax_e.set_title(f"{group}: error against truth", fontsize=10)
        ax_t.set_title(f"{group}: run time", fontsize=10)
        handles, labels = ax_e.get_legend_handles_labels()
        fig.legend(handles, labels, fontsize=7, loc="outside lower center", ncol=2)
        path = out / f"stability_{group.replace(' ', '_')}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def read_csv(path: Path) -> list[Row]:
    """Rows of a ``stability.csv`` with numbers parsed back (for ``--replot``)."""
    rows = []
    with open(path, newline="") as fh:
        for raw in csv.DictReader(fh):
            row: Row = {}
            for key, text in raw.items():
                if text in ("", None):
                    continue
                try:
                    row[key] = int(text) if text.lstrip("-").isdigit() else float(text)
                except ValueError:
                    row[key] = text
            rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--groups", nargs="+", choices=list(GROUPS), default=list(GROUPS))
    parser.add_argument("--timeout", type=float, default=240.0, help="wall-time bound per case, s")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument(
        "--replot", action="store_true", help="redraw the PNGs from an existing stability.csv"
    )
    parser.add_argument(
        "--previous",
        type=Path,
        help="an earlier stability.csv: rows that changed get its numbers beside the new ones",
    )
    parser.add_argument(
        "--compare-only",
        action="store_true",
        help="with --previous: compare the stability.csv in --out instead of running",
    )
    args = parser.parse_args(argv)
    command = "python benchmarks/stability.py " + " ".join(sys.argv[1:] if argv is None else argv)
    today = time.strftime("%Y-%m-%d")
    args.out.mkdir(parents=True, exist_ok=True)
    if args.replot:
        for path in plot(read_csv(args.out / "stability.csv"), args.out):
            print("wrote", path)
        return
    previous = None if args.previous is None else read_csv(args.previous)
    if args.compare_only:
        if previous is None:
            parser.error("--compare-only needs --previous")
        rows = read_csv(args.out / "stability.csv")
        print(mark_changes(rows, previous), "rows changed")
        report = args.out / "stability.md"
        first = next(
            (ln for ln in report.read_text().splitlines() if ln.startswith("Generated")), ""
        )
        generated = first.split(" Errors are ")[0] + (
            f" Compared on {today} with the previous record by `{command.strip()}`."
        )
        write_csv(rows, args.out / "stability.csv")
        write_markdown(rows, report, generated, str(args.previous))
        return
    start = time.perf_counter()
    rows: list[Row] = []
    for group in args.groups:
        for group_name, label, run in GROUPS[group]():
            new = run_bounded(
                group_name, label, _guard(run, group_name, label, "", ""), args.timeout
            )
            for r in new:
                print(
                    f"[{time.perf_counter() - start:6.0f} s] {r.get('group')} | "
                    f"{r.get('case')} | "
                    f"{r.get('parameter', '')}={r.get('value', '')} | {r.get('method', '')} | "
                    f"{r.get('status')} | mean {_fmt(r.get('mean'))} p95 {_fmt(r.get('p95'))} "
                    f"eps {_fmt(r.get('epsilon'))} | halvings {r.get('halvings', '')} "
                    f"min J {_fmt(r.get('min_J'))} | {_fmt(r.get('wall_time'), 2)} s "
                    f"{r.get('error', '')}",
                    flush=True,
                )
            rows += new
    seconds = time.perf_counter() - start
    compared = None
    if previous is not None:
        print(mark_changes(rows, previous), "rows changed")
        compared = str(args.previous)
    generated = f"Generated on {today} by `{command.strip()}` in {seconds / 60:.1f} min."
    write_csv(rows, args.out / "stability.csv")
    write_markdown(rows, args.out / "stability.md", generated, compared)
    for path in plot(rows, args.out):
        print("wrote", path)
    print(check_monotone_epsilon(rows))
    print(f"{len(rows)} rows in {seconds / 60:.1f} min -> {args.out / 'stability.md'}")


if __name__ == "__main__":
    main()
