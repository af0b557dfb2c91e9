"""Does the predicted segment-strain uncertainty cover the spread over noise realisations?

The small left-ventricle scene (``harpx.scenes.lv``: CSPAMM short- and long-axis stacks on
a 2 mm grid, SNR 20, five frames) is built K times with the same motion and different noise
seeds (``lv(size="small", seed=k)``: the scene's own noise model, white on each thick
acquired slice, then resampled onto the common grid). Each realisation is tracked with the
tracker's defaults (phase as in the ``lv-small`` dataset recipe: ``upsample=1``,
``radius=0.7``), its AHA segment measures taken with the scene's exact template, and its
uncertainty predicted by :func:`harpx.cardiac.uncertainty.cardiac_strain_uncertainty`
(M noise samples, the realisation's own tagged images).

For every frame, segment and component the empirical standard deviation over the K
realisations is compared with the predicted σ (root mean square over the realisations), and
each realisation's value is checked against ±2σ (its own σ) around the mean of the K
realisations; with a correct σ that holds with the probability the table states (95.4 % for
a known σ and mean, here with the mean estimated from the same K and each σ from M
samples). Also for the peaks, twist, torsion and each node's
displacement. A second table repeats the check on the realisations whose final penalties
match the most common pattern, since the tracker's penalty choice is not linearised.

Writes ``benchmarks/results/uncertainty_coverage.md``.

Usage::

    python benchmarks/uncertainty_coverage.py                    # K = 30, M = 32 (~40 min)
    python benchmarks/uncertainty_coverage.py --realisations 4 --samples 16   # smoke run
"""

from __future__ import annotations

import argparse
import math
import platform
import time
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

from harpx.cardiac.strain import COMPONENTS, cardiac_strain
from harpx.cardiac.uncertainty import cardiac_strain_uncertainty
from harpx.imaging.harp import extract_phase
from harpx.scenes.lv import lv
from harpx.tracking.track import track

RESULTS = Path(__file__).resolve().parent / "results"
SEGMENT = ("segment_strain", "segment_engineering_strain")
SCALARS = ("twist", "torsion")


def realise(seed: int, samples: int) -> dict:
    """Track one noise realisation and predict its uncertainty; the numbers kept."""
    start = time.perf_counter()
    scene = lv(size="small", seed=seed)
    tagged = scene.tagged
    template = scene.template()
    phase = extract_phase(tagged, upsample=1, radius=0.7)
    body = scene.body()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tracked = track(phase, body, dirichlet=scene.dirichlet())
        clock = time.perf_counter()
        measures = cardiac_strain(tracked, template)
        unc = cardiac_strain_uncertainty(
            tracked, body, phase, template, tagged=tagged, dirichlet=scene.dirichlet(),
            samples=samples, seed=10_000 + seed,
        )  # fmt: skip
        t_unc = time.perf_counter() - clock
    out = {
        "seed": seed,
        "penalty": tracked["penalty"].values.copy(),
        "epsilon_floor": tracked["epsilon_floor"].values.copy(),
        "noise_residual": unc["noise_residual"].values.copy(),
        "equilibrium_step": unc["equilibrium_step"].values.copy(),
        "penalty_sensitivity": unc["penalty_sensitivity"].values.copy(),
        "dof": tracked["dof_displacement"].values.copy(),
        "dof_std": unc["displacement_std"].values.reshape(tracked.sizes["time"], -1).copy(),
        "noise_model": unc.attrs["noise_model"],
        "flags": unc.attrs["flags"],
        "warnings": sorted(
            {str(w.message)[:90] for w in caught if str(w.message)[:48] not in unc.attrs["flags"]}
        ),  # fmt: skip
        "wall": time.perf_counter() - start,
        "wall_uncertainty": t_unc,
    }
    for name in (*SEGMENT, "peak_strain", *SCALARS):
        out[name] = measures[name].values.copy()
        out[f"{name}_std"] = unc[f"{name}_std"].values.copy()
    return out


def compare(values: np.ndarray, sigma: np.ndarray) -> dict:
    """Empirical sd over realisations (axis 0) against the predicted σ; ±2σ coverage."""
    K = values.shape[0]
    empirical = values.std(axis=0, ddof=1)
    predicted = np.sqrt(np.mean(sigma**2, axis=0))
    ok = np.isfinite(empirical) & (predicted > 0)
    ratio = empirical[ok] / predicted[ok]
    if not ratio.size:  # fewer than two realisations: no spread to compare
        ratio = np.full(1, np.nan)
    deviation = values - values.mean(axis=0)
    inside = np.abs(deviation) <= 2.0 * sigma
    valid = np.isfinite(deviation) & (sigma > 0)
    return {
        "ratio_median": float(np.median(ratio)),
        "ratio_p10": float(np.percentile(ratio, 10)),
        "ratio_p90": float(np.percentile(ratio, 90)),
        "ratio_pooled": float(np.sqrt(np.mean(empirical[ok] ** 2) / np.mean(predicted[ok] ** 2)))
        if ok.any()
        else float("nan"),
        "coverage": float(inside[valid].mean()),
        "cells": int(ok.sum()),
        "K": K,
    }


def expected_coverage(K: int, M: int) -> float:
    """P(|x − mean| ≤ 2σ̂) for a correct σ: the mean of K values, σ̂ from M samples."""
    chi2 = np.random.default_rng(0).chisquare(M, 200_000) / M
    z = 2.0 * np.sqrt(chi2) / math.sqrt(1.0 - 1.0 / K)
    return float(np.mean([math.erf(v / math.sqrt(2.0)) for v in z[:20_000]]))


def row(label: str, c: dict) -> str:
    return (
        f"| {label} | {c['cells']} | {c['ratio_pooled']:.3f} | {c['ratio_median']:.3f} "
        f"({c['ratio_p10']:.2f}–{c['ratio_p90']:.2f}) | {100 * c['coverage']:.1f} % |"
    )


def table(runs: list[dict], title: str, samples: int) -> list[str]:
    K = len(runs)
    lines = [
        f"### {title} (K = {K}; a correct σ from M = {samples} samples covers "
        f"{100 * expected_coverage(K, samples):.1f} %)",
        "",
        "| quantity | cells | sd ratio, pooled | sd ratio, median (p10–p90) | ±2σ coverage |",
        "|---|---|---|---|---|",
    ]
    stack = {
        k: np.stack([r[k] for r in runs]) for k in runs[0] if isinstance(runs[0][k], np.ndarray)
    }
    for name in SEGMENT:
        v, s = stack[name][:, 1:], stack[f"{name}_std"][:, 1:]  # frame 0 is exact
        lines.append(row(f"{name} (all frames ≥ 1)", compare(v, s)))
        for c, comp in enumerate(COMPONENTS):
            lines.append(row(f"  {comp}", compare(v[..., c], s[..., c])))
    v, s = stack["segment_strain"][:, 1:], stack["segment_strain_std"][:, 1:]
    for n in range(v.shape[1]):
        lines.append(row(f"segment_strain, frame {n + 1}", compare(v[:, n], s[:, n])))
    lines.append(row("peak_strain", compare(stack["peak_strain"], stack["peak_strain_std"])))
    for name in SCALARS:
        c = compare(stack[name][:, 1:], stack[f"{name}_std"][:, 1:])
        lines.append(row(f"{name} (frames ≥ 1)", c))
    lines.append(row("node displacement (dofs, frames ≥ 1)",
                     compare(stack["dof"][:, 1:], stack["dof_std"][:, 1:])))  # fmt: skip
    return [*lines, ""]


def frame_table(runs: list[dict], samples: int) -> list[str]:
    """Frame by frame, over the realisations whose penalty in that frame is the most common
    one (frames are linearised one by one; the penalty's choice is not)."""
    penalty = np.stack([r["penalty"] for r in runs])
    sensitivity = np.stack([r["penalty_sensitivity"] for r in runs])
    lines = [
        "### Frame by frame, realisations with that frame's most common final penalty",
        "",
        "| frame | penalty (relative) | K | expected coverage | segment_strain sd ratio, "
        "pooled | median (p10–p90) | ±2σ coverage | displacement sd ratio, pooled "
        "| ±2σ coverage | penalty_sensitivity, all K: median (range) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in range(1, penalty.shape[1]):
        values, counts = np.unique(penalty[:, n], return_counts=True)
        mode = values[np.argmax(counts)]
        same = [r for r in runs if r["penalty"][n] == mode]
        seg = compare(np.stack([r["segment_strain"][n] for r in same]),
                      np.stack([r["segment_strain_std"][n] for r in same]))  # fmt: skip
        dof = compare(np.stack([r["dof"][n] for r in same]),
                      np.stack([r["dof_std"][n] for r in same]))  # fmt: skip
        lines.append(
            f"| {n} | {mode:g} | {len(same)} | {100 * expected_coverage(len(same), samples):.1f} %"
            f" | {seg['ratio_pooled']:.3f} | {seg['ratio_median']:.3f} ({seg['ratio_p10']:.2f}–"
            f"{seg['ratio_p90']:.2f}) | {100 * seg['coverage']:.1f} % | {dof['ratio_pooled']:.3f}"
            f" | {100 * dof['coverage']:.1f} % | {np.median(sensitivity[:, n]):.2f} "
            f"({sensitivity[:, n].min():.2f}–{sensitivity[:, n].max():.2f}) |"
        )
    return [*lines, ""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realisations", type=int, default=30)
    parser.add_argument("--samples", type=int, default=32)
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--output", type=Path, default=RESULTS / "uncertainty_coverage.md")
    parser.add_argument("--save", type=Path, default=None, help="also the raw runs (.npz)")
    args = parser.parse_args()
    start = time.perf_counter()
    runs = []
    for k in range(args.realisations):
        runs.append(realise(args.first_seed + k, args.samples))
        r = runs[-1]
        print(f"seed {r['seed']}: {r['wall']:.0f} s (uncertainty {r['wall_uncertainty']:.0f} s), "
              f"penalty {r['penalty'].tolist()}", flush=True)  # fmt: skip
    wall = time.perf_counter() - start
    if args.save is not None:
        arrays = {k: np.stack([r[k] for r in runs]) for k in runs[0]
                  if isinstance(runs[0][k], np.ndarray)}  # fmt: skip
        np.savez_compressed(args.save, **arrays)
    patterns = Counter(tuple(r["penalty"].tolist()) for r in runs)
    common, count = patterns.most_common(1)[0]
    same = [r for r in runs if tuple(r["penalty"].tolist()) == common]
    kept = ("noise_residual", "epsilon_floor", "equilibrium_step", "wall_uncertainty")
    stack = {k: np.stack([r[k] for r in runs]) for k in kept}
    command = "python benchmarks/uncertainty_coverage.py"
    if args.realisations != 30 or args.samples != 32 or args.first_seed != 1:
        command += (f" --realisations {args.realisations} --samples {args.samples}"
                    f" --first-seed {args.first_seed}")  # fmt: skip
    lines = [
        "# Segment-strain uncertainty against the spread over noise realisations",
        "",
        f"`{command}` ({time.strftime('%Y-%m-%d')}, {platform.node() or 'host'}, 2 shared "
        f"cores; {wall / 60:.0f} min in all, the uncertainty "
        f"{np.mean(stack['wall_uncertainty']):.0f} s per realisation with M = {args.samples}).",
        "",
        "Small LV scene, K realisations of the same motion with noise seeds "
        f"{args.first_seed}–{args.first_seed + args.realisations - 1} (SNR 20), tracked with "
        "the defaults; segment measures with the scene's exact template; each realisation's "
        "σ predicted from its own images. *sd ratio* = empirical sd over the realisations / "
        "predicted σ (1 is right; pooled = root mean square over cells first); *coverage* = "
        "share of (realisation, cell) values within ±2σ (their own σ) of the realisations' "
        "mean.",
        "",
        *table(runs, "All realisations", args.samples),
        *table(
            same,
            f"Realisations with the most common final penalties {list(common)}"
            f" ({count} of {len(runs)})",
            args.samples,
        ),
        *frame_table(runs, args.samples),
        "### Diagnostics",
        "",
        f"* noise model: {runs[0]['noise_model']}",
        "* sampled phase noise at the points (mean |δr|, rad) per frame, mean over "
        f"realisations: {np.round(np.nanmean(stack['noise_residual'], axis=0), 4).tolist()}; the "
        f"tracker's `epsilon_floor`: {np.round(stack['epsilon_floor'].mean(axis=0), 4).tolist()}",
        "* Newton step at the rebuilt state (mm, max over realisations) per frame: "
        f"{np.round(stack['equilibrium_step'].max(axis=0), 3).tolist()}",
        "* final penalty patterns (relative, per frame): "
        + "; ".join(f"{list(p)} × {c}" for p, c in patterns.most_common()),
        "* flags raised (realisations): "
        + (
            "; ".join(
                f"{text}… ({n})"
                for text, n in Counter(
                    flag[:48] for r in runs for flag in r["flags"].split(" | ") if flag
                ).items()
            )
            or "none"
        ),  # fmt: skip
        "* other warnings: "
        + ("; ".join(sorted({w for r in runs for w in r["warnings"]})) or "none"),
        "",
    ]
    args.output.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
