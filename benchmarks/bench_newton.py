"""Newton iteration and cut-back counts on a Guccione ventricle inflated to 10 kPa.

Problem: the structured ventricle of :func:`harpx.anatomy.ventricle.ventricle` with
``n_circumferential=32, n_longitudinal=12, n_transmural=4`` (2176 hex8 cells), Guccione
myocardium ``C = 0.88 kPa, bf = 18.5, bt = 3.58, bfs = 1.63`` with ``κ = 880 kPa``
(``κ/C = 10³``), the base fixed (all components), a follower pressure on the endocardium
ramped to 10 kPa over ``--steps`` load steps (default 5), and the issue's box reproduction
(``box((10, 1, 1), (20, 2, 2))``, Guccione ``c=2, bf=8, bt=2, bfs=4, κ=2000``, fibres along
x, left face fixed, bottom pressure 0.004 kPa, one step at ``s = 0.2``).

Each case reports Newton iterations (linear solves), cut-backs, accepted load steps, whether
it converged, and wall time. Run the script on two revisions to compare them (e.g.
``git stash`` for the old solver), each with ``--label``; ``--out`` appends the rows to a
Markdown table::

    python benchmarks/bench_newton.py --label after --out benchmarks/results/newton.md
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def ventricle_case(steps: int) -> dict:
    from harpx.anatomy.ventricle import ventricle
    from harpx.mechanics import Body, Fixed, Pressure, solve
    from harpx.mechanics.materials import Guccione

    mesh = ventricle(n_circumferential=32, n_longitudinal=12, n_transmural=4, segments=False)
    c = 0.88
    body = Body(mesh, Guccione(c=c, bf=18.5, bt=3.58, bfs=1.63, kappa=1e3 * c))
    loads = [Fixed("base"), Pressure("endo", 10.0)]
    t0 = time.perf_counter()
    res = solve(body, loads, steps=steps, raise_on_failure=False)
    return {
        "case": f"ventricle {body.ncell} hex8, 10 kPa, {steps} steps",
        "converged": res.converged,
        "iterations": res.iterations,
        "cutbacks": res.cutbacks,
        "steps": len(res.load_factors),
        "wall": time.perf_counter() - t0,
        "reasons": ", ".join(
            f"{r} {getattr(res, 'cutback_reasons', []).count(r)}"
            for r in sorted(set(getattr(res, "cutback_reasons", [])))
        )
        or "-",
    }


def box_case() -> dict:
    from harpx.mechanics import Body, Fixed, Pressure, box, equilibrate
    from harpx.mechanics.materials import Guccione

    mesh = box((10.0, 1.0, 1.0), (20, 2, 2))
    fibers = np.tile([1.0, 0.0, 0.0], (80, 1))
    body = Body(mesh, Guccione(c=2, bf=8, bt=2, bfs=4, kappa=2000), fibers=fibers)
    t0 = time.perf_counter()
    res = equilibrate(body, [Fixed("left"), Pressure("bottom", 0.004)], s=0.2,
                      raise_on_failure=False)  # fmt: skip
    return {
        "case": "box 80 hex8, equilibrate s=0.2",
        "converged": res.converged,
        "iterations": res.iterations,
        "cutbacks": res.cutbacks,
        "steps": len(res.load_factors),
        "wall": time.perf_counter() - t0,
        "reasons": "-" if res.converged else res.message.split("(")[1].split(")")[0],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", default="current")
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    rows = [box_case(), ventricle_case(args.steps)]
    lines = []
    for r in rows:
        lines.append(
            f"| {args.label} | {r['case']} | {r['converged']} | {r['iterations']} | "
            f"{r['cutbacks']} | {r['reasons']} | {r['steps']} | {r['wall']:.1f} |"
        )
    header = (
        "| solver | case | converged | iterations | cut-backs | why (cut-back or failure) | "
        "accepted steps | wall (s) |\n| --- | --- | --- | --- | --- | --- | --- | --- |"
    )
    print(header)
    print("\n".join(lines))
    if args.out is not None:
        with args.out.open("a") as fh:
            fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
