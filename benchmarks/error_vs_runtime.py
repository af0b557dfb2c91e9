"""Error against run time on every scene, FE tracking with the tracker's defaults beside HARP.

Scenes: the brain phantom (paper §4.1), the left ventricle from the stress-free (SFR) and the
prestretched (PSR) reference (§4.2), the tongue (§4.3) and the short-axis scene with in-plane
tags only. Every scene's FE row uses the tracker's DEFAULT settings (a scene passes only its
boundary conditions) and conventional HARP runs on the same phase images (extracted with
``extract_phase`` defaults); both are scored by the same function
(:func:`harpx.tracking.results.tracking_error` against ``displacement_true`` of the scene's
tagged images). The phantom's extra rows vary what is not a tracking setting (element, mesh,
upsampling, material) and the enforcement method. Every row reports the error (mean ± sd,
95th percentile, max, in mm) beside the wall time that produced it as the result records it
(:func:`harpx.plotting.figures.run_seconds`: the tracker's ``time_total`` with its stages,
HARP's summed ``wall_time``), and the phase extraction that both share in its own column;
the figure is :func:`harpx.plotting.error_vs_runtime` of the tracked datasets and the
scene's truth. Writes ``benchmarks/results/error_vs_runtime[_<size>][_<scene>].{csv,md,png}``.

Usage::

    python benchmarks/error_vs_runtime.py                      # phantom, default rows
    python benchmarks/error_vs_runtime.py --scene lv --cache /tmp/lv.pkl
    python benchmarks/error_vs_runtime.py --scene tongue
    python benchmarks/error_vs_runtime.py --scene short-axis
    python benchmarks/error_vs_runtime.py --size small --rows harp fe-hex8
"""

from __future__ import annotations

import argparse
import csv
import pickle
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

from harpx.errors import HarpxError, HarpxWarning
from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import track_harp
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import cylinder
from harpx.plotting import error_vs_runtime
from harpx.plotting.figures import run_seconds
from harpx.scenes.lv import lv
from harpx.scenes.phantom import GEOMETRIES, phantom
from harpx.scenes.tongue import tongue
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track

OUT = Path(__file__).resolve().parent / "results"
# every row's tracked result and the scene's truth, for the error on the voxels all rows cover
OUTPUTS: list = []
TRUTH: list = []
# the tracker's defaults without the band-pass blur correction (one tracking pass, the
# paper's data term): kept as a row to show what the correction buys, side by side in one run
PREVIOUS = {"blur_passes": 0}

# name -> (kind, settings)
ROWS = {
    "harp": ("harp", {"upsample": 2}),
    "harp-up1": ("harp", {"upsample": 1}),
    "fe-hex8": ("fe", {"element": "hex8", "method": "penalty"}),
    "fe-hex8-al": ("fe", {"element": "hex8", "method": "augmented-lagrangian"}),
    "fe-hex8-coarse": ("fe", {"element": "hex8", "coarse": True}),
    "fe-hex8-up1": ("fe", {"element": "hex8", "upsample": 1}),
    "fe-hex8-c1x10": ("fe", {"element": "hex8", "c1_scale": 10.0}),
    "fe-hex8-c1x0.1": ("fe", {"element": "hex8", "c1_scale": 0.1}),
    "fe-hex20": ("fe", {"element": "hex20"}),
    "fe-hex8-noblur": ("fe", {"element": "hex8", "settings": PREVIOUS}),
}
LV_ROWS = {
    "harp": ("harp", {}),
    "sfr": ("fe", {"reference": "stress-free"}),
    "psr": ("fe", {"reference": "prestretched"}),
    "psr-noblur": ("fe", {"reference": "prestretched", **PREVIOUS}),
    "sfr-noblur": ("fe", {"reference": "stress-free", **PREVIOUS}),
    "psr-increment": ("fe", {"reference": "prestretched", "regularization": "increment"}),
}
SA_ROWS = {
    "harp": ("harp", {}),
    "fe": ("fe", {}),
    "fe-noblur": ("fe", PREVIOUS),
}
DEFAULT_ROWS = {"phantom": ["harp", "fe-hex8", "fe-hex8-noblur", "fe-hex8-coarse"]}
TONGUE_ROWS = {
    "harp": ("harp", {}),
    "fe-hex20": ("fe", {}),
    "fe-hex20-noblur": ("fe", PREVIOUS),
}
SCENE_ROWS = {"phantom": ROWS, "lv": LV_ROWS, "tongue": TONGUE_ROWS, "short-axis": SA_ROWS}


def _mesh(size: str, coarse: bool):
    g = GEOMETRIES[size]
    scale = 2 if coarse else 1
    n_circ = max(8, 4 * round(g.n_circumferential / scale / 4))
    return cylinder(
        g.radius,
        g.height,
        n_radial=max(1, g.n_radial // scale),
        n_circumferential=n_circ,
        n_axial=max(1, g.n_axial // scale),
        center=(0.0, 0.0, -g.height / 2),
    )


def _row(name: str, label: str, out, truth, seconds: float, phase_seconds: float) -> dict:
    """A table row; ``seconds`` (measured around the call, for a check) is replaced by the
    run time the result records."""
    err = tracking_error(out, truth)
    recorded = run_seconds(out)
    row = {
        "row": name,
        "method": label,
        "seconds": round(recorded, 1),
        "measured_seconds": round(seconds - phase_seconds, 1),
        "phase_seconds": round(phase_seconds, 1),
        "mean": float(err.mean_all),
        "sd": float(err.sd_all),
        "p95": float(err.p95_all),
        "max": float(err.max_all),
        "coverage": float(err.coverage),
    }
    if "penalty" in out:  # FE tracking diagnostics
        row.update(
            {
                "epsilon_max": float(np.nanmax(out.epsilon.values[1:])),
                "penalty_max": float(np.nanmax(out.penalty.values)),
                # every pass's Gauss–Newton iterations (the correction pass included)
                "iterations": int(np.sum(out.attrs.get("iterations_per_pass", out.iterations))),
                **{k: float(v) for k, v in out.attrs.items() if k.startswith("time_")},
            }
        )
    print(row, flush=True)
    return row


def run(size: str, rows: list[str]) -> list[dict]:
    """Phantom rows."""
    scene = phantom(size)
    tagged = scene.tagged
    TRUTH.append(tagged)
    phases: dict[int, tuple] = {}
    results = []
    for name in rows:
        kind, cfg = ROWS[name]
        upsample = int(cfg.get("upsample", 2))
        if upsample not in phases:
            t = time.perf_counter()
            phases[upsample] = (extract_phase(tagged, upsample=upsample), time.perf_counter() - t)
        phase, phase_seconds = phases[upsample]
        t = time.perf_counter()
        if kind == "harp":
            out = track_harp(phase, points=tagged)
            label = f"HARP (upsample {upsample})"
        else:
            # only C1 changes: κ stays 120 kPa (a different material, not a rescaled one)
            material = NeoHookean(c1=1.0 * cfg.get("c1_scale", 1.0), kappa=120.0)
            body = Body(_mesh(size, cfg.get("coarse", False)), material, element=cfg["element"])
            method = cfg.get("method", "penalty")
            out = track(phase, body, method=method, **cfg.get("settings", {}))
            label = f"FE {method} {cfg['element']} {body.ncell} cells, upsample {upsample}"
            if "settings" in cfg:
                label += ", no blur correction"
            if "c1_scale" in cfg:
                label += f", C1 x{cfg['c1_scale']:g}"
        seconds = time.perf_counter() - t + phase_seconds
        results.append(_row(name, label, out, tagged, seconds, phase_seconds))
        OUTPUTS.append(out)
    return results


def run_lv(size: str, rows: list[str], cache: Path | None) -> list[dict]:
    """Left-ventricle rows (the scene is built once, or loaded from ``cache``)."""
    if cache is not None and cache.exists():
        with cache.open("rb") as f:
            scene = pickle.load(f)
        if isinstance(scene, tuple):  # (scene, phase) caches of other scripts
            scene = scene[0]
    else:
        scene = lv(size=size)
        if cache is not None:
            with cache.open("wb") as f:
                pickle.dump(scene, f)
    t = time.perf_counter()
    phase = extract_phase(scene.tagged)
    phase_seconds = time.perf_counter() - t
    results = []
    for name in rows:
        kind, cfg = LV_ROWS[name]
        t = time.perf_counter()
        if kind == "harp":
            out = track_harp(phase, points=scene.tagged)
            label = "LV: HARP"
        else:
            body = scene.body(cfg["reference"])  # the prestretch is computed once, untimed
            t = time.perf_counter()
            short = "SFR" if cfg["reference"] == "stress-free" else "PSR"
            extra = {k: v for k, v in cfg.items() if k != "reference"}
            label = f"LV: FE {short} hex8 {body.ncell} cells" + "".join(
                f", {k} {v}" for k, v in extra.items()
            )
            try:
                out = track(phase, body, dirichlet=scene.dirichlet(), **extra)
            except HarpxError as exc:
                print({"row": name, "method": label, "failed": str(exc)[:200]}, flush=True)
                continue
        seconds = time.perf_counter() - t + phase_seconds
        results.append(_row(f"lv-{name}", label, out, scene.tagged, seconds, phase_seconds))
        OUTPUTS.append(out)
    TRUTH.append(scene.tagged)
    return results


def run_tongue(size: str, rows: list[str]) -> list[dict]:
    """Tongue rows."""
    scene = tongue(size)
    t = time.perf_counter()
    phase = extract_phase(scene.tagged)
    phase_seconds = time.perf_counter() - t
    grid = {d: scene.tagged[d] for d in ("z", "y", "x")}  # same grid up to round-off
    results = []
    for name in rows:
        kind, cfg = TONGUE_ROWS[name]
        t = time.perf_counter()
        if kind == "harp":
            out = track_harp(phase, points=scene.tagged)
            label = "tongue: HARP"
        else:
            body = scene.body("hex20")
            out = track(phase, body, dirichlet=list(scene.dirichlet), **cfg)
            out = out.assign_coords(grid)
            label = f"tongue: FE hex20 {body.ncell} cells" + (", no blur correction" if cfg else "")
        seconds = time.perf_counter() - t + phase_seconds
        results.append(_row(f"tongue-{name}", label, out, scene.tagged, seconds, phase_seconds))
        OUTPUTS.append(out)
    TRUTH.append(scene.tagged)
    return results


def run_short_axis(size: str, rows: list[str]) -> list[dict]:
    """Short-axis rows: in-plane tags only; the error split in-plane / through-plane."""
    from harpx.scenes.short_axis import short_axis

    scene = short_axis(size)
    t = time.perf_counter()
    phase = extract_phase(scene.tagged)
    phase_seconds = time.perf_counter() - t
    results = []
    for name in rows:
        kind, cfg = SA_ROWS[name]
        t = time.perf_counter()
        warned = ""
        if kind == "harp":
            out = track_harp(phase, points=scene.tagged)
            label = "short-axis: HARP"
        else:
            body = scene.body()
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                out = track(phase, body, dirichlet=list(scene.dirichlet), **cfg)
            warned = " / ".join(str(w.message)[:80] for w in caught
                                if issubclass(w.category, HarpxWarning))  # fmt: skip
            label = f"short-axis: FE hex8 {body.ncell} cells" + (
                ", no blur correction" if cfg else ""
            )
        seconds = time.perf_counter() - t + phase_seconds
        row = _row(f"sa-{name}", label, out, scene.tagged, seconds, phase_seconds)
        row.update(_split(out, scene.tagged))
        row["warning"] = warned
        results.append(row)
        OUTPUTS.append(out)
        print(row, flush=True)
    TRUTH.append(scene.tagged)
    return results


def _split(out, truth) -> dict:
    """In-plane error and through-plane drift (body-mean u_z against the truth's) per frame."""
    true = truth["displacement_true"]
    est = out["displacement_grid"].assign_coords(z=true.z, y=true.y, x=true.x, time=true.time)
    diff = (est - true).isel(time=slice(1, None))
    inplane = np.sqrt((diff.sel(axis=["x", "y"]) ** 2).sum("axis", skipna=False)).values
    inplane = inplane[np.isfinite(inplane)]
    both = np.isfinite(est.sel(axis="z")) & np.isfinite(true.sel(axis="z"))
    drift = (est.sel(axis="z").where(both).mean(("z", "y", "x"))
             - true.sel(axis="z").where(both).mean(("z", "y", "x")))  # fmt: skip
    return {
        "inplane_mean": float(inplane.mean()),
        "inplane_p95": float(np.percentile(inplane, 95)),
        "drift_max": float(np.abs(drift.values[1:]).max()),
    }


def _covered(out, true) -> np.ndarray:
    """Voxels (time, z, y, x) of ``true``'s grid where ``out`` has a displacement."""
    est = out["displacement_grid"]
    if all(est.sizes[d] == true.sizes[d] for d in ("z", "y", "x")):
        values = est.values
    else:  # as tracking_error matches grids: linear, then the nearest voxel
        grid = {d: true[d] for d in ("z", "y", "x")}
        values = est.interp(grid).fillna(est.interp(grid, method="nearest")).values
    return np.isfinite(values).all(axis=1)


def add_common(results: list[dict]) -> None:
    """Error of every row on the voxels that every row (HARP included) covers.

    The rows cover different voxels (HARP loses points whose phase is invalid; a mesh covers
    what its cells reach), so the overall means compare different sets; the common set is
    the like-for-like comparison.
    """
    if not OUTPUTS or not TRUTH:
        return
    true = TRUTH[0]["displacement_true"]
    common = np.isfinite(true.values).all(axis=1)
    for out in OUTPUTS:
        common &= _covered(out, true)
    where = xr.DataArray(common, dims=("time", "z", "y", "x"),
                         coords={d: true[d] for d in ("time", "z", "y", "x")})  # fmt: skip
    share = common[1:].sum() / max(1, np.isfinite(true.values).all(axis=1)[1:].sum())
    for row, out in zip(results, OUTPUTS, strict=True):
        err = tracking_error(out, TRUTH[0], where=where)
        row.update({"common_mean": float(err.mean_all), "common_p95": float(err.p95_all),
                    "common_max": float(err.max_all), "common_share": float(share)})  # fmt: skip
        print(row["row"], {k: round(v, 3) for k, v in row.items() if k.startswith("common")})


def write(results: list[dict], size: str, scene: str = "phantom") -> None:
    OUT.mkdir(exist_ok=True)
    stem = "error_vs_runtime" + ("" if size == "paper" else f"_{size}")
    stem = OUT / (stem + ("" if scene == "phantom" else f"_{scene}"))
    keys = sorted(
        {k for r in results for k in r},
        key=lambda k: list(results[0]).index(k) if k in results[0] else 99,
    )
    with open(stem.with_suffix(".csv"), "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys)
        writer.writeheader()
        writer.writerows(results)
    header = ["method", "mean ± sd (mm)", "p95 (mm)", "max (mm)", "coverage",
              "common voxels: mean / p95 / max (mm)",
              "wall time (s)", "phase extraction (s)", "Gauss–Newton it.", "λ max"]  # fmt: skip
    sa = any("inplane_mean" in r for r in results)
    if sa:
        header += ["in-plane mean / p95 (mm)", "max drift of mean u_z (mm)"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in results:
        cells = [
            r["method"], f"{r['mean']:.3f} ± {r['sd']:.3f}", f"{r['p95']:.3f}",
            f"{r['max']:.2f}", f"{r['coverage']:.3f}",
            f"{r['common_mean']:.3f} / {r['common_p95']:.3f} / {r['common_max']:.2f}"
            if "common_mean" in r else "",
            f"{r['seconds']:.1f}",
            f"{r['phase_seconds']:.1f}",
            str(r.get("iterations", "")),
            str(r.get("penalty_max", "")),
        ]  # fmt: skip
        if sa:
            cells += [f"{r['inplane_mean']:.3f} / {r['inplane_p95']:.3f}", f"{r['drift_max']:.3f}"]
        lines.append("| " + " | ".join(cells) + " |")
    if results and "common_share" in results[0]:
        lines.append("")
        lines.append(
            f"Common voxels: the {100 * results[0]['common_share']:.1f} % of body voxel-frames "
            "(frames 1..) that every row covers; coverage: the share each row covers."
        )
    stem.with_suffix(".md").write_text("\n".join(lines) + "\n")
    # the figure straight from the tracked datasets and the scene's truth
    labels = [r["method"] for r in results]
    error_vs_runtime(dict(zip(labels, OUTPUTS, strict=True)), TRUTH[0],
                     path=stem.with_suffix(".png"))  # fmt: skip
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", choices=["paper", "small"], default="paper")
    parser.add_argument("--scene", choices=list(SCENE_ROWS), default="phantom")
    parser.add_argument(
        "--rows",
        nargs="+",
        default=None,
        help="rows to run (default: all of the scene's); phantom: "
        f"{', '.join(ROWS)}; lv: {', '.join(LV_ROWS)}; tongue: "
        f"{', '.join(TONGUE_ROWS)}",
    )
    parser.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="LV only: pickle of the built scene, loaded if it exists",
    )
    args = parser.parse_args()
    choices = SCENE_ROWS[args.scene]
    rows = args.rows or DEFAULT_ROWS.get(args.scene, list(choices))
    unknown = [r for r in rows if r not in choices]
    if unknown:
        parser.error(f"--rows {unknown} are not rows of --scene {args.scene}: {list(choices)}")
    if args.scene == "phantom":
        results = run(args.size, rows)
    elif args.scene == "lv":
        results = run_lv(args.size, rows, args.cache)
    elif args.scene == "short-axis":
        results = run_short_axis(args.size, rows)
    else:
        results = run_tongue(args.size, rows)
    add_common(results)
    write(results, args.size, args.scene)


if __name__ == "__main__":
    main()
