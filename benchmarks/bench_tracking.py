"""Paper phantom end to end: phase(), conventional HARP and FE (hex8) tracking, time split.

The paper-size phantom scene (:func:`harpx.scenes.phantom.phantom`, 3 tags x 13 frames x
13 x 160 x 160) is synthesised once and cached as netCDF (``--cache``, default in the system
temporary directory), so that two revisions can be compared on the same data: run the script
once per revision with ``--label`` (e.g. ``PYTHONPATH`` pointing at each checkout) and
``--out`` to append the rows to one Markdown table. Rows:

* ``phase()``: :func:`harpx.imaging.harp.extract_phase` (``upsample=2``), float32 (the default
  since this benchmark was written) or float64 (``--dtype``; older revisions ignore it);
* ``HARP``: :func:`harpx.imaging.harptrack.track_harp` on the voxel centres of the images;
* ``FE``: :func:`harpx.tracking.track` with the hex8 paper mesh (4320 cells), neo-Hookean
  C1 = 1 kPa, κ = 120 kPa, penalty method, the tracker's default ε (``--epsilon`` to pin it;
  as in ``benchmarks/error_vs_runtime.py``; ``--epsilon-factor`` and ``--blur-passes`` set
  those tracking settings), with the tracker's own time split (``time_*`` attrs).

``--steps`` picks the rows (e.g. ``--steps harp`` for conventional HARP alone). Each row also
gives the process CPU time (user + system) of its step, which a shared machine distorts less
than wall time. Errors are :func:`harpx.tracking.results.tracking_error` against the scene's
true motion (mean / p95 / max over frames and points, mm); wall-clock seconds on this machine.

Side by side (before/after): check the old revision out into a temporary worktree
(``git worktree add /tmp/harpx-main main``) and run this same script once with
``PYTHONPATH=/tmp/harpx-main`` and once with this checkout, alternating, several times.
"""

from __future__ import annotations

import argparse
import inspect
import resource
import sys
import tempfile
import time
from pathlib import Path

import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parent))


def scene(cache: Path) -> xr.Dataset:
    if not cache.exists():
        from harpx.scenes.phantom import phantom

        phantom("paper").tagged.to_netcdf(cache)
    return xr.open_dataset(cache).load()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", default="current")
    parser.add_argument("--dtype", default="float32", choices=["float32", "float64"])
    parser.add_argument("--skip-fe", action="store_true")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument(
        "--steps", nargs="+", default=["phase", "harp", "fe"], choices=["phase", "harp", "fe"]
    )
    parser.add_argument("--epsilon", type=float, default=None)
    parser.add_argument("--epsilon-factor", type=float, default=None)
    parser.add_argument("--blur-passes", type=int, default=None)
    parser.add_argument(
        "--cache", type=Path, default=Path(tempfile.gettempdir()) / "harpx_phantom_paper.nc"
    )
    args = parser.parse_args()
    from harpx.imaging.harp import extract_phase
    from harpx.imaging.harptrack import track_harp
    from harpx.tracking.results import tracking_error

    tagged = scene(args.cache)
    kwargs = {}
    if "dtype" in inspect.signature(extract_phase).parameters:
        kwargs["dtype"] = args.dtype
    t0, c0 = time.perf_counter(), _cpu()
    phase = extract_phase(tagged, upsample=2, **kwargs)
    t_phase, c_phase = time.perf_counter() - t0, _cpu() - c0
    label = f"{args.label}, phase {phase.phase.dtype}"
    rows = []
    if "phase" in args.steps:
        rows.append(f"| {label} | phase() | {t_phase:.1f} | {c_phase:.1f} | - | - | - |")
    if "harp" in args.steps:
        t0, c0 = time.perf_counter(), _cpu()
        harp = track_harp(phase, points=tagged)
        t_harp, c_harp = time.perf_counter() - t0, _cpu() - c0
        err = tracking_error(harp, tagged)
        rows.append(
            f"| {label} | HARP | {t_harp:.1f} | {c_harp:.1f} | {_errors(err)} | "
            f"{float(err.coverage):.3f} | - |"
        )
    if "fe" in args.steps and not args.skip_fe:
        from error_vs_runtime import _mesh

        from harpx.mechanics import Body, NeoHookean
        from harpx.tracking.track import track

        body = Body(_mesh("paper", False), NeoHookean(c1=1.0, kappa=120.0), element="hex8")
        pinned = {} if args.epsilon is None else {"epsilon": args.epsilon}
        if args.epsilon_factor is not None:
            pinned["epsilon_factor"] = args.epsilon_factor
        if args.blur_passes is not None:
            pinned["blur_passes"] = args.blur_passes
        t0, c0 = time.perf_counter(), _cpu()
        fe = track(phase, body, method="penalty", **pinned)
        t_fe, c_fe = time.perf_counter() - t0, _cpu() - c0
        err = tracking_error(fe, tagged)
        split = ", ".join(
            f"{k[5:]} {float(v):.1f}" for k, v in fe.attrs.items() if k.startswith("time_")
        )
        rows.append(
            f"| {label} | FE hex8 {body.ncell} cells"
            f"{''.join(f', {k}={v}' for k, v in pinned.items())} "
            f"(+ phase() = {t_fe + t_phase:.1f} s) | "
            f"{t_fe:.1f} | {c_fe:.1f} | {_errors(err)} | {float(err.coverage):.3f} | {split} |"
        )
    print("| run | step | wall s | CPU s | error mean / p95 / max mm | coverage | time split s |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    if args.out is not None:
        with args.out.open("a") as fh:
            fh.write("\n".join(rows) + "\n")


def _cpu() -> float:
    """User + system CPU seconds of this process so far."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _errors(err: xr.Dataset) -> str:
    return f"{float(err.mean_all):.4f} / {float(err.p95_all):.4f} / {float(err.max_all):.3f}"


if __name__ == "__main__":
    main()
