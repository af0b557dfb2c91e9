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

``--land`` runs instead Land et al. 2015 problem 2 (passive inflation of the truncated
ellipsoid: endocardium rs = 7, rl = 17 mm, epicardium rs = 10, rl = 20 mm, base plane
z = 5 mm; isotropic Guccione C = 10 kPa, bf = bt = bfs = 1, nearly incompressible
κ = 10⁴ C; base fixed; 10 kPa follower pressure on the endocardium) on
``ventricle(..., curved=True)`` with hex20 Q2/P1 (``volumetric="linear-dilatation"``) in
one plain ``solve(steps=10)``, at the ventricle levels of ``benchmarks/bench_community.py``
(``--land-levels 0 1 2``: 44, 320, 1116 cells). It reports, besides the counts, the deformed
z of the endocardial and epicardial apex and the cavity volume
(:func:`harpx.anatomy.ventricle.cavity_volume`). ``--land-solver before`` reproduces the
displacement-only Newton (volumetric tangent at each iterate's own dilatation,
``_Newton.carry_dilatation = False``) in the same revision::

    python benchmarks/bench_newton.py --land --land-levels 1 --land-solver after before
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


def _reasons(reasons: list[str]) -> str:
    return ", ".join(f"{r} {reasons.count(r)}" for r in sorted(set(reasons))) or "-"


LAND_LEVELS = [(8, 4, 1), (16, 8, 2), (24, 12, 3)]


def land_case(level: tuple[int, int, int], solver: str) -> dict:
    """Land et al. 2015 problem 2 at κ = 10⁴ C, curved hex20 Q2/P1, ``solve(steps=10)``."""
    from harpx.anatomy.ventricle import cavity_volume, ventricle
    from harpx.mechanics import Body, Fixed, Guccione, Pressure, solve
    from harpx.mechanics.newton import _Newton

    nc, nl, nt = level
    spec = ventricle(inner=(7.0, 17.0), outer=(10.0, 20.0), truncation=5.0,
                     n_circumferential=nc, n_longitudinal=nl, n_transmural=nt,
                     segments=False, curved=True)  # fmt: skip
    c = 10.0
    body = Body(spec.mesh, Guccione(c=c, bf=1.0, bt=1.0, bfs=1.0, kappa=1e4 * c),
                fibers=spec.fibers, element="hex20", volumetric="linear-dilatation",
                boundaries=spec.boundaries, regions=spec.regions)  # fmt: skip
    loads = [Fixed("base", (0, 1, 2)), Pressure("endo", 10.0)]
    _Newton.carry_dilatation = solver == "after"
    try:
        t0 = time.perf_counter()
        res = solve(body, loads, steps=10, raise_on_failure=False, progress=False)
        wall = time.perf_counter() - t0
    finally:
        _Newton.carry_dilatation = True
    # the apices are dof nodes (n_circumferential a multiple of 8)
    apex = np.array([[0.0, 0.0, -17.0], [0.0, 0.0, -20.0]])
    node = np.linalg.norm(body.dof_points[None] - apex[:, None], axis=-1).argmin(axis=1)
    z = apex[:, 2] + body.nodal_displacement(res.u)[node, 2]
    return {
        "case": f"Land P2, {body.ncell} curved hex20 Q2/P1 ({body.ndof} dofs), κ = 1e4 C",
        "converged": res.converged,
        "iterations": res.iterations,
        "cutbacks": res.cutbacks,
        "steps": len(res.load_factors),
        "wall": wall,
        "reasons": _reasons(res.cutback_reasons),
        "endo": float(z[0]),
        "epi": float(z[1]),
        "volume": cavity_volume(body, res.u),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", default="current")
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--land", action="store_true", help="Land problem 2 instead")
    parser.add_argument("--land-levels", nargs="+", type=int, default=[1],
                        help="ventricle levels (0 = coarsest)")  # fmt: skip
    parser.add_argument("--land-solver", nargs="+", default=["after"],
                        choices=["after", "before"])  # fmt: skip
    args = parser.parse_args()
    if args.land:
        _land(args)
        return
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


def _land(args: argparse.Namespace) -> None:
    header = (
        "| solver | case | converged | iterations | cut-backs | why (cut-back) | accepted "
        "steps | endo apex z (mm) | epi apex z (mm) | cavity volume (mm³) | wall (s) |\n"
        + "|"
        + " --- |" * 11
    )
    print(header, flush=True)
    lines = []
    for level in args.land_levels:
        for solver in args.land_solver:
            r = land_case(LAND_LEVELS[level], solver)
            lines.append(
                f"| {solver} ({args.label}) | {r['case']} | {r['converged']} | "
                f"{r['iterations']} | {r['cutbacks']} | {r['reasons']} | {r['steps']} | "
                f"{r['endo']:.5f} | {r['epi']:.5f} | {r['volume']:.3f} | {r['wall']:.1f} |"
            )
            print(lines[-1], flush=True)
    if args.out is not None:
        with args.out.open("a") as fh:
            fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
