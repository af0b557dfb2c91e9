"""Small ready-made archives of the synthetic scenes, and the recipe that makes them.

The repository's ``datasets_synthetic/`` folder holds, for each scene of
:mod:`harpx.scenes` at its small size, the three archives of the pipeline and the tracking
mesh::

    datasets_synthetic/<name>/tagged.nc    tagged/1 images with displacement_true
    datasets_synthetic/<name>/phase.nc     phase/1, extracted from tagged.nc (no truth copy)
    datasets_synthetic/<name>/tracked.nc   tracked/1, tracked through phase.nc
    datasets_synthetic/<name>/mesh.vtu     the tracking mesh (regions, boundaries, fibres)

so a notebook can start from any stage without building a scene::

    import harpx.datasets
    harpx.datasets.list_datasets()          # name -> what it shows
    tracked = harpx.datasets.open("phantom-small", kind="tracked")
    mesh = harpx.datasets.path("phantom-small", "mesh")  # for harpx.io.mesh.read_body

The archives carry the CF ``Conventions`` attribute of the files (``CF-1.10``, plus
``UGRID-1.0`` for the tracked mesh), and :func:`open` keeps it.

Each archive is made by :func:`build` from a fixed :class:`Recipe` (scene, phase and
tracking settings) and written by :func:`regenerate`, which is also the command line
``python -m harpx.datasets regenerate [NAME ...] [--kinds ...]``; ``datasets_synthetic/
README.md`` is written by the same command and lists every recipe.

To keep the archives small (a few MB for all nine), the large floating-point fields are
stored with a shortened mantissa (:data:`MANTISSA_BITS`, truncated towards zero so that
wrapped phases stay in [-π, π) and fractions in [0, 1]): 12 bits keep the images and phases
to a relative 2.4e-4 (a phase to 8e-4 rad, far below the noise of an SNR-20 image), 16 bits
keep displacements to a relative 1.5e-5 (1e-4 mm at 6 mm). The phase archive is extracted
from the stored (shortened) tagged archive and the tracked archive tracked through the
stored phase archive, so each stage can be reproduced exactly from the one before.
"""

from __future__ import annotations

import argparse
import builtins
import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import PathLike

__all__ = [
    "DATASETS",
    "KINDS",
    "MANTISSA_BITS",
    "Recipe",
    "build",
    "directory",
    "export_scene",
    "list_datasets",
    "main",
    "open",
    "path",
    "regenerate",
    "shorten",
    "shorten_mantissa",
]

#: The stages of the pipeline that are archived, in order.
KINDS: tuple[str, ...] = ("tagged", "phase", "tracked")
#: Environment variable naming another folder of archives (e.g. for an installed harpx).
ENVIRONMENT = "HARPX_DATASETS"
#: Mantissa bits kept per variable (float64 has 52); variables not listed are exact.
MANTISSA_BITS: dict[str, int] = {
    "image": 12,
    "phase": 12,
    "magnitude": 12,
    "body": 12,
    "displacement_true": 16,
    "displacement_grid": 16,
}
_MESH_FILE = "mesh.vtu"


@dataclass(frozen=True)
class Recipe:
    """How one dataset is made.

    Parameters
    ----------
    scene : {"phantom", "lv", "tongue"}
        Scene of :mod:`harpx.scenes`.
    size : {"small", "paper"}
        Scene size.
    description : str
        One line for listings.
    scene_kwargs : mapping
        Keyword arguments of the scene function besides ``size``.
    element : str
        Element order of the tracking model.
    phase : mapping
        Keyword arguments of :func:`harpx.imaging.harp.extract_phase`.
    track : mapping
        Keyword arguments of :func:`harpx.tracking.track.track` (the scene's boundary
        conditions are added when it has them).
    """

    scene: str
    size: str
    description: str
    scene_kwargs: Mapping[str, Any] = field(default_factory=dict)
    element: str = "hex8"
    phase: Mapping[str, Any] = field(default_factory=dict)
    track: Mapping[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        """``<scene>-<size>``, e.g. ``"phantom-small"``."""
        return f"{self.scene}-{self.size}"

    def python(self) -> str:
        """The recipe as Python code (for the README)."""
        lines = [f"scene = harpx.scenes.{self.scene}({_call_args(self)})"]
        body = {
            "phantom": f"scene.body({self.element!r})",
            "lv": "scene.body()",
            "tongue": f"scene.body({self.element!r})",
        }[self.scene]
        extra = {"lv": ", dirichlet=scene.dirichlet()", "tongue": ", dirichlet=scene.dirichlet"}
        track_args = f", {_kwargs(self.track)}" if self.track else ""
        lines += [
            "tagged = shorten(scene.tagged)",
            f"phase = shorten(extract_phase(tagged, {_kwargs(self.phase)}))",
            'phase = phase.drop_vars("displacement_true")',
            f"tracked = track(phase, {body}{extra.get(self.scene, '')}{track_args})",
            'tracked = shorten(tracked.drop_vars("wall_time"))  # and no time_* attributes',
        ]
        return "\n".join(lines)


def _kwargs(kwargs: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in kwargs.items())


def _call_args(recipe: Recipe) -> str:
    size = f"size={recipe.size!r}"
    return ", ".join([size, *(f"{k}={v!r}" for k, v in recipe.scene_kwargs.items())])


def _recipes() -> dict[str, Recipe]:
    out: dict[str, Recipe] = {}
    for size in ("small", "paper"):
        for recipe in (
            Recipe(
                "phantom",
                size,
                "brain phantom, rotational impact (SPAMM)",
                element="hex8",
                phase={"upsample": 1},
                track={"epsilon": 0.05},
            ),
            Recipe(
                "lv",
                size,
                "left ventricle in systole (CSPAMM, SA + LA)",
                phase={"upsample": 1, "radius": 0.7},
                track={},  # the tracker's defaults
            ),
            Recipe(
                "tongue",
                size,
                "tongue, five active muscles (CSPAMM)",
                element="hex20",
                phase={"upsample": 1},
                track={},  # the tracker's defaults
            ),
        ):
            out[recipe.name] = recipe
    return out


#: Every recipe by name; the ``-small`` ones are stored in ``datasets_synthetic/``.
DATASETS: dict[str, Recipe] = _recipes()
STORED: tuple[str, ...] = ("phantom-small", "lv-small", "tongue-small")


def list_datasets() -> dict[str, str]:
    """The stored datasets and what each shows.

    Each has the archives :data:`KINDS` (:func:`open`) and the tracking mesh
    (:func:`path` with ``kind="mesh"``). The paper-size recipes of :data:`DATASETS` are not
    stored: :func:`build` or :func:`regenerate` make them.

    Returns
    -------
    dict of str to str
        Name → one-line description.

    Examples
    --------
    >>> sorted(list_datasets())
    ['lv-small', 'phantom-small', 'tongue-small']
    """
    return {name: DATASETS[name].description for name in STORED}


def directory() -> Path:
    """The folder of stored archives.

    Returns
    -------
    pathlib.Path
        ``$HARPX_DATASETS`` if set, else the repository's ``datasets_synthetic/``.
    """
    env = os.environ.get(ENVIRONMENT)
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[1] / "datasets_synthetic"


def path(name: str, kind: str = "tagged", *, root: PathLike | None = None) -> Path:
    """File of one stored archive (``<root>/<name>/<kind>.nc``; ``kind="mesh"``: mesh.vtu).

    Parameters
    ----------
    name : str
        Dataset name (:func:`list_datasets`).
    kind : {"tagged", "phase", "tracked", "mesh"}, default "tagged"
        Pipeline stage.
    root : str or os.PathLike, optional
        Folder of archives (default :func:`directory`).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    ValueError
        For an unknown name or kind (the message lists the known ones).
    """
    _check(name, kind, allow_mesh=True)
    folder = Path(root) if root is not None else directory()
    return folder / name / (_MESH_FILE if kind == "mesh" else f"{kind}.nc")


def open(  # noqa: A001  (harpx.datasets.open reads as the verb it is)
    name: str,
    kind: str = "tagged",
    *,
    chunks: Mapping[str, int] | str | None = None,
    root: PathLike | None = None,
) -> xr.Dataset:
    """Open a stored dataset.

    Parameters
    ----------
    name : str
        ``"phantom-small"``, ``"lv-small"`` or ``"tongue-small"`` (:func:`list_datasets`),
        or a paper-size recipe that :func:`regenerate` stored under ``root``.
    kind : {"tagged", "phase", "tracked"}, default "tagged"
        Pipeline stage. The tracking mesh is a file, not an archive: ``path(name, "mesh")``
        gives it, :func:`harpx.io.mesh.read_body` reads it.
    chunks : mapping, "auto", {} or None, default None
        As in :func:`harpx.io.netcdf.open_dataset` (e.g. ``{"time": 1}``: one frame per
        dask chunk, the archives' own chunking).
    root : str or os.PathLike, optional
        Folder of archives (default :func:`directory`).

    Returns
    -------
    xarray.Dataset
        A ``tagged/1``, ``phase/1`` or ``tracked/1`` dataset, with the file's CF
        ``Conventions`` attribute.

    Raises
    ------
    ValueError
        For an unknown name or kind (the message lists the stored datasets, and for
        ``kind="mesh"`` says how to read the mesh).
    FileNotFoundError
        If the archive is not there (e.g. harpx installed without the repository): the
        message gives the command that makes it.

    Examples
    --------
    >>> tagged = open("phantom-small")  # doctest: +SKIP
    >>> tagged.attrs["harpx_schema"]  # doctest: +SKIP
    'tagged/1'
    """
    from harpx.io.netcdf import open_dataset

    _check(name, kind)
    file = path(name, kind, root=root)
    if not file.is_file():
        raise FileNotFoundError(
            f"no stored archive {str(file)!r}; make it with `python -m harpx.datasets "
            f"regenerate {name} --kinds {kind} --output {file.parent.parent}` (or set "
            f"{ENVIRONMENT} to a folder that has it)"
        )
    ds = open_dataset(file, chunks=chunks)
    if "Conventions" not in ds.attrs:  # harpx.io drops what its writer added: keep this one
        conventions = _file_conventions(file)
        if conventions is not None:
            ds.attrs["Conventions"] = conventions
    return ds


def _file_conventions(file: Path) -> str | None:
    """The global ``Conventions`` attribute of a NetCDF file (None if it has none)."""
    import netCDF4

    with netCDF4.Dataset(file) as nc:
        value = getattr(nc, "Conventions", None)
    return None if value is None else str(value)


def _conventions(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` with the ``Conventions`` its archive carries (as :func:`to_netcdf` writes it:
    UGRID for the hexahedral mesh of every tracked recipe)."""
    from harpx.io.netcdf import CONVENTIONS, UGRID_CONVENTIONS

    mesh = ds.attrs.get("harpx_schema") == "tracked/1" and "cells" in ds
    ds.attrs["Conventions"] = CONVENTIONS + (f" {UGRID_CONVENTIONS}" if mesh else "")
    return ds


def _check(name: str, kind: str, *, allow_mesh: bool = False) -> None:
    if name not in DATASETS:
        others = sorted(set(DATASETS) - set(STORED))
        raise ValueError(
            f"unknown dataset {name!r}; stored: {sorted(STORED)!r} (list_datasets()); "
            f"not stored, made by regenerate(): {others!r}"
        )
    kinds = (*KINDS, "mesh") if allow_mesh else KINDS
    if kind not in kinds:
        hint = (
            f" (the tracking mesh is a file, not an archive: harpx.datasets.path({name!r}, "
            "'mesh') gives it, harpx.io.mesh.read_body reads it)"
            if kind == "mesh"
            else ""
        )
        raise ValueError(f"kind={kind!r}; expected one of {list(kinds)!r}{hint}")


# --- making the archives -------------------------------------------------------------------


def shorten_mantissa(values: np.ndarray, bits: int) -> np.ndarray:
    """Keep ``bits`` mantissa bits of float64 values, truncating towards zero.

    Parameters
    ----------
    values : ndarray of float64
        Values (NaN and infinities pass unchanged).
    bits : int
        Mantissa bits to keep, 1 … 52.

    Returns
    -------
    ndarray of float64
        ``|out| <= |values|`` with the same sign, relative change below ``2**-bits``.

    Raises
    ------
    ValueError
        If ``bits`` is not in 1 … 52.

    Examples
    --------
    >>> float(shorten_mantissa(np.array([np.pi]), 8)[0])
    3.140625
    """
    if not 1 <= bits <= 52:
        raise ValueError(f"bits={bits!r} must be between 1 and 52")
    if np.asarray(values).dtype == np.float32:  # float32 (phase() output) has 23 bits
        data32 = np.ascontiguousarray(values, dtype=np.float32)
        keep = min(bits, 23)
        mask32 = np.uint32(~((1 << (23 - keep)) - 1) & 0xFFFFFFFF)
        out32 = (data32.view(np.uint32) & mask32).view(np.float32)
        return np.where(np.isfinite(data32), out32, data32)
    data = np.ascontiguousarray(values, dtype=np.float64)
    mask = np.uint64(~((1 << (52 - bits)) - 1) & 0xFFFFFFFFFFFFFFFF)
    out = (data.view(np.uint64) & mask).view(np.float64)
    return np.where(np.isfinite(data), out, data)


def shorten(ds: xr.Dataset) -> xr.Dataset:
    """Copy of ``ds`` whose :data:`MANTISSA_BITS` variables keep only those bits.

    Parameters
    ----------
    ds : xarray.Dataset
        Any dataset (variables not in :data:`MANTISSA_BITS` are left exact).

    Returns
    -------
    xarray.Dataset
        The values that the stored archives hold (:func:`shorten_mantissa`).
    """
    out = ds.copy()
    for name, bits in MANTISSA_BITS.items():
        if name in out.data_vars and out[name].dtype in (np.float64, np.float32):
            out[name] = out[name].copy(data=shorten_mantissa(out[name].values, bits))
    return out


@dataclass
class _Scene:
    tagged: xr.Dataset
    body: Any
    dirichlet: list[Any]


def _scene(recipe: Recipe, progress: bool | None = None) -> _Scene:
    from harpx import scenes
    from harpx._progress import elapsed

    make: Any = getattr(scenes, recipe.scene)
    with elapsed(f"building the {recipe.name} scene", progress=progress):
        if recipe.scene == "lv":
            v = make(size=recipe.size, **recipe.scene_kwargs)
            return _Scene(v.tagged, v.body(), list(v.dirichlet()))
        scene = make(recipe.size, **recipe.scene_kwargs)
        body = scene.body(recipe.element)
    return _Scene(scene.tagged, body, list(getattr(scene, "dirichlet", ())))


def build(
    name: str,
    kinds: Sequence[str] = KINDS,
    *,
    root: PathLike | None = None,
    progress: bool | None = None,
) -> dict[str, Any]:
    """Make a dataset's archives in memory, exactly as :func:`regenerate` stores them.

    Parameters
    ----------
    name : str
        Dataset name (any key of :data:`DATASETS`).
    kinds : sequence of {"tagged", "phase", "tracked"}, default all
        Stages to make.
    root : str or os.PathLike, optional
        Where earlier stages may be read from instead of rebuilt: ``phase`` alone starts from
        the stored ``tagged`` archive and ``tracked`` alone from the stored ``phase`` archive
        when they exist there (default: always rebuild from the scene).
    progress : bool or None, default None
        Progress of the scene build and the tracking (None: auto, see
        :mod:`harpx._progress`).

    Returns
    -------
    dict
        Kind → dataset (with the ``Conventions`` attribute of its archive), plus ``"body"``
        (the tracking model) and ``"dirichlet"``.
    """
    from harpx.imaging.harp import extract_phase
    from harpx.tracking.track import track

    for kind in kinds:
        _check(name, kind)
    recipe = DATASETS[name]
    last = max(KINDS.index(k) for k in kinds)
    scene: _Scene | None = None
    data: dict[str, xr.Dataset] = {}
    for kind in KINDS[: last + 1]:
        if kind not in kinds and root is not None and path(name, kind, root=root).is_file():
            data[kind] = open(name, kind, root=root)  # an earlier stage, as stored
        elif kind == "tagged":
            scene = scene or _scene(recipe, progress)
            data[kind] = _conventions(shorten(scene.tagged))
        elif kind == "phase":
            phase = extract_phase(data["tagged"], **recipe.phase)
            # the truth is in the tagged archive: no second copy
            phase = phase.drop_vars(["displacement_true"], errors="ignore")
            data[kind] = _conventions(shorten(phase))
        else:
            scene = scene or _scene(recipe, progress)
            kwargs = dict(recipe.track)
            if scene.dirichlet:
                kwargs["dirichlet"] = scene.dirichlet
            tracked = track(data["phase"], scene.body, progress=progress, **kwargs)
            data[kind] = _conventions(shorten(_without_timings(tracked)))
    out: dict[str, Any] = {k: data[k] for k in KINDS if k in kinds}
    if scene is not None:
        out["body"], out["dirichlet"] = scene.body, scene.dirichlet
    return out


def _without_timings(tracked: xr.Dataset) -> xr.Dataset:
    """Drop the wall-clock records, which differ from run to run."""
    out = tracked.drop_vars([v for v in ("wall_time",) if v in tracked])
    out.attrs = {k: v for k, v in tracked.attrs.items() if not str(k).startswith("time_")}
    return out


def export_scene(name: str, output: PathLike, *, progress: bool | None = None) -> dict[str, Path]:
    """Write a scene's input archive and tracking mesh, to try the ``harpx`` subcommands on.

    Parameters
    ----------
    name : str
        Dataset name (any key of :data:`DATASETS`, e.g. ``"phantom-small"``).
    output : str or os.PathLike
        Folder (created if needed).
    progress : bool or None, default None
        Show the running time of the scene build (None: auto, see :mod:`harpx._progress`).

    Returns
    -------
    dict of str to pathlib.Path
        ``{"tagged": output/tagged.nc, "mesh": output/mesh.vtu}``.
    """
    from harpx.io.netcdf import to_netcdf

    _check(name, "tagged")
    folder = Path(output)
    folder.mkdir(parents=True, exist_ok=True)
    scene = _scene(DATASETS[name], progress)
    return {
        "tagged": to_netcdf(scene.tagged, folder / "tagged.nc"),
        "mesh": _write_mesh(scene.body, folder / _MESH_FILE),
    }


def _write_mesh(body: Any, target: Path) -> Path:
    """The body's mesh with its regions, boundaries and fibres, written atomically."""
    import meshio

    tmp = target.with_name(f".{target.name}.tmp.vtu")
    try:
        meshio.write(tmp, body.to_meshio())
        os.replace(tmp, target)
    finally:
        if tmp.exists():
            tmp.unlink()
    return target


def regenerate(
    names: Sequence[str] | None = None,
    kinds: Sequence[str] = KINDS,
    *,
    output: PathLike | None = None,
    progress: bool | None = None,
) -> list[Path]:
    """Make and store datasets (and rewrite the folder's README).

    Parameters
    ----------
    names : sequence of str, optional
        Datasets to make (default: the stored ones, :func:`list_datasets`).
    kinds : sequence of {"tagged", "phase", "tracked"}, default all
        Stages to make. A later stage alone starts from the stored earlier one, e.g.
        ``kinds=["tracked"]`` re-tracks the stored phase archive (what to run after the
        tracker changed).
    output : str or os.PathLike, optional
        Folder of archives (default :func:`directory`).
    progress : bool or None, default None
        Progress bars (None: auto).

    Returns
    -------
    list of pathlib.Path
        Files written.
    """
    from harpx.io.netcdf import to_netcdf

    root = Path(output) if output is not None else directory()
    written: list[Path] = []
    for name in names or STORED:
        made = build(name, kinds, root=root, progress=progress)
        folder = root / name
        folder.mkdir(parents=True, exist_ok=True)
        for kind in KINDS:
            if kind in made:
                written.append(to_netcdf(made[kind], folder / f"{kind}.nc"))
        if "body" in made:
            written.append(_write_mesh(made["body"], folder / _MESH_FILE))
    written.append(_write_readme(root))
    return written


def _error(root: Path, name: str) -> str:
    """Mean and p95 error of the stored tracked archive against the stored truth."""
    from harpx.tracking.results import tracking_error

    if not all(path(name, k, root=root).is_file() for k in ("tagged", "tracked")):
        return "not made"
    err = tracking_error(open(name, "tracked", root=root), open(name, "tagged", root=root))
    return f"{float(err.mean_all):.3f} / {float(err.p95_all):.3f}"


def _write_readme(root: Path) -> Path:
    lines = [
        "# datasets_synthetic",
        "",
        "Small ready-made archives of the synthetic scenes of `harpx.scenes`, one folder per",
        "dataset: `tagged.nc` (tagged/1 with `displacement_true`), `phase.nc` (phase/1,",
        "without a second copy of the truth),",
        "`tracked.nc` (tracked/1) and `mesh.vtu` (the tracking mesh with its regions,",
        "boundaries and fibres). Open them with",
        "",
        "```python",
        "import harpx.datasets",
        'tracked = harpx.datasets.open("phantom-small", kind="tracked")',
        "harpx.datasets.list_datasets()",
        "```",
        "",
        "This file and every archive here are written by one command, run from the",
        "repository root:",
        "",
        "```",
        "python -m harpx.datasets regenerate                  # every dataset, every stage",
        "python -m harpx.datasets regenerate --kinds tracked  # re-track the stored phases",
        "```",
        "",
        "`tests/test_datasets.py` rebuilds `phantom-small`'s tagged and phase archives and",
        "checks that they equal the stored ones: structure exactly, floats within the",
        "rounding that FFTs and SIMD paths of other CPUs leave (one stored quantum in a few",
        "values), so a change to the scene or the phase extraction shows up as a failing test",
        "until the archives are regenerated.",
        "",
        "Large floating-point fields keep a shortened mantissa (truncated towards zero) to",
        "keep the files small (`harpx.datasets.shorten`; float64 has 52 bits):",
        ", ".join(f"`{k}` {v} bits" for k, v in MANTISSA_BITS.items()) + ".",
        "The phase archive is extracted from the stored tagged archive and the tracked",
        "archive tracked through the stored phase archive, so each stage reproduces",
        "exactly from the one before. Wall-clock records (`wall_time`, `time_*`",
        "attributes) are left out of the tracked archives.",
        "",
        "| dataset | what | files (MB) | tracked error, mean / p95 (mm) |",
        "|---|---|---|---|",
    ]
    for name in STORED:
        folder = root / name
        sizes = ", ".join(
            f"{p.name} {p.stat().st_size / 1e6:.2f}"
            for p in sorted(folder.glob("*"))
            if p.suffix in (".nc", ".vtu")
        )
        row = f"| `{name}` | {DATASETS[name].description} | {sizes} | {_error(root, name)} |"
        lines.append(row)
    lines += ["", "## Recipes", ""]
    lines += [
        "Each dataset is made as below, with `import harpx.scenes`,",
        "`from harpx.datasets import shorten`, `from harpx.imaging.harp import",
        "extract_phase` and `from harpx.tracking.track import track`.",
        "",
    ]
    for name in STORED:
        lines += [f"### {name}", "", "```python", DATASETS[name].python(), "```", ""]
    target = root / "README.md"
    target.write_text("\n".join(lines))
    return target


# --- command line ------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m harpx.datasets``: list or regenerate the stored datasets."""
    parser = argparse.ArgumentParser(
        prog="python -m harpx.datasets",
        description="List or regenerate the small archives of datasets_synthetic/.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the stored datasets and their files")
    regen = sub.add_parser(
        "regenerate",
        help="make the archives again",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    regen.add_argument("names", nargs="*", help="datasets (default: every stored one)")
    regen.add_argument("--kinds", nargs="+", choices=KINDS, default=list(KINDS))
    regen.add_argument("--output", help="folder of archives (default: datasets_synthetic/)")
    args = parser.parse_args(argv)
    if args.command == "list":
        for name, text in list_datasets().items():
            kinds = [k for k in KINDS if path(name, k).is_file()]
            mesh = _MESH_FILE if path(name, "mesh").is_file() else "none"
            builtins.print(
                f"{name:15s} {text}  [archives: {', '.join(kinds) or 'none'}; mesh: {mesh}]"
            )
        builtins.print(
            f"\nopen an archive: harpx.datasets.open(NAME, KIND), KIND one of {', '.join(KINDS)}"
            "\nthe tracking mesh: harpx.datasets.path(NAME, 'mesh'), read by "
            f"harpx.io.mesh.read_body\nfolder: {directory()}"
        )
        return 0
    for file in regenerate(args.names or None, args.kinds, output=args.output):
        builtins.print(f"wrote {file} ({file.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
