"""Error against run time on the brain-phantom scene (paper §4.1).

Rows: conventional HARP and FE tracking (penalty and augmented Lagrangian; hex8 and hex20;
two mesh sizes; two upsampling factors; material stiffness ×10 and ×0.1). Every row reports
the displacement error against the analytic truth (mean ± sd, 95th percentile, max, in mm)
beside the wall time that produced it, including phase extraction. Writes
``benchmarks/results/error_vs_runtime.{csv,md,png}``.

Usage::

    python benchmarks/error_vs_runtime.py            # paper-size phantom, all rows
    python benchmarks/error_vs_runtime.py --size small --rows harp fe-hex8
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import track_harp
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import cylinder
from harpx.plotting import error_vs_runtime
from harpx.scenes.phantom import GEOMETRIES, phantom
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track

OUT = Path(__file__).resolve().parent / "results"

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
}


def _mesh(size: str, coarse: bool):
    g = GEOMETRIES[size]
    scale = 2 if coarse else 1
    n_circ = max(8, 4 * round(g.n_circumferential / scale / 4))
    return cylinder(
        g.radius, g.height, n_radial=max(1, g.n_radial // scale), n_circumferential=n_circ,
        n_axial=max(1, g.n_axial // scale), center=(0.0, 0.0, -g.height / 2),
    )


def run(size: str, rows: list[str]) -> list[dict]:
    scene = phantom(size)
    tagged = scene.tagged
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
            extra = {}
        else:
            # only C1 changes: κ stays 120 kPa (a different material, not a rescaled one)
            material = NeoHookean(c1=1.0 * cfg.get("c1_scale", 1.0), kappa=120.0)
            body = Body(_mesh(size, cfg.get("coarse", False)), material, element=cfg["element"])
            method = cfg.get("method", "penalty")
            out = track(phase, body, method=method, epsilon=0.05)
            label = f"FE {method} {cfg['element']} {body.ncell} cells, upsample {upsample}"
            if "c1_scale" in cfg:
                label += f", C1 x{cfg['c1_scale']:g}"
            extra = {
                "epsilon_max": float(np.nanmax(out.epsilon.values[1:])),
                "penalty_max": float(np.nanmax(out.penalty.values)),
                "iterations": int(out.iterations.sum()),
                **{k: float(v) for k, v in out.attrs.items() if k.startswith("time_")},
            }
        seconds = time.perf_counter() - t + phase_seconds
        err = tracking_error(out, tagged)
        row = {
            "row": name, "method": label, "seconds": round(seconds, 1),
            "phase_seconds": round(phase_seconds, 1),
            "mean": float(err.mean_all), "sd": float(err.sd_all), "p95": float(err.p95_all),
            "max": float(err.max_all), "coverage": float(err.coverage), **extra,
        }
        print(row, flush=True)
        results.append(row)
    return results


def write(results: list[dict], size: str) -> None:
    OUT.mkdir(exist_ok=True)
    stem = OUT / ("error_vs_runtime" if size == "paper" else f"error_vs_runtime_{size}")
    keys = sorted({k for r in results for k in r}, key=lambda k: list(results[0]).index(k) if k in results[0] else 99)
    with open(stem.with_suffix(".csv"), "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys)
        writer.writeheader()
        writer.writerows(results)
    lines = [
        "| method | mean ± sd (mm) | p95 (mm) | max (mm) | wall time (s) | Gauss–Newton it. | λ max |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in results:
        lines.append(
            f"| {r['method']} | {r['mean']:.3f} ± {r['sd']:.3f} | {r['p95']:.3f} | {r['max']:.2f} | "
            f"{r['seconds']:.1f} | {r.get('iterations', '')} | {r.get('penalty_max', '')} |"
        )
    stem.with_suffix(".md").write_text("\n".join(lines) + "\n")
    error_vs_runtime(results, path=stem.with_suffix(".png"))
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", choices=["paper", "small"], default="paper")
    parser.add_argument("--rows", nargs="+", choices=list(ROWS), default=list(ROWS))
    args = parser.parse_args()
    write(run(args.size, args.rows), args.size)


if __name__ == "__main__":
    main()
