"""Benchmark of ``extract_phase`` against bare 2D FFT round trips of the same data.

Cases (isotropic voxels, ``upsample=2``, radius 0.5, three tags x, y, z with slice axes z, z, y):

* **phantom**: 3 tags × 13 frames × 13 slices × 160² (1.5 mm voxels, paper §4.1 size);
* **cardiac**: 3 tags × 25 frames × 12 slices × 256² (1.25 mm voxels, paper §4.2 size).

``phase()`` is :func:`harpx.imaging.harp.extract_phase` on an in-memory ``tagged/1`` dataset,
output included (phase and magnitude on the common refined grid, 8× the input voxels), in
float32 (the default, ``phase()``) and float64 (``phase64``).
The FFT baselines transform exactly the arrays a straightforward implementation of the same
method transforms: for every tag, its acquisition slices *upsampled in-plane* (x and y tags:
frames × nz slices of 2ny × 2nx; z tag: frames × ny slices of 2nz × 2nx), complex128, one
forward and one inverse 2D FFT:

* **pyfftw**: ``pyfftw.FFTW`` plans (FFTW_MEASURE, all cores) executed on preallocated aligned
  buffers — the bare transform cost, nothing else; complex128 (``pyfftw``) and complex64
  (``pyfftw32``, the precision of the float32 ``phase()``);
* **numpy.fft** and **scipy.fft** (``workers`` = all cores) ``fft2`` + ``ifft2``.

Every repeat runs all methods back to back (the machine may be shared) and the table shows
medians over repeats of wall-clock time, plus user and system CPU time (all threads), which
are less sensitive to other processes: user time is the computation, system time mostly the
kernel providing fresh zeroed pages for new output arrays. The first ``phase()`` call, which
plans the FFTs, is reported apart.
Run ``python benchmarks/bench_phase.py`` (``--quick`` for the phantom case only, ``--repeats``).

``--rss CASE`` measures peak memory instead: a child process synthesises the case and saves
it (``/tmp``), then a fresh child per precision loads it and runs ``phase()`` once, and its
peak resident set size (``ru_maxrss``: input + output + temporaries + interpreter) is
reported, with the same for a per-frame lazy pass (``ds.chunk(time=1)``, each frame's
phase computed and dropped, as the tracker consumes it).
"""

from __future__ import annotations

import argparse
import gc
import os
import platform
import resource
import statistics
import time

import numpy as np
import pyfftw
import scipy
import scipy.fft
import xarray as xr

from harpx.imaging.harp import extract_phase
from harpx.imaging.synth import synthesize_tagged

CASES = {
    "phantom": dict(frames=13, shape=(13, 160, 160), spacing=1.5, period=8.0),
    "cardiac": dict(frames=25, shape=(12, 256, 256), spacing=1.25, period=8.0),
}
UPSAMPLE = 2


def tagged_dataset(frames: int, shape: tuple[int, int, int], spacing: float, period: float):
    """A CSPAMM cine of a still 3D pattern with noise (content does not change the cost).

    Ground truth is dropped: acquired data has ``image`` and a ``mask``/``body`` only, and
    carrying ``displacement_true`` (3 x the phase output) is timed apart.
    """
    ds = synthesize_tagged(
        lambda X, t: np.zeros_like(X),
        shape=shape,
        spacing=(spacing,) * 3,
        times=np.arange(frames) * 20.0,
        tag_period=period,
        snr=20.0,
        oversample=1,
        rng=0,
    )
    return ds.drop_vars("displacement_true"), ds


def fft_stacks(shape: tuple[int, int, int], frames: int) -> list[tuple[int, int, int]]:
    """Shapes of the upsampled in-plane slice stacks transformed per tag (x, y, z tags)."""
    nz, ny, nx = shape
    m = UPSAMPLE
    return [
        (frames * nz, m * ny, m * nx),  # x tag, slices normal to z
        (frames * nz, m * ny, m * nx),  # y tag, slices normal to z
        (frames * ny, m * nz, m * nx),  # z tag, slices normal to y
    ]


class PyfftwRoundTrip:
    """Forward + inverse 2D FFT plans on two preallocated aligned buffers."""

    def __init__(self, shape: tuple[int, int, int], threads: int, rng, dtype=np.complex128) -> None:
        self.a = pyfftw.empty_aligned(shape, dtype=dtype)
        self.b = pyfftw.empty_aligned(shape, dtype=dtype)
        flags = ("FFTW_MEASURE",)
        self.fwd = pyfftw.FFTW(self.a, self.b, axes=(-2, -1), flags=flags, threads=threads)
        self.inv = pyfftw.FFTW(
            self.b,
            self.a,
            axes=(-2, -1),
            direction="FFTW_BACKWARD",
            flags=flags,
            threads=threads,
        )
        self.a[...] = rng.standard_normal(shape)

    def __call__(self) -> None:
        self.fwd.execute()
        self.inv.execute()


def timed(fn) -> float:
    """Wall-clock seconds of ``fn()``."""
    return timed_both(fn)[0]


def timed_both(fn) -> tuple[float, float, float]:
    """(wall-clock, user CPU, system CPU) seconds of ``fn()``; CPU sums all threads.

    System time is mostly the kernel zeroing fresh pages for new arrays (page faults).
    """
    gc.collect()
    before = resource.getrusage(resource.RUSAGE_SELF)
    wall = time.perf_counter()
    fn()
    wall = time.perf_counter() - wall
    after = resource.getrusage(resource.RUSAGE_SELF)
    return wall, after.ru_utime - before.ru_utime, after.ru_stime - before.ru_stime


def run_case(name: str, repeats: int, threads: int) -> dict:
    spec = CASES[name]
    ds, with_truth = tagged_dataset(spec["frames"], spec["shape"], spec["spacing"], spec["period"])
    rng = np.random.default_rng(1)
    stacks = fft_stacks(spec["shape"], spec["frames"])
    fft_elems = sum(int(np.prod(s)) for s in stacks)

    first = timed(lambda: extract_phase(ds, upsample=UPSAMPLE))  # plans the FFTs
    extract_phase(ds, upsample=UPSAMPLE, dtype="float64")
    out = extract_phase(ds, upsample=UPSAMPLE)
    out_elems = int(out.phase.size)
    del out

    times: dict[str, list[float]] = {
        "phase": [],
        "phase64": [],
        "pyfftw": [],
        "pyfftw32": [],
        "numpy": [],
        "scipy": [],
    }
    cpu: dict[str, list[float]] = {k: [] for k in times}
    system: dict[str, list[float]] = {k: [] for k in times}

    def record(label: str, pairs: list[tuple[float, float, float]]) -> None:
        times[label].append(sum(p[0] for p in pairs))
        cpu[label].append(sum(p[1] for p in pairs))
        system[label].append(sum(p[2] for p in pairs))

    for _ in range(repeats):
        record("phase", [timed_both(lambda: extract_phase(ds, upsample=UPSAMPLE))])
        record(
            "phase64",
            [timed_both(lambda: extract_phase(ds, upsample=UPSAMPLE, dtype="float64"))],
        )
        # pyfftw: plans are built per stack outside the timed region
        for label, dtype in (("pyfftw", np.complex128), ("pyfftw32", np.complex64)):
            pairs = []
            for shape in stacks:
                rt = PyfftwRoundTrip(shape, threads, rng, dtype)
                rt()  # warm the buffers
                pairs.append(timed_both(rt))
                del rt
            record(label, pairs)
        for label, mod, kw in (
            ("numpy", np.fft, {}),
            ("scipy", scipy.fft, {"workers": threads}),
        ):
            pairs = []
            for shape in stacks:
                data = rng.standard_normal(shape) + 0j
                pairs.append(timed_both(lambda d=data, m=mod, k=kw: m.ifft2(m.fft2(d, **k), **k)))
                del data
            record(label, pairs)
    med = {k: statistics.median(v) for k, v in times.items()}
    med_cpu = {k: statistics.median(v) for k, v in cpu.items()}
    med_sys = {k: statistics.median(v) for k, v in system.items()}
    truth = None
    if name == "phantom":  # cardiac ground truth on the refined grid would need > 11 GB
        truth = statistics.median(
            timed(lambda: extract_phase(with_truth, upsample=UPSAMPLE)) for _ in range(3)
        )
    return {
        "truth": truth,
        "name": name,
        "first": first,
        "median": med,
        "median_cpu": med_cpu,
        "median_sys": med_sys,
        "all": times,
        "fft_elems": fft_elems,
        "out_elems": out_elems,
        "stacks": stacks,
        "input": tuple(ds.image.shape),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="phantom case only")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--rss", choices=sorted(CASES), help="peak memory of one case")
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        _child(*args.child)
        return
    if args.rss:
        peak_memory(args.rss)
        return
    names = ["phantom"] if args.quick else ["phantom", "cardiac"]
    print(
        f"# bench_phase: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"threads={args.threads}, numpy {np.__version__}, scipy {scipy.__version__}, "
        f"pyfftw {pyfftw.__version__}, xarray {xr.__version__}, load "
        f"{os.getloadavg()[0]:.1f}"
    )
    results = [run_case(name, args.repeats, args.threads) for name in names]
    print()
    print(
        "| case | FFT'd stacks (upsampled) | phase() f32 s | phase() f64 s | pyfftw c128 "
        "fwd+inv s | pyfftw c64 s | numpy.fft s | scipy.fft s | f32 / pyfftw c128 | "
        "f32 / pyfftw c64 | f64 / pyfftw c128 | f32 / f64 | user CPU s f32 / c128 | "
        "system CPU s f32 / c128 | first phase() s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        m, c, y = r["median"], r["median_cpu"], r["median_sys"]
        stacks = " + ".join("x".join(str(n) for n in s) for s in r["stacks"])
        print(
            f"| {r['name']} {r['input']} | {stacks} | {m['phase']:.3f} | {m['phase64']:.3f} | "
            f"{m['pyfftw']:.3f} | {m['pyfftw32']:.3f} | {m['numpy']:.3f} | {m['scipy']:.3f} | "
            f"{m['phase'] / m['pyfftw']:.2f} | {m['phase'] / m['pyfftw32']:.2f} | "
            f"{m['phase64'] / m['pyfftw']:.2f} | {m['phase'] / m['phase64']:.2f} | "
            f"{c['phase']:.2f} / {c['pyfftw']:.2f} | {y['phase']:.2f} / {y['pyfftw']:.2f} | "
            f"{r['first']:.2f} |"
        )
    print()
    for r in results:
        if r["truth"] is not None:
            print(
                f"{r['name']}: phase() with displacement_true carried to the refined grid: "
                f"{r['truth']:.3f} s (median of 3)"
            )
        print(
            f"{r['name']}: phase() writes {r['out_elems'] / 1e6:.0f} M voxels x 2 variables; "
            f"the FFT baselines transform {r['fft_elems'] / 1e6:.0f} M complex values; "
            "per-repeat seconds: "
            + "; ".join(f"{k} {', '.join(f'{v:.3f}' for v in vs)}" for k, vs in r["all"].items())
        )


def _child(action: str, name: str, path: str) -> None:
    """One measured process: ``make`` the case file, or run ``float32``/``float64``/``lazy``."""
    if action == "make":
        spec = CASES[name]
        ds, _ = tagged_dataset(spec["frames"], spec["shape"], spec["spacing"], spec["period"])
        ds.to_netcdf(path)
        return
    ds = xr.open_dataset(path).load()
    start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    wall = time.perf_counter()
    if action == "lazy":
        phase = extract_phase(ds.chunk(time=1), upsample=UPSAMPLE)
        for k in range(ds.sizes["time"]):
            phase.isel(time=k).compute()
    else:
        phase = extract_phase(ds, upsample=UPSAMPLE, dtype=action)  # type: ignore[arg-type]
    wall = time.perf_counter() - wall
    nbytes = sum(phase[v].nbytes for v in ("phase", "magnitude")) / 2**30
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(f"{action} {start:.2f} {peak:.2f} {nbytes:.2f} {wall:.1f}")


def peak_memory(name: str) -> None:
    """Peak RSS (GiB) of ``phase()`` on one case, each precision in its own process."""
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, f"{name}.nc")
        run = [sys.executable, __file__, "--child"]
        subprocess.run([*run, "make", name, path], check=True)
        print(
            f"| case {name} | run | RSS after loading the input (GiB) | peak RSS (GiB) | "
            "phase + magnitude (GiB) | wall s |\n|---|---|---|---|---|---|"
        )
        for action in ("float32", "float64", "lazy"):
            out = subprocess.run(
                [*run, action, name, path], check=True, capture_output=True, text=True
            ).stdout.split()
            label = {"lazy": "lazy float32, one frame at a time"}.get(action, action)
            print(f"| {name} | {label} | {out[1]} | {out[2]} | {out[3]} | {out[4]} |")


if __name__ == "__main__":
    main()
