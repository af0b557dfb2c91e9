"""How far two runs of the same tracking differ, and how to make them identical.

Runs one tracking case (``track_case.py``'s scenes and settings) several times, each in a
fresh process, under each of two environments: as installed, and with Intel MKL's
conditional numerical reproducibility (``MKL_CBWR=AUTO``, which must be set before MKL
loads, so before Python starts). Records, per environment, the largest and mean difference
of the tracked displacement between any two runs (mm) beside the tracking error of the
first run, and the wall time of each run.

PARDISO (MKL) factorises on several threads; the order in which their partial sums meet can
change from run to run, and a Gauss-Newton frame that stops once its step is below the
tolerance can then stop at a slightly different iterate. harpx does not switch MKL's
process-wide CNR mode itself (the library does not change global state it does not own).

Writes ``benchmarks/results/reproducibility_<case>.md``.

Usage::

    python benchmarks/reproducibility.py                       # lv-small, 3 runs each
    python benchmarks/reproducibility.py --case phantom-small --runs 2
"""

from __future__ import annotations

import argparse
import itertools
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
ENVIRONMENTS = {"as installed": {}, "MKL_CBWR=AUTO": {"MKL_CBWR": "AUTO"}}


def child(case: str, out: Path) -> None:
    """Track ``case`` once and save its displacement (node, axis, time) and mean error."""
    import warnings

    sys.path.insert(0, str(HERE))
    from track_case import inputs

    from harpx.imaging.harp import extract_phase
    from harpx.tracking.results import tracking_error
    from harpx.tracking.track import track

    tagged, body, options, kwargs = inputs(case)
    phase = extract_phase(tagged, **options)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tracked = track(phase, body, **kwargs)
    wall = time.perf_counter() - start
    error = float(tracking_error(tracked, tagged)["mean_all"])
    np.savez(out, u=tracked["displacement"].values, error=error, wall=wall)


def measure(case: str, runs: int) -> list[dict[str, float | str]]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, extra in ENVIRONMENTS.items():
            env = {**os.environ, **extra}
            results = []
            for k in range(runs):
                out = Path(tmp) / f"{len(rows)}_{k}.npz"
                subprocess.run(
                    [sys.executable, __file__, "--child", str(out), "--case", case],
                    env=env,
                    check=True,
                )
                results.append(np.load(out))
            diffs = [np.abs(a["u"] - b["u"]) for a, b in itertools.combinations(results, 2)]
            rows.append(
                {
                    "environment": label,
                    "max_diff": max(float(d.max()) for d in diffs),
                    "mean_diff": float(np.mean([d.mean() for d in diffs])),
                    "error": float(results[0]["error"]),
                    "wall": float(np.median([float(r["wall"]) for r in results])),
                }
            )
    return rows


def report(case: str, runs: int, rows: list[dict[str, float | str]]) -> str:
    lines = [
        f"# Run-to-run differences of FE tracking: {case}",
        "",
        f"`python benchmarks/reproducibility.py --case {case} --runs {runs}` "
        f"({time.strftime('%Y-%m-%d')}, {platform.machine()}, {os.cpu_count()} cores). "
        f"{runs} runs per environment, each a fresh process, the tracker's defaults; "
        "differences of the tracked displacement over every node and frame, between every "
        "pair of runs.",
        "",
        "| environment | largest difference (mm) | mean difference (mm) | mean error of the "
        "first run (mm) | median tracking time (s) |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['environment']} | {r['max_diff']:.2e} | {r['mean_diff']:.2e} | "
            f"{r['error']:.4f} | {r['wall']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="lv-small",
                        choices=["phantom-small", "lv-small", "short-axis-small"])  # fmt: skip
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        child(args.case, args.child)
        return
    rows = measure(args.case, args.runs)
    text = report(args.case, args.runs, rows)
    path = RESULTS / f"reproducibility_{args.case}.md"
    path.write_text(text)
    print(text)
    print(f"written {path}")


if __name__ == "__main__":
    main()
