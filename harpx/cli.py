"""The ``harpx`` command line.

Subcommands: ``demo`` (the phantom scene end to end), ``scene`` (a synthetic scene's input
archive and tracking mesh, to try the other subcommands on), ``phase`` (tagged archive →
phase archive), ``track`` (phase archive + mesh → tracked archive), ``dicom`` (tagged cine
DICOM series → tagged archive), ``report`` (summary of a tracked archive, optionally
against ground truth). ``track`` and ``demo`` end with a summary: ε against its target
per frame, the frames that missed it, levelled off (plateau) or did not converge, the
warnings raised (count and first line of each), the total time and the files written; the
other subcommands print the warnings on standard error as ``harpx CMD: warning: ...``.

Errors print as one line (``--debug`` for the traceback), followed by the choices where
harpx cannot choose for the user (the series ``harpx dicom`` found) or by every problem of
a dataset that breaks the harpx conventions, one per line; exit codes: 0 success,
1 harpx or input error, 2 usage error. Progress bars follow :mod:`harpx._progress`: shown
in a terminal for calls longer than a few seconds, never in logs or pipes, unless
``--progress`` or ``--no-progress`` says otherwise. Exit code 130 means interrupted
(Ctrl-C) and 143 terminated (SIGTERM): an interrupted write removes its temporary file and
leaves an existing output untouched. ``phase``, ``track``, ``dicom`` and ``demo`` check
that their output can be written (its directory exists; it is not an input, a directory,
a link or a read-only file) before any work.
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
import threading
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from harpx.cli_output import frames_table, print_frames, print_warnings, tag_periods
from harpx.errors import HarpxError, HarpxWarning, SchemaError

_DESCRIPTION = "Motion estimation from tagged cine MRI with hyperelastic finite-element models."
_EPILOG = (
    "Try it on a synthetic scene: harpx scene phantom-small --output try/ writes try/tagged.nc "
    "and try/mesh.vtu and prints the phase, track and report commands to run on them. "
    "Exit codes: 0 success, 1 harpx or input error (one line; --debug for the traceback), "
    "2 usage error."
)
_AXES = {"x": 0, "y": 1, "z": 2}
#: Subcommands that list the warnings in their closing summary (the others print them on
#: standard error).
_SUMMARISED = ("track", "demo")


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows ``(default: ...)`` only where there is a default worth stating."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if action.default in (None, False, [], argparse.SUPPRESS) or "default" in text:
            return text
        return super()._get_help_string(action)


def _demo(args: argparse.Namespace) -> int:
    from harpx._progress import elapsed
    from harpx.imaging.harp import extract_phase
    from harpx.imaging.harptrack import track_harp
    from harpx.io.netcdf import check_writable_target, to_netcdf
    from harpx.plotting import displacement_maps, error_vs_runtime
    from harpx.scenes.phantom import phantom
    from harpx.tracking.results import tracking_error
    from harpx.tracking.track import track

    start = time.perf_counter()
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    for name in [f"phantom_{element}.nc" for element in args.elements] + ["phantom_harp.nc"]:
        check_writable_target(out / name)  # before the work, not after it
    t = time.perf_counter()
    with elapsed(f"building the phantom scene ({args.size})", progress=args.progress):
        scene = phantom(args.size)
    seconds = time.perf_counter() - t
    print(f"phantom ({args.size}): images {dict(scene.tagged.sizes)} built in {seconds:.1f} s")
    t = time.perf_counter()
    with elapsed("harmonic phase", progress=args.progress):
        phase = extract_phase(scene.tagged, upsample=args.upsample)
    phase_time = time.perf_counter() - t
    print(f"harmonic phase (upsample {args.upsample}) in {phase_time:.1f} s")
    rows: list[dict[str, Any]] = []
    results = {}
    written: list[Path] = []
    t = time.perf_counter()
    with elapsed("conventional HARP", progress=args.progress):
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
        fe = track(phase, body, **_tracking(args))
        results[f"FE {element}"] = fe
        rows.append(
            {
                "method": f"FE {fe.attrs['method']} {element} ({body.ncell} cells)",
                "seconds": time.perf_counter() - t + phase_time,
                "result": fe,
            }
        )
        written.append(to_netcdf(fe, out / f"phantom_{element}.nc"))
    written.append(to_netcdf(harp, out / "phantom_harp.nc"))
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
            f"| {row['method']} | {row['mean']:.3f} ± {row['sd']:.3f} | {row['p95']:.3f} "
            f"| {row['max']:.2f} | {row['seconds']:.1f} |"
        )
    frame_time = 54.0 if args.size == "paper" else float(scene.tagged.time[-2])
    import matplotlib.pyplot as plt

    maps, runtime = out / "phantom_displacement_maps.png", out / "phantom_error_vs_runtime.png"
    plt.close(displacement_maps(results, scene.tagged, time=frame_time, path=maps))
    plt.close(error_vs_runtime(rows, path=runtime))
    written += [maps, runtime]
    for row in rows[1:]:  # the FE models: what happened in each frame
        print()
        print_frames(row["result"], row["method"])
    print()
    print_warnings(getattr(args, "warnings", []))
    print(f"total {time.perf_counter() - start:.1f} s")
    print(f"wrote {', '.join(p.name for p in written)} to {out}/")
    return 0


def _phase(args: argparse.Namespace) -> int:
    from harpx.imaging.harp import extract_phase
    from harpx.io.netcdf import open_dataset, to_netcdf

    _check_output(args.output, [args.input])
    ds = open_dataset(args.input)
    phase = extract_phase(ds, upsample=args.upsample, radius=args.radius)
    to_netcdf(phase, args.output)
    print(f"wrote {args.output}")
    periods = tag_periods(phase)
    if periods:
        print(periods)
    return 0


def _track(args: argparse.Namespace) -> int:
    from harpx.io.mesh import read_body
    from harpx.io.netcdf import open_dataset, to_netcdf
    from harpx.mechanics.materials import NeoHookean
    from harpx.tracking.track import track

    start = time.perf_counter()
    _check_output(args.output, [args.input, args.mesh])
    ds = open_dataset(args.input)
    body = read_body(args.mesh, NeoHookean(c1=args.c1, kappa=args.kappa), element=args.element)
    fixed = [_fixed(item, body) for item in args.fix]
    reading = time.perf_counter() - start
    t = time.perf_counter()
    result = track(ds, body, dirichlet=fixed, **_tracking(args))
    tracking = time.perf_counter() - t
    t = time.perf_counter()
    to_netcdf(result, args.output)
    writing = time.perf_counter() - t
    print_frames(result)
    print_warnings(getattr(args, "warnings", []))
    print(
        f"total {time.perf_counter() - start:.1f} s (reading {reading:.1f} s, tracking "
        f"{tracking:.1f} s, writing {writing:.1f} s)"
    )
    print(f"wrote {args.output}")
    return 0


#: TrackingSettings fields the ``demo`` and ``track`` commands expose, with their help
_TRACKING_OPTIONS: dict[str, str] = {
    "method": "constraint method",
    "epsilon": "target tracking residual, rad (default: epsilon-factor times each frame's "
    "noise floor, never below epsilon-min)",
    "epsilon_factor": "default target relative to the estimated noise floor",
    "epsilon_min": "lowest default target, rad",
    "blur_passes": "band-pass blur-correction passes (default: 1 with the default target, 0 "
    "with --epsilon)",
    "penalty": "starting penalty relative to stiffness and tag wavenumber, raised "
    "automatically until the target is met",
    "max_iterations": "Gauss-Newton iterations per penalty stage",
}


def _tracking_options(parser: argparse.ArgumentParser) -> None:
    """Add the tracking options; their defaults are :class:`TrackingSettings`'s own."""
    from dataclasses import fields

    from harpx.tracking.settings import METHODS, TrackingSettings

    defaults = {f.name: f.default for f in fields(TrackingSettings)}
    kinds = {"epsilon": float, "epsilon_factor": float, "epsilon_min": float, "penalty": float,
             "blur_passes": int, "max_iterations": int}  # fmt: skip
    for name, text in _TRACKING_OPTIONS.items():
        default = defaults[name]
        shown = "" if default is None else f" (default: {default})"
        flag = "--" + name.replace("_", "-")
        if name == "method":
            parser.add_argument(flag, choices=METHODS, default=None, help=text + shown)
        else:
            parser.add_argument(flag, type=kinds[name], default=None, help=text + shown)


def _tracking(args: argparse.Namespace) -> dict[str, Any]:
    """The tracking settings given on the command line (the rest stay the library's)."""
    given = {k: getattr(args, k) for k in _TRACKING_OPTIONS if getattr(args, k) is not None}
    if args.progress is not None:  # else the library's auto rule, as in a notebook
        given["progress"] = args.progress
    return given


def _fixed(item: str, body: Any) -> Any:
    """``--fix NAME[:AXES]`` → :class:`~harpx.mechanics.loads.Fixed` on a named boundary."""
    from harpx.mechanics.loads import Fixed

    name, _, axes = item.partition(":")
    if name not in body.boundaries:
        raise ValueError(
            f"--fix {item!r}: the mesh has no boundary {name!r}; its boundaries are "
            f"{sorted(body.boundaries)!r}"
        )
    axes = axes or "xyz"
    if any(a not in _AXES for a in axes) or len(set(axes)) != len(axes):
        raise ValueError(
            f"--fix {item!r}: axes {axes!r} must be distinct letters of 'xyz', e.g. "
            f"'{name}:z' to hold only the z displacement"
        )
    return Fixed(name, tuple(_AXES[a] for a in axes))


def _scene(args: argparse.Namespace) -> int:
    from harpx.datasets import DATASETS, export_scene

    out = Path(args.output)
    files = export_scene(args.name, out, progress=args.progress)
    recipe = DATASETS[args.name]
    print(f"wrote {files['tagged']} and {files['mesh']} ({recipe.description})")
    phase_opts = " ".join(f"--{k} {v}" for k, v in recipe.phase.items())
    fix = {"tongue": " --fix mandible --fix base", "lv": " --fix base:z"}.get(recipe.scene, "")
    track_opts = " ".join(
        f"--{k} {v}" for k, v in recipe.track.items() if k in ("epsilon", "penalty")
    )
    element = f" --element {recipe.element}" if recipe.element != "hex8" else ""
    print("try next:")
    print(f"  harpx phase {out / 'tagged.nc'} {out / 'phase.nc'} {phase_opts}".rstrip())
    print(
        f"  harpx track {out / 'phase.nc'} {out / 'tracked.nc'} --mesh {files['mesh']}"
        f"{element}{fix} {track_opts}".rstrip()
    )
    print(f"  harpx report {out / 'tracked.nc'} --truth {out / 'tagged.nc'}")
    if recipe.scene == "lv":
        print(
            "(the command line tracks with a neo-Hookean model; the scene's Guccione "
            "myocardium and in-plane base pins are in Python: harpx.scenes.lv)"
        )
    return 0


def _report(args: argparse.Namespace) -> int:
    import harpx.accessor  # noqa: F401  (ds.harp)
    from harpx.io.netcdf import open_dataset
    from harpx.tracking.results import tracking_error

    ds = open_dataset(args.archive)
    kind = ds.attrs.get("harpx_schema")
    if kind != "tracked/1":
        hint = {
            "tagged/1": "run `harpx phase` and `harpx track` on it first",
            "phase/1": "run `harpx track` on it first",
        }.get(str(kind), "pass an archive written by `harpx track` or `harpx demo`")
        raise SchemaError(
            f"{args.archive!r} is a {kind!r} archive; report needs a 'tracked/1' archive: {hint}"
        )
    print(f"{args.archive}: {kind}, method {ds.attrs.get('method')}")
    for line in frames_table(ds, wall_time=True):
        print(line)
    if "wall_time" in ds and ds.sizes["time"] and float(ds["wall_time"].values[0]) > 0:
        blur = " and the blur correction" if ds.attrs.get("blur_passes_applied") else ""
        seconds = float(ds["wall_time"].values[0])
        print(
            f"frame 0 is the reference: its wall_time, {seconds:.2f} s, is the set-up{blur}, "
            "not tracking (left out of the table)"
        )
    if args.figure:
        import matplotlib.pyplot as plt

        ax = ds.harp.plot.displacement()
        ax.figure.savefig(args.figure, dpi=110)
        plt.close(ax.figure)
        print(f"wrote {args.figure}")
    if args.truth:
        err = tracking_error(ds, open_dataset(args.truth))
        print(
            f"error against truth: mean {float(err.mean_all):.3f} ± {float(err.sd_all):.3f} "
            f"mm, p95 {float(err.p95_all):.3f} mm, max {float(err.max_all):.3f} mm"
        )
    return 0


def _dicom(args: argparse.Namespace) -> int:
    from harpx.io.dicom import read_tagged
    from harpx.io.netcdf import to_netcdf

    if not args.tag:
        raise _series_choice(
            "no --tag given: say which series carries which tag with --tag "
            "SERIES:LABEL:DIRECTION (DIRECTION: row, column or x,y,z), e.g. --tag "
            "'SA tagging:x:row', once per tag",
            args.input,
        )
    if args.tag_period is None:
        raise HarpxError(
            "--tag-period is required: DICOM does not record the tag spacing; give it in mm, "
            "e.g. --tag-period 8"
        )
    _check_output(args.output, args.input)
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
    # without --time-tolerance, read_tagged's own default applies
    tolerance = {} if args.time_tolerance is None else {"time_tolerance": args.time_tolerance}
    try:
        ds = read_tagged(
            args.input,
            tag_period=args.tag_period,
            tag_directions=directions,
            sequence=args.sequence,
            spacing=args.spacing,
            **tolerance,
        )
    except HarpxError as err:
        first = (str(err).strip().splitlines() or [""])[0]
        if "tag_directions" not in first:  # not about which series carries which tag
            raise
        # the series selection failed: say it in the command's words, with the series found
        head = _SERIES_FOUND.split(first)[0].replace("tag_directions", "--tag")
        raise _series_choice(head, args.input, err) from err
    to_netcdf(ds, args.output)
    print(f"wrote {args.output}: {dict(ds.sizes)}")
    return 0


#: Where a harpx.io.dicom message starts listing the series it found.
_SERIES_FOUND = re.compile(r"[;.]?\s*[Ss]eries found:")


class _Choices(HarpxError):
    """An error that lists what the user can choose from: printed in full, not one line."""


def _series_choice(
    message: str, inputs: Sequence[str], err: HarpxError | None = None
) -> HarpxError:
    """``message`` followed by the DICOM series found in ``inputs`` (as harpx.io.dicom
    lists them); without a listing (e.g. no DICOM images at all) that error itself."""
    from harpx.io.dicom import read_tagged

    listing = _SERIES_FOUND.split(str(err), maxsplit=1)[1:] if err is not None else []
    if not listing:
        try:
            read_tagged(inputs, tag_directions=None)  # headers only: fails listing the series
        except HarpxError as found:
            listing = _SERIES_FOUND.split(str(found), maxsplit=1)[1:]
            if not listing:
                return found  # no images, unreadable files: that is the error to show
    if not listing:  # pragma: no cover - read_tagged always needs tag_directions
        return HarpxError(message)
    series = listing[0].strip("\n").rstrip()  # keeps the items' indentation
    return _Choices(f"{message}; series found:\n{series}")


def _progress_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="progress bars (default: shown when stderr is a terminal, after a few seconds)",
    )


def _check_output(output: str, inputs: Sequence[str]) -> None:
    """Refuse, before any work, an output that is an input or that cannot be written
    (missing directory, a directory, link or read-only file:
    :func:`~harpx.io.files.check_writable_target`)."""
    from harpx.io.files import check_writable_target

    _refuse_overwriting_input(output, inputs)
    check_writable_target(Path(output))


def _refuse_overwriting_input(output: str, inputs: Sequence[str]) -> None:
    """Raise before any work if ``output`` is one of the input files."""
    target = Path(output).resolve()
    for item in inputs:
        source = Path(item).resolve()
        if target == source:
            raise HarpxError(
                f"output {output!r} is the input {item!r}; writing it would replace the data "
                "being read: choose another output file"
            )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``harpx`` command."""
    from harpx import __version__

    fmt = _HelpFormatter
    parser = argparse.ArgumentParser(
        prog="harpx", description=_DESCRIPTION, epilog=_EPILOG, formatter_class=fmt
    )
    parser.add_argument("--version", action="version", version=f"harpx {__version__}")
    parser.add_argument("--debug", action="store_true", help="print full tracebacks on errors")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    _add_demo(sub, fmt)
    _add_scene(sub, fmt)
    _add_phase(sub, fmt)
    _add_track(sub, fmt)
    _add_dicom(sub, fmt)
    _add_report(sub, fmt)
    return parser


def _add_demo(sub: Any, fmt: type[argparse.HelpFormatter]) -> None:
    """The ``harpx demo`` subcommand: the synthetic brain phantom end to end."""
    from harpx.imaging.phase_parameters import DEFAULT_UPSAMPLE

    demo = sub.add_parser(
        "demo", help="track the synthetic brain phantom end to end", formatter_class=fmt
    )
    demo.add_argument("--output", default="harpx-demo", help="output folder")
    demo.add_argument(
        "--size",
        choices=["paper", "small"],
        default="paper",
        help="scene size: paper (13 frames of 13 × 160² voxels, 4320 cells: a minute or two) "
        "or small (5 frames of 7 × 48² voxels, 432 cells: seconds)",
    )
    demo.add_argument(
        "--upsample",
        type=int,
        default=DEFAULT_UPSAMPLE,
        help="in-plane phase upsampling",
    )
    _tracking_options(demo)
    demo.add_argument(
        "--elements",
        nargs="+",
        choices=["hex8", "hex20"],
        default=["hex8"],
        help="element orders of the FE models",
    )
    _progress_option(demo)
    demo.set_defaults(func=_demo)


def _add_scene(sub: Any, fmt: type[argparse.HelpFormatter]) -> None:
    """The ``harpx scene`` subcommand: a synthetic scene's archive and mesh."""
    from harpx.datasets import DATASETS

    scn = sub.add_parser(
        "scene",
        help="write a synthetic scene's tagged archive and tracking mesh",
        description="Write a synthetic scene's tagged/1 archive (tagged.nc, with ground "
        "truth) and its tracking mesh (mesh.vtu, with named boundaries) into a folder, and "
        "print the phase, track and report commands to run on them.",
        formatter_class=fmt,
    )
    scn.add_argument("name", choices=sorted(DATASETS), help="scene and size")
    scn.add_argument("--output", default="harpx-scene", help="output folder")
    _progress_option(scn)
    scn.set_defaults(func=_scene)


def _add_phase(sub: Any, fmt: type[argparse.HelpFormatter]) -> None:
    """The ``harpx phase`` subcommand: harmonic phase of a tagged archive."""
    from harpx.imaging.phase_parameters import DEFAULT_RADIUS, DEFAULT_UPSAMPLE

    phase = sub.add_parser("phase", help="harmonic phase of a tagged archive", formatter_class=fmt)
    phase.add_argument("input", help="tagged/1 archive")
    phase.add_argument("output", help="phase/1 archive to write")
    phase.add_argument(
        "--upsample",
        type=int,
        default=DEFAULT_UPSAMPLE,
        help="in-plane upsampling factor",
    )
    phase.add_argument(
        "--radius",
        type=float,
        default=DEFAULT_RADIUS,
        help="band-pass radius, fraction of tag frequency",
    )
    phase.set_defaults(func=_phase)


def _add_track(sub: Any, fmt: type[argparse.HelpFormatter]) -> None:
    """The ``harpx track`` subcommand: track a mesh through an archive."""
    trk = sub.add_parser(
        "track", help="track a mesh through a phase or tagged archive", formatter_class=fmt
    )
    trk.add_argument("input", help="phase/1 (or tagged/1) archive")
    trk.add_argument("output", help="tracked/1 archive to write")
    trk.add_argument("--mesh", required=True, help="hexahedral mesh readable by meshio (mm)")
    trk.add_argument("--element", choices=["hex8", "hex20"], default="hex8", help="element")
    trk.add_argument("--c1", type=float, default=1.0, help="neo-Hookean C1, kPa")
    trk.add_argument("--kappa", type=float, default=120.0, help="bulk modulus, kPa")
    _tracking_options(trk)
    trk.add_argument(
        "--fix",
        action="append",
        default=[],
        metavar="NAME[:AXES]",
        help="hold a named boundary of the mesh fixed, e.g. 'bottom' (all axes) or 'base:z'; "
        "repeat for several",
    )
    _progress_option(trk)
    trk.set_defaults(func=_track)


def _add_dicom(sub: Any, fmt: type[argparse.HelpFormatter]) -> None:
    """The ``harpx dicom`` subcommand: tagged cine DICOM series to a tagged archive."""
    dcm = sub.add_parser(
        "dicom", help="tagged cine DICOM series -> tagged archive", formatter_class=fmt
    )
    dcm.add_argument("input", nargs="+", help="DICOM files or folders")
    dcm.add_argument("output", help="tagged/1 NetCDF archive to write")
    dcm.add_argument(
        "--tag",
        action="append",
        default=[],
        metavar="SERIES:LABEL:DIRECTION",
        help="tag of a series (SeriesDescription, number or UID): label and "
        "direction 'row', 'column' or 'x,y,z'; repeat for each tag (without it: lists the "
        "series found)",
    )
    dcm.add_argument("--tag-period", type=float, help="tag spacing, mm (required with --tag)")
    dcm.add_argument(
        "--sequence", choices=["SPAMM", "CSPAMM"], help="tagging sequence (default: from headers)"
    )
    dcm.add_argument(
        "--spacing", type=float, help="isotropic output voxel size, mm (default: in-plane)"
    )
    dcm.add_argument(
        "--time-tolerance",
        type=float,
        metavar="MS",
        help="largest disagreement of one frame's trigger times across slices and series, "
        "ms; images of one slice closer than this are duplicates (default: that of "
        "harpx.io.dicom.read_tagged)",
    )
    dcm.set_defaults(func=_dicom)


def _add_report(sub: Any, fmt: type[argparse.HelpFormatter]) -> None:
    """The ``harpx report`` subcommand: summary of a tracked archive."""
    rep = sub.add_parser("report", help="summarise a tracked archive", formatter_class=fmt)
    rep.add_argument("archive", help="tracked/1 archive")
    rep.add_argument("--truth", help="tagged archive with displacement_true")
    rep.add_argument("--figure", help="write a displacement map of the last frame (PNG)")
    rep.set_defaults(func=_report)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``harpx`` command; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _terminate)  # unwind, so cleanups run
    recorded: list[warnings.WarningMessage] = []
    try:
        # the command reports its warnings itself (its summary, or one line each on
        # stderr); the filters are restored when it returns
        with warnings.catch_warnings(record=True) as caught:
            warnings.filterwarnings("always", category=HarpxWarning)
            recorded = args.warnings = caught
            code = int(args.func(args))
        if args.command not in _SUMMARISED:
            _warnings_to_stderr(args.command, recorded)
        return code
    except (KeyboardInterrupt, _Terminated) as exc:
        _warnings_to_stderr(args.command, recorded)
        if args.debug:
            raise
        what = "terminated" if isinstance(exc, _Terminated) else "interrupted"
        print(f"harpx {args.command}: {what}; no partial output was written", file=sys.stderr)
        return 143 if isinstance(exc, _Terminated) else 130
    except Exception as exc:  # every failure is one line; --debug shows the traceback
        _warnings_to_stderr(args.command, recorded)
        if args.debug:
            raise
        print(f"harpx {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 1
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so that ``finally`` blocks remove temp files."""


def _terminate(signum: int, frame: Any) -> None:
    raise _Terminated()


def _warnings_to_stderr(command: str, caught: Sequence[warnings.WarningMessage]) -> None:
    """Each warning of a run as ``harpx COMMAND: warning: MESSAGE`` on stderr."""
    for item in caught:
        print(f"harpx {command}: warning: {str(item.message).strip()}", file=sys.stderr)


def _one_line(exc: BaseException) -> str:
    """First line of an error, prefixed by its type unless it is a harpx or input error
    (an error listing the user's choices keeps its list, a schema error every problem)."""
    if isinstance(exc, _Choices):
        return str(exc).strip()
    if isinstance(exc, SchemaError) and len(exc.problems) > 1:  # every problem, one each
        items = "".join(f"\n  - {' '.join(p.split())}" for p in exc.problems)
        return f"{len(exc.problems)} schema problems:{items}"
    lines = str(exc).strip().splitlines()
    first = lines[0] if lines else ""
    if isinstance(exc, HarpxError | ValueError | OSError) and first:
        return first
    return f"{type(exc).__name__}: {first}" if first else type(exc).__name__


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
