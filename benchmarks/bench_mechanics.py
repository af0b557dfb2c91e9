"""Benchmark of the hyperelastic FE solver against the scikit-fem form-style "peer".

Problem: a 25 x 17 x 10 mm box of 25 x 17 x 10 = 4250 hexahedra (hex8: 15.4k dofs, hex20:
59k dofs), uncoupled neo-Hookean C1 = 1 kPa, κ = 120 kPa, bottom clamped, top face twisted by
10° about the vertical centre line and lifted by 1 mm, three load steps.

* **ours**: ``harpx.mechanics.solve`` (vectorised assembly, pattern built once, mean
  dilatation, PARDISO with symbolic-analysis reuse).
* **peer**: the same problem written the way scikit-fem's documented hyperelasticity example
  writes its forms: ``BilinearForm``/``LinearForm`` with ``skfem.helpers`` on an
  ``ElementVector`` basis, ``skfem.condense`` and ``skfem.solve`` (SciPy SuperLU), assembled
  afresh every Newton iteration (plain displacement formulation).
* **linear solvers** on our tangent (after the first Newton iteration, Dirichlet rows/columns
  eliminated): PARDISO (first call with analysis; later calls reuse it), SuperLU COLAMD,
  SuperLU MMD_AT_PLUS_A in symmetric mode, smoothed-aggregation AMG-CG with and without the
  rigid-body near-nullspace.

Each part runs in its own process so that its peak memory (``ru_maxrss``) is its own.
Run ``python benchmarks/bench_mechanics.py`` (``--quick`` for a 10 x 7 x 4 box); it prints a
Markdown table and the ratios. Timings are wall-clock seconds on this machine.

Before/after (``benchmarks/results/mechanics.md``): run single parts with each checkout on
``PYTHONPATH`` (the old one from a temporary ``git worktree``), alternating, several times:
``--part ours --element hex8`` (the Newton run: assembly and solve per iteration) and
``--part assembly --element hex8 --mesh phantom`` (one residual-and-tangent assembly at a
random displacement, min and median of 7; ``--mesh box`` is the box above, ``phantom`` the
paper phantom's 4320-cell cylinder that ``benchmarks/bench_tracking.py`` tracks with).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np

DIVISIONS = (25, 17, 10)
TWIST_DEG = 10.0
LIFT = 1.0
C1, KAPPA = 1.0, 120.0


def _loads_ours(body):
    from harpx.mechanics import Fixed, Prescribed

    L = np.array(DIVISIONS, dtype=float)
    centre = np.array([L[0] / 2, L[1] / 2, 0.0])
    th = np.deg2rad(TWIST_DEG)

    def twist(X, s):
        c, sn = np.cos(s * th), np.sin(s * th)
        Y = X - centre
        R = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
        return Y @ R.T - Y + s * np.array([0.0, 0.0, LIFT])

    return [Fixed("bottom"), Prescribed("top", twist)]


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def part_ours(element: str, divisions) -> dict:
    from harpx.mechanics import Body, NeoHookean, box, solve
    from harpx.mechanics.assembly import internal_forces, sparsity

    t0 = time.perf_counter()
    body = Body(box(tuple(float(d) for d in divisions), divisions), NeoHookean(C1, KAPPA),
                element=element)  # fmt: skip
    t_body = time.perf_counter() - t0
    t0 = time.perf_counter()
    sparsity(body)
    t_pattern = time.perf_counter() - t0
    u = np.zeros(body.ndof)
    from harpx.mechanics.linsolve import LinearSolver

    LinearSolver("auto")  # one-time MKL library lookup, outside the timings
    internal_forces(body, u)  # warm-up
    reps = 3
    t0 = time.perf_counter()
    for _ in range(reps):
        internal_forces(body, u)
    t_asm = (time.perf_counter() - t0) / reps
    t0 = time.perf_counter()
    res = solve(body, _loads_ours(body), steps=3, linear_solver="auto")
    wall = time.perf_counter() - t0
    return {
        "ndof": body.ndof,
        "ncell": body.ncell,
        "body_setup": t_body,
        "pattern": t_pattern,
        "assembly_one": t_asm,
        "iterations": res.iterations,
        "history": res.residual_history[0],
        "cutbacks": res.cutbacks,
        "wall": wall,
        "per_iteration": wall / res.iterations,
        "assembly_per_iteration": res.time_assembly / res.iterations,
        "solve_per_iteration": res.time_solve / res.iterations,
        "converged": res.converged,
        "peak_mb": _peak_mb(),
    }


def part_assembly(element: str, divisions, mesh: str) -> dict:
    from harpx.mechanics import Body, NeoHookean, box, cylinder
    from harpx.mechanics.assembly import internal_forces, sparsity

    if mesh == "phantom":  # harpx.scenes.phantom "paper": 48 x 6 rings + core, 10 layers
        spec = cylinder(60.0, 15.0, n_radial=6, n_circumferential=48, n_axial=10)
    else:
        spec = box(tuple(float(d) for d in divisions), divisions)
    body = Body(spec, NeoHookean(C1, KAPPA), element=element)
    sparsity(body)
    rng = np.random.default_rng(0)
    u = (0.02 if element == "hex8" else 0.01) * rng.standard_normal(body.ndof)
    internal_forces(body, u)  # warm-up (cached gradient layouts)
    times = []
    for _ in range(7):
        t0 = time.perf_counter()
        internal_forces(body, u)
        times.append(time.perf_counter() - t0)
    return {
        "mesh": mesh,
        "ncell": body.ncell,
        "ndof": body.ndof,
        "assembly_min": min(times),
        "assembly_median": float(np.median(times)),
        "peak_mb": _peak_mb(),
    }


def part_peer(element: str, divisions, iterations: int) -> dict:
    import skfem
    from skfem.helpers import ddot, det, eye, grad, inv, mul, transpose

    t0 = time.perf_counter()
    L = [float(d) for d in divisions]
    mesh = skfem.MeshHex.init_tensor(*[np.linspace(0.0, L[i], divisions[i] + 1) for i in range(3)])
    elem = skfem.ElementHex1() if element == "hex8" else skfem.ElementHexS2()
    basis = skfem.Basis(mesh, skfem.ElementVector(elem), intorder=3 if element == "hex8" else 5)
    t_basis = time.perf_counter() - t0

    def first_piola(F):
        J = det(F)
        Finv_T = transpose(inv(F))
        I1 = ddot(F, F)
        a = J ** (-2.0 / 3.0)
        return 2 * C1 * a * (F - I1 / 3.0 * Finv_T) + KAPPA * np.log(J) * Finv_T

    def dP(F, dF):
        J = det(F)
        H = transpose(inv(F))
        I1 = ddot(F, F)
        a = J ** (-2.0 / 3.0)
        HdF = ddot(H, dF)
        FdF = ddot(F, dF)
        HdFtH = mul(H, mul(transpose(dF), H))
        iso = 2 * C1 * a * (dF - 2.0 / 3.0 * (HdF * F + FdF * H) + 2.0 / 9.0 * I1 * HdF * H
                            + I1 / 3.0 * HdFtH)  # fmt: skip
        vol = KAPPA * (HdF * H - np.log(J) * HdFtH)
        return iso + vol

    @skfem.LinearForm
    def residual(v, w):
        F = grad(w["u"]) + eye(np.ones(w["u"].shape[1:]), 3)
        return ddot(first_piola(F), grad(v))

    @skfem.BilinearForm
    def tangent(du, v, w):
        F = grad(w["u"]) + eye(np.ones(w["u"].shape[1:]), 3)
        return ddot(dP(F, grad(du)), grad(v))

    th = np.deg2rad(TWIST_DEG)
    centre = np.array([L[0] / 2, L[1] / 2, 0.0])
    bottom = basis.get_dofs(lambda x: np.isclose(x[2], 0.0)).all()
    top = basis.get_dofs(lambda x: np.isclose(x[2], L[2])).all()
    X = basis.doflocs
    c, sn = np.cos(th), np.sin(th)
    Y = X - centre[:, None]
    R = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    target = R @ Y - Y + np.array([[0.0], [0.0], [LIFT]])
    u = np.zeros(basis.N)
    # dof k of an ElementVector basis carries component k % 3 at doflocs[:, k]; half the
    # load (the first of the three load steps), applied through the linearised predictor
    g = np.zeros(basis.N)
    g[top] = target[top % 3, top] / 3.0
    D = np.concatenate([bottom, top])
    t_asm = t_solve = 0.0
    history = []
    for _ in range(iterations):
        t0 = time.perf_counter()
        uu = basis.interpolate(u)
        K = skfem.asm(tangent, basis, u=uu)
        r = skfem.asm(residual, basis, u=uu)
        t_asm += time.perf_counter() - t0
        rf = r.copy()
        rf[D] = 0.0
        history.append(float(np.linalg.norm(rf)))
        t0 = time.perf_counter()
        du = skfem.solve(*skfem.condense(K, -r, x=g - u, D=D))
        t_solve += time.perf_counter() - t0
        u += du
    return {
        "ndof": int(basis.N),
        "basis_setup": t_basis,
        "iterations": iterations,
        "assembly_per_iteration": t_asm / iterations,
        "solve_per_iteration": t_solve / iterations,
        "per_iteration": (t_asm + t_solve) / iterations,
        "history": history,
        "peak_mb": _peak_mb(),
    }


def part_solvers(element: str, divisions, amg: bool) -> dict:
    from scipy.sparse import linalg as spla

    from harpx.mechanics import Body, NeoHookean, box
    from harpx.mechanics.linsolve import LinearSolver, rigid_body_modes
    from harpx.mechanics.newton import _Newton

    body = Body(box(tuple(float(d) for d in divisions), divisions), NeoHookean(C1, KAPPA),
                element=element)  # fmt: skip
    nt = _Newton(body, _loads_ours(body), tol=1e-8, atol=None, max_iterations=25,
                 line_search=True, linear_solver="auto")  # fmt: skip
    # converged state at a third of the load (a stable, deformed equilibrium), then the
    # tangent of the next load step's first iteration
    out = nt.run(np.zeros(body.ndof), 1.0 / 3.0)
    asm = nt.assemble(out.u, 2.0 / 3.0)
    RF = asm.R.copy()
    RF[nt.D] = 0.0
    data = asm.data
    data[nt.zero_mask] = 0.0
    data[nt.diag_D] = np.abs(data[nt.pattern.diagonal]).mean()
    K = nt.pattern.matrix(data)
    b = -RF
    times: dict = {}

    def timed(name, fn, reps=1):
        t0 = time.perf_counter()
        for _ in range(reps):
            x = fn()
        times[name] = (time.perf_counter() - t0) / reps
        times[name + "_residual"] = float(np.linalg.norm(K @ x - b) / np.linalg.norm(b))

    try:
        ls = LinearSolver("pardiso")
        timed("pardiso_first", lambda: ls.solve(K, b, symmetric=True))
        timed("pardiso_reuse", lambda: ls.solve(K, b, symmetric=True), reps=2)
        ls.close()
    except ValueError:
        pass
    timed("superlu_colamd", lambda: spla.splu(K.tocsc()).solve(b))
    sym = {"SymmetricMode": True}
    timed("superlu_mmd_sym", lambda: spla.splu(K.tocsc(), permc_spec="MMD_AT_PLUS_A",
                                               diag_pivot_thresh=0.0,
                                               options=sym).solve(b))  # fmt: skip
    if amg:
        import pyamg

        B = rigid_body_modes(body.dof_points + out.u.reshape(-1, 3))

        def amg_solve(with_b: bool):
            its: list = []
            ml = pyamg.smoothed_aggregation_solver(K, B=B if with_b else None,
                                                   symmetry="symmetric")  # fmt: skip
            x = ml.solve(b, tol=1e-8, accel="cg", maxiter=100, residuals=its)
            times["amg_iterations_" + ("rbm" if with_b else "default")] = len(its) - 1
            return x

        timed("amg_cg_rbm", lambda: amg_solve(True))
        timed("amg_cg_default", lambda: amg_solve(False))
    times["ndof"] = body.ndof
    times["nnz"] = int(K.nnz)
    times["peak_mb"] = _peak_mb()
    return times


def _run(part: str, element: str, divisions, extra: list[str]) -> dict:
    cmd = [sys.executable, __file__, "--part", part, "--element", element,
           "--divisions", *map(str, divisions), *extra]  # fmt: skip
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=["ours", "peer", "solvers", "assembly"])
    ap.add_argument("--mesh", choices=["box", "phantom"], default="box")
    ap.add_argument("--element", default="hex8")
    ap.add_argument("--divisions", type=int, nargs=3, default=list(DIVISIONS))
    ap.add_argument("--peer-iterations", type=int, default=None)
    ap.add_argument("--quick", action="store_true", help="10 x 7 x 4 box")
    ap.add_argument("--no-amg", action="store_true")
    args = ap.parse_args()
    divisions = tuple(args.divisions)
    if args.part:
        if args.part == "ours":
            res = part_ours(args.element, divisions)
        elif args.part == "assembly":
            res = part_assembly(args.element, divisions, args.mesh)
        elif args.part == "peer":
            n = args.peer_iterations or (3 if args.element == "hex8" else 1)
            res = part_peer(args.element, divisions, n)
        else:
            res = part_solvers(args.element, divisions, not args.no_amg)
        print(json.dumps(res))
        return
    if args.quick:
        divisions = (10, 7, 4)
    rows = []
    for element in ("hex8", "hex20"):
        ours = _run("ours", element, divisions, [])
        peer_its = [
            "--peer-iterations",
            str(args.peer_iterations or (3 if element == "hex8" else 1)),
        ]
        peer = _run("peer", element, divisions, peer_its)
        solvers = _run("solvers", element, divisions, ["--no-amg"] if args.no_amg else [])
        rows.append((element, ours, peer, solvers))
    print(f"\nBox {divisions} cells, twist {TWIST_DEG}° + lift {LIFT} mm, three load steps\n")
    print(
        "| element | dofs | who | assembly / it [s] | solve / it [s] | Newton it [s] "
        "| assembly share | its | peak RSS [MB] |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for element, ours, peer, _ in rows:
        for who, r in (("harpx", ours), ("skfem forms (peer)", peer)):
            share = r["assembly_per_iteration"] / r["per_iteration"]
            print(f"| {element} | {r['ndof']} | {who} | {r['assembly_per_iteration']:.3f} | "
                  f"{r['solve_per_iteration']:.3f} | {r['per_iteration']:.3f} | {share:.0%} | "
                  f"{r['iterations']} | {r['peak_mb']:.0f} |")  # fmt: skip
    print(
        "\n| element | pattern (once) [s] | body set-up [s] | one tangent assembly [s] "
        "| Newton it speed-up vs peer | assembly speed-up |"
    )
    print("|---|---|---|---|---|---|")
    for element, ours, peer, _ in rows:
        speedup = peer["per_iteration"] / ours["per_iteration"]
        print(f"| {element} | {ours['pattern']:.3f} | {ours['body_setup']:.3f} | "
              f"{ours['assembly_one']:.3f} | {speedup:.1f}x | "
              f"{peer['assembly_per_iteration'] / ours['assembly_one']:.0f}x |")  # fmt: skip
    print(
        "\nLinear solvers on the tangent (Dirichlet eliminated), seconds per solve "
        "(relative residual):\n"
    )
    names = ["pardiso_first", "pardiso_reuse", "superlu_colamd", "superlu_mmd_sym",
             "amg_cg_rbm", "amg_cg_default"]  # fmt: skip
    print("| element | dofs | nnz | " + " | ".join(names) + " |")
    print("|---|---|---|" + "---|" * len(names))
    for element, _, _, s in rows:
        cells = []
        for n in names:
            if n in s:
                extra = ""
                if n.startswith("amg"):
                    key = "amg_iterations_" + ("rbm" if n.endswith("rbm") else "default")
                    extra = f", {s[key]} it"
                cells.append(f"{s[n]:.3f} ({s[n + '_residual']:.0e}{extra})")
            else:
                cells.append("n/a")
        print(f"| {element} | {s['ndof']} | {s['nnz']} | " + " | ".join(cells) + " |")
    for element, ours, peer, _ in rows:
        ours_history = [format(h, ".2e") for h in ours["history"]]
        peer_history = [format(h, ".2e") for h in peer["history"]]
        print(f"\n{element}: harpx residual history {ours_history}")
        print(f"{element}: peer  residual history {peer_history}")


if __name__ == "__main__":
    main()
