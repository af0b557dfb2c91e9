"""The ``harpx`` command line.

Subcommands: ``demo`` (the phantom scene end to end), ``phase`` (tagged archive → phase
archive), ``track`` (phase archive + mesh → tracked archive), ``dicom`` (tagged cine DICOM
series → tagged archive), ``report`` (summary of a tracked archive, optionally against
ground truth). Errors print as one line (``--debug`` for the
traceback); exit codes: 0 success, 1 harpx or input error, 2 usage error.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from harpx.errors import HarpxError


def _demo(args: argparse.Namespace) -> int:
    from harpx.imaging.harp import extract_phase
    from harpx.imaging.harptrack import track_harp
    from harpx.io.netcdf import to_netcdf
    from harpx.plotting import displacement_maps, error_vs_runtime
    from harpx.scenes.phantom import phantom
    from harpx.tracking.results import tracking_error
    from harpx.tracking.track import track

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    scene = phantom(args.size)
    print(
        f"phantom ({args.size}): images {dict(scene.tagged.sizes)} built in "
        f"{time.perf_counter() - t:.1f} s"
    )
    t = time.perf_counter()
    phase = extract_phase(scene.tagged, upsample=args.upsample)
    phase_time = time.perf_counter() - t
    print(f"harmonic phase (upsample {args.upsample}) in {phase_time:.1f} s")
    rows: list[dict[str, Any]] = []
    results = {}
    t = time.perf_counter()
    harp = track_harp(phase, points=scene.tagged)
    results["HARP"] = harp
    rows.append(
        {
            "method": "conventional HARP",
            "seconds": time.perf_counter() - t + phase_time,
            "result": harp,
        }
    )
    for element in args.elements:
        body = scene.body(element)
        t = time.perf_counter()
        fe = track(phase, body, method=args.method, epsilon=args.epsilon, progress=args.progress)
        results[f"FE {element}"] = fe
        rows.append(
            {
                "method": f"FE {args.method} {element} ({body.ncell} cells)",
                "seconds": time.perf_counter() - t + phase_time,
                "result": fe,
            }
        )
        to_netcdf(fe, out / f"phantom_{element}.nc")
    to_netcdf(harp, out / "phantom_harp.nc")
    print()
    print("| method | mean ± sd (mm) | p95 (mm) | max (mm) | wall time (s) |")
    print("|---|---|---|---|---|")
    for row in rows:
        err = tracking_error(row["result"], scene.tagged)
        row.update(
            mean=float(err.mean_all),
            sd=float(err.sd_all),
            p95=float(err.p95_all),
            max=float(err.max_all),
        )
        print(
            f"| {row['method']} | {row['mean']:.3f} ± {row['sd']:.3f} | {row['p95']:.3f} | "
            f"{row['max']:.2f} | {row['seconds']:.1f} |"
        )
    frame_time = 54.0 if args.size == "paper" else float(scene.tagged.time[-2])
    displacement_maps(
        results, scene.tagged, time=frame_time, path=out / "phantom_displacement_maps.png"
    )
    error_vs_runtime(rows, path=out / "phantom_error_vs_runtime.png")
    print(f"\narchives and figures written to {out}/")
    return 0


def _phase(args: argparse.Namespace) -> int:
    from harpx.imaging.harp import extract_phase
    from harpx.io.netcdf import open_dataset, to_netcdf

    ds = open_dataset(args.input)
    to_netcdf(extract_phase(ds, upsample=args.upsample, radius=args.radius), args.output)
    print(f"wrote {args.output}")
    return 0


def _track(args: argparse.Namespace) -> int:
    from harpx.io.netcdf import open_dataset, to_netcdf
    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean
    from harpx.tracking.track import track

    ds = open_dataset(args.input)
    body = Body(args.mesh, NeoHookean(c1=args.c1, kappa=args.kappa), element=args.element)
    result = track(ds, body, method=args.method, epsilon=args.epsilon, progress=args.progress)
    to_netcdf(result, args.output)
    print(f"wrote {args.output}")
    return 0


def _report(args: argparse.Namespace) -> int:
    import harpx.accessor  # noqa: F401  (ds.harp)
    from harpx.io.netcdf import open_dataset
    from harpx.tracking.results import tracking_error

    ds = open_dataset(args.archive)
    print(f"{args.archive}: {ds.attrs.get('harpx_schema')}, method {ds.attrs.get('method')}")
    cols = [c for c in ("epsilon", "penalty", "iterations", "wall_time") if c in ds]
    print("| time (ms) | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 1) + "|")
    for i, t in enumerate(ds.time.values):
        print(f"| {t:.0f} | " + " | ".join(f"{float(ds[c][i]):.4g}" for c in cols) + " |")
    if args.figure:
        import matplotlib.pyplot as plt

        ax = ds.harp.plot.displacement()
        ax.figure.savefig(args.figure, dpi=110)
        plt.close(ax.figure)
        print(f"wrote {args.figure}")
    if args.truth:
        err = tracking_error(ds, open_dataset(args.truth))
        print(
            f"error against truth: mean {float(err.mean_all):.3f} ± {float(err.sd_all):.3f} mm, "
            f"p95 {float(err.p95_all):.3f} mm, max {float(err.max_all):.3f} mm"
        )
    return 0


def _dicom(args: argparse.Namespace) -> int:
    from harpx.io.dicom import read_tagged
    from harpx.io.netcdf import to_netcdf

    directions: dict[str, list[tuple[str, Any]]] = {}
    for item in args.tag:
        try:
            series, label, direction = item.split(":")
        except ValueError:
            raise ValueError(
                f"--tag {item!r} must be SERIES:LABEL:DIRECTION, e.g. 'SA tagging:x:row'"
            ) from None
        vector = [float(v) for v in direction.split(",")] if "," in direction else direction
        directions.setdefault(series, []).append((label, vector))
    ds = read_tagged(
        args.input,
        tag_period=args.tag_period,
        tag_directions=directions,
        sequence=args.sequence,
        spacing=args.spacing,
    )
    to_netcdf(ds, args.output)
    print(f"wrote {args.output}: {dict(ds.sizes)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``harpx`` command."""
    parser = argparse.ArgumentParser(prog="harpx", description=__doc__.splitlines()[0])
    parser.add_argument("--debug", action="store_true", help="print full tracebacks on errors")
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="track the synthetic brain phantom end to end")
    demo.add_argument("--output", default="harpx-demo", help="output folder (default harpx-demo)")
    demo.add_argument("--size", choices=["paper", "small"], default="paper")
    demo.add_argument("--upsample", type=int, default=2)
    demo.add_argument("--method", choices=["penalty", "augmented-lagrangian"], default="penalty")
    demo.add_argument("--epsilon", type=float, default=0.05, help="target tracking residual, rad")
    demo.add_argument("--elements", nargs="+", choices=["hex8", "hex20"], default=["hex8"])
    demo.add_argument(
        "--no-progress", dest="progress", action="store_false", help="no progress bar"
    )
    demo.set_defaults(func=_demo)

    phase = sub.add_parser("phase", help="harmonic phase of a tagged archive")
    phase.add_argument("input")
    phase.add_argument("output")
    phase.add_argument("--upsample", type=int, default=2)
    phase.add_argument("--radius", type=float, default=0.5)
    phase.set_defaults(func=_phase)

    trk = sub.add_parser("track", help="track a mesh through a phase or tagged archive")
    trk.add_argument("input")
    trk.add_argument("output")
    trk.add_argument("--mesh", required=True, help="hexahedral mesh readable by meshio (mm)")
    trk.add_argument("--element", choices=["hex8", "hex20"], default="hex8")
    trk.add_argument("--c1", type=float, default=1.0, help="neo-Hookean C1, kPa")
    trk.add_argument("--kappa", type=float, default=120.0, help="bulk modulus, kPa")
    trk.add_argument("--method", choices=["penalty", "augmented-lagrangian"], default="penalty")
    trk.add_argument("--epsilon", type=float, default=0.05, help="target tracking residual, rad")
    trk.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    trk.set_defaults(func=_track)

    dcm = sub.add_parser("dicom", help="tagged cine DICOM series -> tagged archive")
    dcm.add_argument("input", nargs="+", help="DICOM files or folders")
    dcm.add_argument("output", help="tagged/1 NetCDF archive to write")
    dcm.add_argument(
        "--tag",
        action="append",
        required=True,
        metavar="SERIES:LABEL:DIRECTION",
        help="tag of a series (SeriesDescription, number or UID): label and "
        "direction 'row', 'column' or 'x,y,z'; repeat for each tag",
    )
    dcm.add_argument("--tag-period", type=float, required=True, help="tag spacing, mm")
    dcm.add_argument("--sequence", choices=["SPAMM", "CSPAMM"])
    dcm.add_argument("--spacing", type=float, help="isotropic output voxel size, mm")
    dcm.set_defaults(func=_dicom)

    rep = sub.add_parser("report", help="summarise a tracked archive")
    rep.add_argument("archive")
    rep.add_argument("--truth", help="tagged archive with displacement_true")
    rep.add_argument("--figure", help="write a displacement map of the last frame (PNG)")
    rep.set_defaults(func=_report)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``harpx`` command; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except (HarpxError, ValueError, OSError) as exc:
        if args.debug:
            raise
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"harpx {args.command}: error: {first}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
