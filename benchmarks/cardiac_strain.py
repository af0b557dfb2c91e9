"""Per-segment peak strain of FE tracking and conventional HARP against the LV scene's truth.

The left-ventricle scene (``harpx.scenes.lv``, optionally with a regional infarct:
``--infarct 7 8 13 14 --scar-activation 0.5``) is imaged (CSPAMM, SA + LA slices), the
template is fitted to the scene's own body mask (as a user would fit it to a segmentation;
the anterior direction given as the scene's, +y), and the strain in the template's local
frame is averaged over the 17 AHA segments for

* the truth: the forward simulation's fine-mesh cell strains (``scene.truth_result()``);
* the FE tracking result (stress-free reference, the tracker's defaults unless
  ``--epsilon``) with the scene's template mesh, and with a hexahedral mesh of the body
  mask (``mesh_from_labels``, names, fibres and base conditions from the fitted template);
* conventional HARP (per voxel), its strain by central differences between voxel centres;
* the truth's displacement on the same voxels, differentiated the same way (what a voxel
  method could at best reach on this grid);
* the truth's displacement at the tracking mesh's nodes, interpolated by its cells: the
  tracking mesh's own discretisation error (not a strict floor: a fit to the images can
  come closer than the nodal interpolant).

Phase extraction: upsample 2 (the library's default) and band-pass radius 0.8 (``--radius``;
the library's default is 0.5, which SPAMM's DC peak needs): CSPAMM has no DC peak, and the
wider filter blurs the 10 mm wall less (``benchmarks/results/infarct_radius.md``).
``--blur-passes`` sets the tracker's blur-correction passes (default: the tracker's, 1);
``--set NAME=VALUE ...`` any other numeric tracker setting (e.g. ``epsilon_factor=1.0``);
``--divisions NC NL NT`` a template tracking mesh other than the scene's; ``--snr`` the
images' signal-to-noise ratio (``none``: noise free); ``--seed N`` another realisation of
the images' noise (same motion), written beside the recorded table as ``..._seedN.md``.

Summary statistics are over segments 1-16 (the short-axis segments; HARP has no value in
the apical cap 17, which only long-axis slices image); segment 17 is listed per segment.
Errors are ``peak - true peak``; the radial error is also given relative to the true peak
radial strain: mean over segments of ``|error|`` divided by the mean ``|true peak|``.

Writes ``benchmarks/results/cardiac_strain[_<size>].md`` (healthy) or
``benchmarks/results/infarct_<size>.md`` (with ``--infarct``), or ``--output PATH``.

``--radius-study 0.5 0.7 0.8`` instead tracks every small scene (phantom, tongue, LV,
short axis) with the phase extracted at each band-pass radius (FE with the tracker's
defaults, conventional HARP) and writes ``benchmarks/results/infarct_radius.md``: mean
displacement error (in-plane on the short-axis scene) and, on the LV and short-axis scenes,
the peak radial strain's bias per segment. The phantom is SPAMM (a radius above 0.5 takes
in its DC peak) and is run at 0.5 only. The short-axis tube is analysed with a ventricle
template whose basal third holds the whole tube (segments 1-6: six 60° sectors over its
length; an ellipsoid with a 120 mm long axis, within 0.7 % of the tube's radius), its truth
the closed-form motion on a fine tube mesh (8 × 96 × 28 cells).

Usage::

    python benchmarks/cardiac_strain.py --size small                       # ~2 min
    python benchmarks/cardiac_strain.py --size small --infarct 7 8 13 14 --scar-activation 0.5
    python benchmarks/cardiac_strain.py --size paper     # several minutes
    python benchmarks/cardiac_strain.py --radius-study 0.5 0.7 0.8       # ~5 min
"""

from __future__ import annotations

import argparse
import platform
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from harpx.anatomy.segmentation import mesh_from_labels
from harpx.anatomy.ventricle import ventricle
from harpx.anatomy.ventricle_fit import fit_ventricle_to_mask
from harpx.cardiac.strain import COMPONENTS, cardiac_strain
from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import track_harp
from harpx.mechanics.body import Body
from harpx.scenes.lv import ANTERIOR, lv
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track

RESULTS = Path(__file__).resolve().parent / "results"
SHORT_AXIS = slice(0, 16)  # segments 1-16
SYMBOL = {"radial": "Err", "circumferential": "Ecc", "longitudinal": "Ell"}


def peaks(ds, component: str) -> np.ndarray:
    """Peak strain (17,) of one component."""
    return np.asarray(ds.peak_strain.sel(component=component).values, dtype=np.float64)


def summary(est, truth) -> dict[str, float]:
    """Mean and max |error| over segments 1-16 per component; radial relative and bias."""
    out: dict[str, float] = {}
    for c in COMPONENTS:
        d = (peaks(est, c) - peaks(truth, c))[SHORT_AXIS]
        out[f"{c} mean"] = float(np.nanmean(np.abs(d)))
        out[f"{c} max"] = float(np.nanmax(np.abs(d)))
    true_err = peaks(truth, "radial")[SHORT_AXIS]
    d = peaks(est, "radial")[SHORT_AXIS] - true_err
    out["radial relative"] = float(np.nanmean(np.abs(d)) / np.nanmean(np.abs(true_err)))
    out["radial bias"] = float(np.nanmean(d) / np.nanmean(np.abs(true_err)))
    return out


def least_contracting(ds, count: int) -> list[int]:
    """The ``count`` segments of 1-16 with the smallest |peak Ecc| (NaN last)."""
    ecc = np.abs(peaks(ds, "circumferential")[SHORT_AXIS])
    order = np.argsort(np.where(np.isfinite(ecc), ecc, np.inf))
    return sorted(int(k) + 1 for k in order[:count])


def radial_bias(est, truth) -> float:
    """Mean over segments with a value of (peak Err - true) / true peak Err."""
    t = peaks(truth, "radial")
    d = (peaks(est, "radial") - t) / np.abs(t)
    return float(np.nanmean(d[np.isfinite(t)]))


def _tube_truth(scene, template):
    """The short-axis scene's closed-form motion on a fine tube mesh, analysed."""
    from harpx.mechanics.materials import NeoHookean
    from harpx.mechanics.mesh import tube
    from harpx.tracking.results import tracked_dataset

    g, m = scene.info["geometry"], scene.motion
    spec = tube(g.inner_radius, g.outer_radius, g.length, n_radial=8, n_circumferential=96,
                n_axial=28, center=(0.0, 0.0, m.bottom))  # fmt: skip
    body = Body(spec, NeoHookean(c1=1.0, kappa=100.0))
    U = np.zeros((scene.tagged.sizes["time"], body.ndof))
    for n, t in enumerate(scene.tagged.time.values):
        U[n, body.node_dofs] = m(body.dof_points, float(t))
    known = {"observed_fraction": (("cell", "axis"), np.ones((body.ncell, 3)))}
    return cardiac_strain(tracked_dataset(body, U, scene.tagged, known, {}), template)


def _truth_on_mesh(scene, body):
    """The truth's displacement at the tracking mesh's nodes, as a ``tracked/1`` result.

    The tracking mesh's nodal interpolant of the true motion (its discretisation error).
    Nodes just outside the truth's own faceted mesh are sampled a little inside it: moved
    towards their nearest truth node in steps until located (at most the whole way).
    """
    from scipy.spatial import cKDTree

    from harpx.tracking.results import tracked_dataset

    times = scene.tagged.time.values
    X0 = body.dof_points
    X = X0.copy()
    _, nearest = cKDTree(scene.truth.body.nodes).query(X0)
    towards = scene.truth.body.nodes[nearest] - X0
    for step in (0.05, 0.1, 0.2, 0.4, 0.7, 1.0):
        outside = ~np.isfinite(scene.truth(X, float(times[0]))[:, 0])
        if not outside.any():
            break
        X[outside] = X0[outside] + step * towards[outside]
    U = np.zeros((times.size, body.ndof))
    for n, t in enumerate(times):
        U[n, body.node_dofs] = scene.truth(X, float(t))
    known = {"observed_fraction": (("cell", "axis"), np.ones((body.ncell, 3)))}
    return tracked_dataset(body, U, scene.tagged, known, {})


def radius_study(radii: list[float]) -> None:
    """Every small scene tracked at each band-pass radius (module docstring)."""
    from harpx.anatomy.ventricle import VentricleGeometry
    from harpx.anatomy.ventricle_fit import VentricleTemplate
    from harpx.scenes.phantom import phantom
    from harpx.scenes.short_axis import short_axis
    from harpx.scenes.tongue import tongue

    command = "python benchmarks/cardiac_strain.py " + shlex.join(sys.argv[1:])
    lines = [
        "# Band-pass radius on every small scene",
        "",
        f"`{command}` ({time.strftime('%Y-%m-%d')}, {platform.node() or 'host'}). Phase "
        "`extract_phase(tagged, radius=r)` (upsample 2, the default), FE "
        "`track(phase, scene.body(), dirichlet=...)` with the tracker's defaults, HARP "
        "`track_harp`. Errors: mean displacement error over frames 1..N-1 and body voxels "
        "(mm; short axis: in-plane x-y part); Err bias: mean over segments of (peak Err − "
        "true) / true (LV: segments 1–16 and 17 for FE; short axis: its 6 sectors).",
        "",
        "| scene | sequence | radius | FE error (mm) | HARP error (mm) | FE Err bias "
        "| HARP Err bias | FE Ecc mean abs error | HARP Ecc mean abs error | FE time (s) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def row(name, seq, r, fe_err, h_err, fe_s=None, h_s=None, truth=None, wall=0.0):
        cells = [name, seq, f"{r:g}", f"{fe_err:.4f}", f"{h_err:.4f}"]
        if truth is None:
            cells += ["", "", "", ""]
        else:
            cells += [f"{100 * radial_bias(fe_s, truth):+.1f} %",
                      f"{100 * radial_bias(h_s, truth):+.1f} %"]  # fmt: skip
            cells += [
                f"{np.nanmean(np.abs(peaks(ds, 'circumferential') - peaks(truth, 'circumferential'))[SHORT_AXIS]):.4f}"  # noqa: E501
                for ds in (fe_s, h_s)
            ]
        lines.append("| " + " | ".join(cells + [f"{wall:.0f}"]) + " |")
        print(lines[-1], flush=True)

    def run(scene, body, dirichlet, r, upsample=2):
        phase = extract_phase(scene.tagged, upsample=upsample, radius=r)
        start = time.perf_counter()
        fe = track(phase, body, dirichlet=dirichlet)
        wall = time.perf_counter() - start
        return phase, fe, track_harp(phase, points=scene.tagged), wall

    sc = phantom("small")
    _, fe, hp, wall = run(sc, sc.body("hex8"), [], 0.5)
    grid = {d: sc.tagged[d] for d in ("z", "y", "x")}
    row("phantom", "SPAMM", 0.5, float(tracking_error(fe.assign_coords(grid), sc.tagged).mean_all),
        float(tracking_error(hp, sc.tagged).mean_all), wall=wall)  # fmt: skip
    sc = tongue("small")
    grid = {d: sc.tagged[d] for d in ("z", "y", "x")}
    for r in radii:
        _, fe, hp, wall = run(sc, sc.body(), list(sc.dirichlet), r)
        row("tongue", "CSPAMM", r,
            float(tracking_error(fe.assign_coords(grid), sc.tagged).mean_all),
            float(tracking_error(hp, sc.tagged).mean_all), wall=wall)  # fmt: skip
    sc = lv(size="small")
    template = sc.template()
    truth = cardiac_strain(sc.truth_result(), template)
    for r in radii:
        _, fe, hp, wall = run(sc, sc.body(), sc.dirichlet(), r)
        row("LV", "CSPAMM", r, float(tracking_error(fe, sc.tagged).mean_all),
            float(tracking_error(hp, sc.tagged).mean_all), cardiac_strain(fe, template),
            cardiac_strain(hp, template, body=sc.tagged["body"]), truth, wall)  # fmt: skip
    sc = short_axis("small")
    g = sc.info["geometry"]
    geometry = VentricleGeometry(
        (g.inner_radius, 120.0),
        (g.outer_radius, 120.0 + g.outer_radius - g.inner_radius),
        truncation=sc.motion.bottom + sc.motion.length,
    )
    template = VentricleTemplate(geometry, anterior=ANTERIOR)
    truth = _tube_truth(sc, template)
    for r in radii:
        _, fe, hp, wall = run(sc, sc.body(), list(sc.dirichlet), r)
        fe_split, h_split = sc.error_split(fe), sc.error_split(hp)
        row("short axis", "CSPAMM", r, float(fe_split.in_plane_mean_all),
            float(h_split.in_plane_mean_all), cardiac_strain(fe, template),
            cardiac_strain(hp, template, body=sc.tagged["body"]), truth, wall)  # fmt: skip
    out = RESULTS / "infarct_radius.md"
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", choices=("small", "paper"), default="small")
    parser.add_argument(
        "--epsilon",
        type=float,
        default=None,
        help="fixed tracking residual, rad (default: the tracker's, with the blur correction)",
    )
    parser.add_argument(
        "--radius", type=float, default=0.8, help="band-pass radius (the library's default: 0.5)"
    )
    parser.add_argument(
        "--blur-passes",
        type=int,
        default=None,
        help="blur-correction passes (default: the tracker's)",
    )
    parser.add_argument(
        "--upsample", type=int, default=2, help="phase upsampling (default: the library's, 2)"
    )
    parser.add_argument(
        "--in-plane-blur",
        action="store_true",
        help="drop the slice geometry from the phase: the blur correction models the in-plane "
        "band-pass only (the model before the slice profile; harpx.tracking.blur)",
    )
    parser.add_argument(
        "--divisions",
        type=int,
        nargs=3,
        default=None,
        metavar=("NC", "NL", "NT"),
        help="template tracking mesh (circumferential, longitudinal, transmural cells; "
        "default: the scene's)",
    )
    parser.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="NAME=VALUE",
        help="further tracker settings (harpx.tracking.settings.TrackingSettings)",
    )
    parser.add_argument(
        "--output",
        default=None,
        help="write the table here instead of benchmarks/results/ (e.g. for an experiment "
        "with --set, which should not replace the recorded table)",
    )
    parser.add_argument("--infarct", type=int, nargs="*", default=[])
    parser.add_argument("--scar-activation", type=float, default=0.0)
    parser.add_argument(
        "--snr",
        type=lambda v: None if v.lower() == "none" else float(v),
        default=20.0,
        help="image signal-to-noise ratio of the scene ('none': noise free; default 20)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help="the scene's noise seed (default 0, the recorded tables'); another seed writes "
        "<table>_seed<N>.md beside them",
    )
    parser.add_argument(
        "--radius-study",
        type=float,
        nargs="+",
        default=None,
        help="track every small scene at these band-pass radii instead (module docstring)",
    )
    parser.add_argument(
        "--element-size",
        type=float,
        default=None,
        help="segmentation-mesh element size, mm (default 6 small, 4 paper)",
    )
    args = parser.parse_args()
    if args.radius_study:
        radius_study(args.radius_study)
        return
    if args.element_size is None:
        args.element_size = 6.0 if args.size == "small" else 4.0
    command = "python benchmarks/cardiac_strain.py " + shlex.join(sys.argv[1:])
    settings = {} if args.epsilon is None else {"epsilon": args.epsilon}
    if args.blur_passes is not None:
        settings["blur_passes"] = args.blur_passes
    for item in args.set:
        name, value = item.split("=", 1)
        try:
            settings[name] = None if value == "None" else float(value)
        except ValueError:  # a named choice, e.g. regularization=increment
            settings[name] = value

    start = time.perf_counter()
    scene = lv(size=args.size, infarct=tuple(args.infarct), scar_activation=args.scar_activation,
               snr=args.snr, seed=args.seed)  # fmt: skip
    t_scene = time.perf_counter() - start
    tagged = scene.tagged

    start = time.perf_counter()
    fit = fit_ventricle_to_mask(tagged, anterior=ANTERIOR)
    t_fit = time.perf_counter() - start
    template = fit.template

    phase = extract_phase(tagged, upsample=args.upsample, radius=args.radius)
    if args.in_plane_blur:
        phase = phase.drop_vars(["slice_thickness", "slice_position"], errors="ignore")
    start = time.perf_counter()
    body = scene.body("stress-free")
    if args.divisions is not None:
        g = scene.geometry
        nc, nl, nt = args.divisions
        spec = ventricle(inner=g.inner, outer=g.outer, truncation=g.truncation,
                         n_circumferential=nc, n_longitudinal=nl, n_transmural=nt)  # fmt: skip
        body = Body(spec, scene.material)
    tracked = track(phase, body, dirichlet=scene.dirichlet(), **settings)
    t_fe = time.perf_counter() - start
    start = time.perf_counter()
    segmented = mesh_from_labels(
        tagged, element_size=args.element_size, boundaries=template.facet_predicates(),
        fibers=template.fibers,
    )  # fmt: skip
    seg_body = Body(segmented.spec, scene.material)
    seg_tracked = track(phase, seg_body, dirichlet=template.base_conditions(), **settings)
    t_seg = time.perf_counter() - start
    start = time.perf_counter()
    harp = track_harp(phase)
    t_harp = time.perf_counter() - start

    truth = cardiac_strain(scene.truth_result(), template)
    fe_name = "FE tracking (hex8, stress-free)"
    seg_name = f"FE tracking (segmentation mesh {args.element_size:g} mm)"
    harp_name = "conventional HARP (voxels)"
    rows = {
        fe_name: cardiac_strain(tracked, template),
        seg_name: cardiac_strain(seg_tracked, template),
        harp_name: cardiac_strain(harp, template, body=phase["body"] > 0.5),
        "truth displacement on voxels": cardiac_strain(tagged, template),
        "truth displacement on the tracking mesh": cardiac_strain(
            _truth_on_mesh(scene, body), template
        ),
    }
    wall = {fe_name: t_fe, seg_name: t_seg, harp_name: t_harp}
    displacement = {
        fe_name: tracking_error(tracked, tagged),
        seg_name: tracking_error(seg_tracked, tagged),
        harp_name: tracking_error(harp, tagged),
    }
    stats = {name: summary(ds, truth) for name, ds in rows.items()}

    infarct = tuple(args.infarct)
    title = (
        f"Cardiac strain by AHA segment: LV scene `{args.size}`"
        if not infarct
        else f"Infarct: LV scene `{args.size}` with segments {', '.join(map(str, infarct))} "
        f"at {args.scar_activation:g} × the active tension"
    )
    fwd = scene.info["forward"]
    lines = [
        f"# {title}",
        "",
        f"`{command}` ({time.strftime('%Y-%m-%d')}, {platform.node() or 'host'}; scene built "
        f"in {t_scene:.0f} s; ejection fraction {fwd['ejection_fraction'][-1]:.3f}).",
        "",
        "Template fitted to the scene's body mask "
        f"({t_fit:.2f} s): inner {tuple(round(v, 2) for v in template.geometry.inner)}, "
        f"outer {tuple(round(v, 2) for v in template.geometry.outer)}, base "
        f"{float(template.to_image([[0, 0, template.geometry.truncation]])[0, 2]):.2f} mm "
        "(truth (25, 70), (35, 78), 10); residual "
        + ", ".join(f"{k} {v:.2f} mm" for k, v in fit.report().items()),
        "",
        "Peak strain = the segment mean's signed extreme over the frames (Green–Lagrange). "
        "Errors over segments 1–16 (HARP has no value in the apical cap 17): mean / max of "
        "|peak − true peak|; Err relative = mean |Err error| / mean |true peak Err|, Err "
        "bias = mean (Err − true) / mean |true peak Err|.",
        "",
        "| method | Err error | Err relative | Err bias | Ecc error | Ell error "
        "| twist ES (deg) | displacement error mean (mm) | wall time (s) |",
        "|---|---|---|---|---|---|---|---|---|",
        f"| truth (fine FE mesh) | | | | | | {float(truth.twist[-1]):.2f} | | |",
    ]
    for name, ds in rows.items():
        s = stats[name]
        shown = " | ".join(
            f"{s[f'{c} mean']:.4f} / {s[f'{c} max']:.4f}"
            + (f" | {100 * s['radial relative']:.1f} % | {100 * s['radial bias']:+.1f} %"
               if c == "radial" else "")
            for c in COMPONENTS
        )  # fmt: skip
        disp = float(displacement[name].mean_all) if name in displacement else float("nan")
        lines.append(
            f"| {name} | {shown} | {float(ds.twist[-1]):.2f} | {disp:.3f} | "
            f"{wall.get(name, float('nan')):.1f} |"
        )
    fe, hp = stats[fe_name], stats[harp_name]
    checks = [
        ("FE peak Ecc mean |error| ≤ 0.01", fe["circumferential mean"] <= 0.01,
         f"{fe['circumferential mean']:.4f}"),
        ("FE Err error ≤ 10 % of the true peak Err", fe["radial relative"] <= 0.10,
         f"{100 * fe['radial relative']:.1f} %"),
    ] + [
        (f"FE ≤ HARP, {SYMBOL[c]} mean |error|", fe[f"{c} mean"] <= hp[f"{c} mean"],
         f"{fe[f'{c} mean']:.4f} vs {hp[f'{c} mean']:.4f}")
        for c in COMPONENTS
    ]  # fmt: skip
    if infarct:
        found = {name: least_contracting(ds, len(infarct)) for name, ds in rows.items()}
        checks.insert(
            0,
            (f"FE: the {len(infarct)} least contracting segments (smallest |peak Ecc|) "
             "are the infarct", found[fe_name] == sorted(infarct), str(found[fe_name])),
        )  # fmt: skip
        lines += ["", "Least contracting segments (smallest |peak Ecc| of 1–16):", ""]
        lines += [f"* truth: {least_contracting(truth, len(infarct))}"]
        lines += [f"* {name}: {found[name]}" for name in rows]
    lines += ["", "| goal | met | measured |", "|---|---|---|"]
    lines += [f"| {goal} | {'yes' if ok else '**no**'} | {value} |" for goal, ok, value in checks]
    for c in ("circumferential", "radial", "longitudinal"):
        sym = SYMBOL[c]
        lines += [
            "",
            f"Peak {sym} per segment (error = method − truth):",
            "",
            "| segment | truth | FE | FE error | FE source | HARP | HARP error | truth "
            "displacement on voxels |",
            "|---|---|---|---|---|---|---|---|",
        ]
        t = peaks(truth, c)
        f_, h_, v_ = (
            peaks(rows[n], c) for n in (fe_name, harp_name, "truth displacement on voxels")
        )
        # observed by the tags or (partly) inferred by the model (harpx.cardiac.quality)
        source = rows[fe_name].strain_source.sel(component=c).values
        for k in range(17):
            mark = " (infarct)" if k + 1 in infarct else ""
            lines.append(
                f"| {k + 1} {truth.segment_name.values[k]}{mark} | {t[k]:.4f} | {f_[k]:.4f} | "
                f"{f_[k] - t[k]:+.4f} | {source[k]} | {h_[k]:.4f} | {h_[k] - t[k]:+.4f} | "
                f"{v_[k]:.4f} |"
            )
    q = segmented.quality
    epsilon = "the tracker's default ε (noise floor × 1.5, blur correction)" if (
        args.epsilon is None) else f"ε {args.epsilon} rad (no blur correction)"  # fmt: skip
    lines += [
        "",
        f"Phase: upsample {args.upsample}, band-pass radius {phase.attrs['radius']:g}. "
        f"FE tracking: {epsilon}, "
        f"blur model {tracked.attrs.get('blur_model', 'none')!r}, "
        f"{len(tracked.time)} frames; template mesh {tracked.sizes['cell']} cells; "
        f"segmentation mesh {q.cells} cells (min scaled Jacobian {q.min_scaled_jacobian:.2f}, "
        f"{q.inverted} inverted). Wall times on a shared 2-core machine.",
    ]
    if args.output is not None:
        out = Path(args.output)
    elif infarct:
        out = RESULTS / f"infarct_{args.size}.md"
    else:
        out = RESULTS / (
            "cardiac_strain.md" if args.size == "paper" else f"cardiac_strain_{args.size}.md"
        )
    if args.output is None and args.seed != 0:
        out = out.with_name(f"{out.stem}_seed{args.seed}.md")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
