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
  C1 = 1 kPa, κ = 120 kPa, penalty method, ε = 0.05 rad (as in
  ``benchmarks/error_vs_runtime.py``), with the tracker's own time split (``time_*`` attrs).

Errors are :func:`harpx.tracking.results.tracking_error` against the scene's true motion (mean
over frames and points, mm); wall-clock seconds on this machine.
"""

from __future__ import annotations

import argparse
import inspect
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
    t0 = time.perf_counter()
    phase = extract_phase(tagged, upsample=2, **kwargs)
    t_phase = time.perf_counter() - t0
    label = f"{args.label}, phase {phase.phase.dtype}"
    rows = [f"| {label} | phase() | {t_phase:.1f} | - | - | - |"]
    t0 = time.perf_counter()
    harp = track_harp(phase, points=tagged)
    t_harp = time.perf_counter() - t0
    err = tracking_error(harp, tagged)
    rows.append(
        f"| {label} | HARP | {t_harp:.1f} | {float(err.mean_all):.4f} | "
        f"{float(err.coverage):.3f} | - |"
    )
    if not args.skip_fe:
        from error_vs_runtime import _mesh

        from harpx.mechanics import Body, NeoHookean
        from harpx.tracking import track

        body = Body(_mesh("paper", False), NeoHookean(c1=1.0, kappa=120.0), element="hex8")
        t0 = time.perf_counter()
        fe = track(phase, body, method="penalty", epsilon=0.05)
        t_fe = time.perf_counter() - t0
        err = tracking_error(fe, tagged)
        split = ", ".join(
            f"{k[5:]} {float(v):.1f}" for k, v in fe.attrs.items() if k.startswith("time_")
        )
        rows.append(
            f"| {label} | FE hex8 {body.ncell} cells (+ phase() = {t_fe + t_phase:.1f} s) | "
            f"{t_fe:.1f} | {float(err.mean_all):.4f} | {float(err.coverage):.3f} | {split} |"
        )
    print("| run | step | wall s | mean error mm | coverage | time split s |")
    print("|---|---|---|---|---|---|")
    print("\n".join(rows))
    if args.out is not None:
        with args.out.open("a") as fh:
            fh.write("\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
