"""One tracking case in one process: wall, CPU, peak memory, iterations and errors, as JSON.

Made to be timed from outside, run after run, under two checkouts of harpx (``PYTHONPATH``
pointing at each), so that a before/after comparison is of whole processes. The scene's
tagged images (and for the left ventricle and the short-axis scene, the built scene) are
synthesised once and cached in the system temporary directory, per checkout, so the timed
runs load them instead of building them. Cases:

* ``phantom`` / ``phantom-small``: paper (or small) brain phantom, FE hex8 with the
  tracker's defaults (``phase()`` with ``upsample=2`` included in the step);
* ``phantom-hex20``: the paper phantom with a hex20 body on the same mesh (the
  ``fe-hex20`` row of ``benchmarks/error_vs_runtime.py``);
* ``phantom-harp``: conventional HARP on the same phase images (phase extraction
  included);
* ``lv-small`` / ``lv``: left ventricle, stress-free reference, tracker defaults;
* ``short-axis-small`` / ``short-axis``: in-plane tags only, tracker defaults.

Prints one JSON line: ``step_wall`` / ``step_cpu`` (phase extraction and tracking, s),
``peak_rss_mib`` (the process's maximum resident set; the phase images are dropped before the
errors are evaluated), ``step_peak_rss_mib`` (the same, read right after the step, before the
evaluation), ``iterations`` (Gauss–Newton, every
pass), ``mean`` / ``p95`` / ``max`` error (mm, :func:`harpx.tracking.results.tracking_error`)
and the tracker's own ``time_*`` split.

Usage::

    python benchmarks/track_case.py phantom
    PYTHONPATH=/path/to/other/checkout python benchmarks/track_case.py phantom
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pickle
import resource
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

CASES = ("phantom", "phantom-small", "phantom-hex20", "phantom-harp", "lv-small", "lv",
         "short-axis-small", "short-axis")  # fmt: skip


def _cache(name: str) -> Path:
    import harpx

    key = hashlib.sha1(str(Path(harpx.__file__).resolve()).encode()).hexdigest()[:8]
    return Path(tempfile.gettempdir()) / f"harpx_case_{name}_{key}"


def _phantom(size: str, element: str = "hex8") -> tuple[xr.Dataset, Any]:
    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean
    from harpx.mechanics.mesh import cylinder
    from harpx.scenes.phantom import GEOMETRIES, phantom

    path = _cache(f"phantom_{size}").with_suffix(".nc")
    if not path.exists():
        phantom(size).tagged.to_netcdf(path)
    tagged = xr.open_dataset(path).load()
    g = GEOMETRIES[size]
    mesh = cylinder(g.radius, g.height, n_radial=g.n_radial, n_circumferential=g.n_circumferential,
                    n_axial=g.n_axial, center=(0.0, 0.0, -g.height / 2))  # fmt: skip
    return tagged, Body(mesh, NeoHookean(c1=1.0, kappa=120.0), element=element)


def _scene(name: str, size: str) -> Any:
    path = _cache(f"{name}_{size}").with_suffix(".pkl")
    if path.exists():
        with path.open("rb") as fh:
            return pickle.load(fh)
    if name == "lv":
        from harpx.scenes.lv import lv

        scene = lv(size=size)
    else:
        from harpx.scenes.short_axis import short_axis

        scene = short_axis(size)
    with path.open("wb") as fh:
        pickle.dump(scene, fh)
    return scene


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def inputs(case: str) -> tuple[xr.Dataset, Any, dict[str, Any], dict[str, Any]]:
    """The tagged images, the body, the ``extract_phase`` and the ``track`` keywords of
    ``case`` (one of :data:`CASES`)."""
    if case.startswith("phantom"):
        element = "hex20" if case == "phantom-hex20" else "hex8"
        tagged, body = _phantom("small" if case == "phantom-small" else "paper", element)
        return tagged, body, {"upsample": 2}, {}
    name = "lv" if case.startswith("lv") else "short-axis"
    scene = _scene(name, "small" if case.endswith("small") else "paper")
    body = scene.body("stress-free") if name == "lv" else scene.body()
    dirichlet = list(scene.dirichlet() if name == "lv" else scene.dirichlet)
    return scene.tagged, body, {}, {"dirichlet": dirichlet}


def run(case: str) -> dict[str, Any]:
    """Run ``case`` (one of :data:`CASES`) and return its figures."""
    import harpx
    from harpx.imaging.harp import extract_phase
    from harpx.tracking.results import tracking_error
    from harpx.tracking.track import track

    tagged, body, upsample, kwargs = inputs(case)
    wall, cpu = time.perf_counter(), _cpu()
    phase = extract_phase(tagged, **upsample)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if case == "phantom-harp":
            from harpx.imaging.harptrack import track_harp

            out = track_harp(phase, points=tagged)
        else:
            out = track(phase, body, **kwargs)
    wall, cpu = time.perf_counter() - wall, _cpu() - cpu
    step_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    del phase  # the images are done with: the evaluation below does not add to them
    err = tracking_error(out, tagged)
    row: dict[str, Any] = {
        "case": case,
        "harpx": str(Path(harpx.__file__).resolve().parent.parent),
        "step_wall": round(wall, 2),
        "step_cpu": round(cpu, 2),
        "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "step_peak_rss_mib": round(step_peak, 1),
        "mean": round(float(err.mean_all), 5),
        "p95": round(float(err.p95_all), 5),
        "max": round(float(err.max_all), 4),
    }
    if "constraint_points" in out.attrs:
        row["points"] = int(out.attrs["constraint_points"])
    if "iterations_per_pass" in out.attrs:
        row["iterations"] = [int(i) for i in np.atleast_1d(out.attrs["iterations_per_pass"])]
    row.update({k: float(v) for k, v in out.attrs.items() if k.startswith("time_")})
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", choices=CASES)
    args = parser.parse_args()
    print(json.dumps(run(args.case)), flush=True)


if __name__ == "__main__":
    main()
