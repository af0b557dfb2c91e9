"""Draw the plots changed in issue 26 (item 5) with whatever harpx is importable.

Run once with the harpx of an older commit on ``PYTHONPATH`` (``git archive <commit> harpx``
unpacked in a folder) and once with the working tree, on the same cached data, to get the
before/after pairs of benchmarks/results/plots_before_after/:

    python benchmarks/plots_before_after.py data  --cache /tmp/harpx-plots   # build once
    PYTHONPATH=/tmp/harpx_head python benchmarks/plots_before_after.py draw \
        --cache /tmp/harpx-plots --out benchmarks/results/plots_before_after/before
    python benchmarks/plots_before_after.py draw --cache /tmp/harpx-plots \
        --out benchmarks/results/plots_before_after/after

The data: the small phantom (phase, FE hex8 tracking, as in tutorial 01), the small tongue
(FE hex20 tracking, its five muscles) and the small LV tracked with its own template
(``scene.template()``), whose cardiac strain gives the radial/circumferential/longitudinal
maps. Each figure is saved at 80 dpi, the size the user guide shows.
"""

from __future__ import annotations

import argparse
import inspect
import pickle
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # a script's choice; the library never sets the backend

import matplotlib.pyplot as plt  # noqa: E402

DPI = 80


def build(cache: Path) -> None:
    """Track the three small scenes once and keep the datasets in ``cache``."""
    import harpx  # noqa: F401  (registers ds.harp)
    from harpx.io.netcdf import to_netcdf
    from harpx.mechanics.loads import Fixed
    from harpx.scenes import lv, phantom, tongue

    cache.mkdir(parents=True, exist_ok=True)
    scene = phantom("small")
    phase = scene.tagged.harp.phase(upsample=2)
    to_netcdf(phase, cache / "phantom_phase.nc")
    to_netcdf(phase.harp.track(scene.body("hex8"), epsilon=0.05), cache / "phantom_tracked.nc")

    scene = tongue("small")
    body = scene.body("hex20")
    tracked = scene.tagged.harp.phase().harp.track(
        body, dirichlet=[Fixed("mandible"), Fixed("base")]
    )
    to_netcdf(tracked, cache / "tongue_tracked.nc")

    scene = lv(size="small")
    phase = scene.tagged.harp.phase(upsample=1, radius=0.7)
    tracked = phase.harp.track(scene.body("stress-free"), epsilon=0.2, dirichlet=scene.dirichlet())
    # the cardiac strain is computed when drawing: a cardiac_strain result does not go into
    # NetCDF when one of its attributes is empty (no segment without data)
    to_netcdf(tracked, cache / "lv_tracked.nc")
    (cache / "lv_template.pickle").write_bytes(pickle.dumps(scene.template()))
    to_netcdf(phase, cache / "lv_phase.nc")


def draw(cache: Path, out: Path) -> list[str]:
    """Draw every changed plot from the cached data into ``out`` (one PNG each)."""
    import harpx
    import harpx.plotting
    from harpx.io.netcdf import open_dataset

    out.mkdir(parents=True, exist_ok=True)
    phase = open_dataset(cache / "phantom_phase.nc")
    phantom = open_dataset(cache / "phantom_tracked.nc")
    tongue = open_dataset(cache / "tongue_tracked.nc")
    template = pickle.loads((cache / "lv_template.pickle").read_bytes())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lv = open_dataset(cache / "lv_tracked.nc").harp.cardiac_strain(template)
    lv_phase = open_dataset(cache / "lv_phase.nc")
    new = "component" in inspect.signature(harpx.plotting.strain_map).parameters
    figures = {
        # asked for z = 0.0: the phantom's slices are at +-0.4 mm
        "phase_map_phantom": lambda: phase.harp.plot.phase(tag="y", time=0.0, z=0.0),
        "phase_map_lv": lambda: lv_phase.harp.plot.phase(tag="x", z=-30.0),
        "strain_map_phantom": (
            (lambda: phantom.harp.plot.strain(component="xy"))
            if new
            else (lambda: phantom.harp.plot.strain(i=0, j=1))
        ),
        "strain_map_lv": (
            (lambda: lv.harp.plot.strain(component="circumferential", z=-30.0))
            if new
            else (lambda: lv.harp.plot.strain(i=0, j=0, z=-30.0))
        ),
        "fiber_stretch_by_region_tongue": lambda: tongue.harp.plot.fiber_stretch(),
        "fiber_stretch_by_region_lv": lambda: lv.harp.plot.fiber_stretch(),
    }
    if new:
        for c in ("radial", "longitudinal"):
            figures[f"strain_map_lv_{c}"] = lambda c=c: lv.harp.plot.strain(component=c, z=-30.0)
    written = []
    for name, plot in figures.items():
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            drawn = plot()
        fig = drawn if hasattr(drawn, "savefig") else drawn.figure
        path = out / f"{name}.png"
        fig.savefig(path, dpi=DPI)
        plt.close(fig)
        size = fig.get_size_inches() * DPI
        notes = "; ".join(sorted({str(w.message)[:100] for w in caught}))
        written.append(f"{name}: {size[0]:.0f} x {size[1]:.0f} px" + (f" ({notes})" * bool(notes)))
    return written


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("step", choices=("data", "draw"))
    parser.add_argument("--cache", type=Path, default=Path("/tmp/harpx-plots"))
    parser.add_argument("--out", type=Path, default=Path("plots"))
    args = parser.parse_args()
    if args.step == "data":
        build(args.cache)
    else:
        print("\n".join(draw(args.cache, args.out)))


if __name__ == "__main__":
    main()
