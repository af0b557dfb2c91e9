"""What a wrong tag period costs, and whether harpx says so.

Scanner files do not record the tag period; ``read_tagged`` takes it from the user. This
relabels the tag frequency of a scene's images (the images themselves unchanged, so the
truth stays the same) by a factor, extracts the phase with the library's defaults and
tracks it with the tracker's defaults, and records per factor: the stated and the measured
tag period (``tag_frequency_measured``, mean over the measured tags), whether
``extract_phase`` warned, the tags ``track`` flagged (``attrs["tags_off_frequency"]``), the
largest ε over the frames against its target, and the error against the truth.

Writes ``benchmarks/results/tag_period_error_<scene>.md``.

Usage::

    python benchmarks/tag_period_error.py                   # small phantom
    python benchmarks/tag_period_error.py --scene lv-small
"""

from __future__ import annotations

import argparse
import platform
import time
import warnings
from pathlib import Path

import numpy as np

import harpx.accessor  # noqa: F401  (registers ds.harp)
from harpx.errors import HarpxWarning
from harpx.imaging.harp import extract_phase
from harpx.tracking.track import track

RESULTS = Path(__file__).resolve().parent / "results"
FACTORS = (0.8, 0.9, 0.95, 0.97, 1.0, 1.03, 1.05, 1.1, 1.25)  # stated period / true period


def scene_of(name: str):
    if name == "phantom-small":
        from harpx.scenes.phantom import phantom

        scene = phantom("small")
        return scene, scene.body(), {}
    from harpx.scenes.lv import lv

    scene = lv(size="small")
    return scene, scene.body("stress-free"), {"dirichlet": scene.dirichlet()}


def run(name: str) -> list[dict]:
    scene, body, options = scene_of(name)
    tagged = scene.tagged
    rows = []
    for factor in FACTORS:
        relabelled = tagged.assign_coords(tag_frequency=tagged.tag_frequency / factor)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", HarpxWarning)
            phase = extract_phase(relabelled)
        warned = any("but its tag_frequency says" in str(w.message) for w in caught)
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HarpxWarning)
            tracked = track(phase, body, **options)
        seconds = time.perf_counter() - start
        error = tracked.harp.error(tagged)
        measured = phase["tag_frequency_measured"].values
        rows.append(
            {
                "factor": factor,
                "stated": 1.0 / float(relabelled.tag_frequency.values[0]),
                "measured": 1.0 / float(np.nanmean(measured)),
                "warned": warned,
                "flagged": tracked.attrs["tags_off_frequency"],
                "epsilon": float(tracked.epsilon.max()),
                "target": float(tracked.epsilon_target.max()),
                "reached": bool(tracked.target_reached.all()),
                "mean": float(error.mean_all),
                "p95": float(error.p95_all),
                "seconds": seconds,
            }
        )
        print(rows[-1], flush=True)
    return rows


def write(name: str, rows: list[dict], command: str) -> Path:
    path = RESULTS / f"tag_period_error_{name}.md"
    right = next(r for r in rows if r["factor"] == 1.0)
    lines = [
        f"# A wrong tag period: scene `{name}`",
        "",
        f"`{command}` ({time.strftime('%Y-%m-%d')}, {platform.node() or 'this machine'}).",
        "",
        "The images are unchanged; only their `tag_frequency` label is scaled (stated period",
        "= factor × true period). Error: mean / p95 distance to the true displacement (mm),",
        "relative to the right label's. Warned: `extract_phase` said the phase misses the",
        "stated frequency; flagged: the tags `track` recorded in `attrs['tags_off_frequency']`.",
        "",
        "| factor | stated period (mm) | measured period (mm) | warned | flagged | max ε (rad) "
        "| ε target reached | error mean / p95 (mm) | × right label | tracking (s) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['factor']:.2f} | {r['stated']:.2f} | {r['measured']:.2f} | "
            f"{'yes' if r['warned'] else 'no'} | {r['flagged']} | {r['epsilon']:.3f} | "
            f"{'yes' if r['reached'] else 'no'} | {r['mean']:.3f} / {r['p95']:.3f} | "
            f"{r['mean'] / right['mean']:.2f} | {r['seconds']:.1f} |"
        )
    path.write_text("\n".join(lines) + "\n")
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", choices=("phantom-small", "lv-small"), default="phantom-small")
    args = parser.parse_args()
    command = "python benchmarks/tag_period_error.py" + (
        "" if args.scene == "phantom-small" else f" --scene {args.scene}"
    )
    print("wrote", write(args.scene, run(args.scene), command))


if __name__ == "__main__":
    main()
