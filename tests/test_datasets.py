"""The stored datasets: present, valid, small, and what their recipe makes (to rounding)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

import harpx.datasets as datasets
from harpx.schema import validate
from harpx.tracking.track import track

NAMES = ["lv-small", "phantom-small", "tongue-small"]


def test_listing_names_every_stored_dataset():
    assert sorted(datasets.list_datasets()) == NAMES
    assert datasets.path("lv-small", "phase").parts[-2:] == ("lv-small", "phase.nc")
    with pytest.raises(ValueError, match=r"unknown dataset 'brain'; stored: \['lv-small'"):
        datasets.open("brain")
    with pytest.raises(ValueError, match=r"kind='mesh'; expected one of \['tagged'"):
        datasets.open("lv-small", "mesh")


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("kind", datasets.KINDS)
def test_stored_archives_are_valid_and_small(name, kind):
    file = datasets.path(name, kind)
    # the folder must stay small enough to ship in the repository
    assert file.stat().st_size < 5e6, f"{file} is {file.stat().st_size / 1e6:.1f} MB"
    ds = datasets.open(name, kind, chunks={"time": 1})  # lazy, one frame per chunk
    try:
        validate(ds, kind)
        assert ds.attrs["harpx_schema"] == f"{kind}/1"
    finally:
        ds.close()


def test_the_whole_folder_stays_under_15_mb():
    total = sum(f.stat().st_size for f in datasets.directory().rglob("*") if f.is_file())
    assert total < 15e6, f"datasets_synthetic/ holds {total / 1e6:.1f} MB"


# Regenerated floats are compared within bounds, not bit for bit: the FFTs and numpy's SIMD
# kernels round differently on other CPUs, and after the 12-bit truncation of the stored
# mantissa (datasets.MANTISSA_BITS) a rounding-level change flips a value by one stored
# quantum. Measured with numpy's AVX-512 kernels disabled (NPY_DISABLE_CPU_FEATURES=
# "AVX512_ICL X86_V4", as on a CPU without them): 52 of 241 920 phases differ, each by
# 4.9e-4 rad, one quantum for |φ| in [2, π), and 3 magnitudes by one quantum. A real change
# moves far more: 0.1 % more rotation puts the 99.9th percentile of the phase change at
# 0.03 rad and its maximum at 1.3 rad. Bounds per variable: (99.9th percentile, maximum)
# of the wrapped difference (phase, rad) or of |a - b| / max|b| (other floats).
_PHASE_BOUNDS = (1e-3, 0.05)  # two quanta at |φ| ≥ 2; 0.05 rad is 0.05 mm of 6 mm tags
_RELATIVE_BOUNDS = (2.0**-11, 1e-2)  # two 12-bit quanta of the largest value; 1 % of it


def _assert_regenerated(made: xr.Dataset, stored: xr.Dataset) -> None:
    """``made`` equals ``stored`` exactly in structure, within rounding bounds in floats."""
    floats = [n for n in stored.data_vars if stored[n].dtype.kind == "f"]
    # dims, coordinates, attributes, masks and integer data: exact
    xr.testing.assert_identical(made.drop_vars(floats), stored.drop_vars(floats))
    for name in floats:
        a, b = made[name], stored[name]
        assert (a.dims, a.dtype, a.attrs) == (b.dims, b.dtype, b.attrs), name
        x, y = np.asarray(a.values, np.float64), np.asarray(b.values, np.float64)
        finite = np.isfinite(y)
        assert np.array_equal(np.isfinite(x), finite), f"{name}: NaN/inf moved"
        x, y = x[finite], y[finite]
        if name == "phase":
            change, (q_bound, max_bound) = np.abs(np.angle(np.exp(1j * (x - y)))), _PHASE_BOUNDS
        else:
            scale = max(float(np.abs(y).max(initial=0.0)), np.finfo(np.float64).tiny)
            change, (q_bound, max_bound) = np.abs(x - y) / scale, _RELATIVE_BOUNDS
        if change.size:
            q, worst = float(np.quantile(change, 0.999)), float(change.max())
            assert q <= q_bound and worst <= max_bound, (
                f"{name} changed: 99.9th percentile {q:.3g} (bound {q_bound:.3g}), max "
                f"{worst:.3g} (bound {max_bound:.3g}); regenerate the archives if intended"
            )


def test_phantom_tagged_and_phase_regenerate_within_rounding():
    made = datasets.build("phantom-small", ("tagged", "phase"))
    for kind in ("tagged", "phase"):
        # same code, same seed: equal up to the CPU's rounding (regenerate after changing it)
        _assert_regenerated(made[kind], datasets.open("phantom-small", kind))


def test_regeneration_check_tolerates_one_quantum_flips(rng):
    # what another CPU does: one stored quantum up in 0.05 % of the values (4x the measured)
    stored = datasets.open("phantom-small", "phase")
    flipped = stored.copy(deep=True)
    for name in ("phase", "magnitude"):
        bits = flipped[name].values.view(np.uint32).reshape(-1)
        pick = rng.choice(bits.size, bits.size // 2000, replace=False)
        bits[pick] += np.uint32(1 << (23 - datasets.MANTISSA_BITS[name]))
    _assert_regenerated(flipped, stored)


@pytest.mark.parametrize(
    ("field", "factor"),
    [("angle", 1.01), ("tag_period", 1.01)],
    ids=["motion+1%", "tag-period+1%"],
)
def test_regeneration_check_catches_a_real_change(monkeypatch, field, factor):
    import dataclasses
    import importlib

    module = importlib.import_module("harpx.scenes.phantom")
    small = module.GEOMETRIES["small"]
    changed = dataclasses.replace(small, **{field: getattr(small, field) * factor})
    monkeypatch.setitem(module.GEOMETRIES, "small", changed)
    made = datasets.build("phantom-small", ("tagged", "phase"))
    for kind, name in (("tagged", "image"), ("phase", "phase")):
        stored = datasets.open("phantom-small", kind)
        if field == "tag_period":  # the recorded frequency differs, and exactly is checked
            with pytest.raises(AssertionError, match="tag_frequency"):
                _assert_regenerated(made[kind], stored)
            made[kind] = made[kind].assign_coords(tag_frequency=stored.tag_frequency)
        with pytest.raises(AssertionError, match=rf"{name} changed: 99.9th percentile"):
            _assert_regenerated(made[kind], stored)


@pytest.mark.slow
def test_phantom_tracked_regenerates_within_tolerance():
    """Re-track the first two frames of the stored phase (so the test is fast).

    Tracking is causal (frame n only sees frames 0..n), so they are the stored run's first
    two frames; 0.02 mm is a tenth of the stored result's mean error against the truth
    (0.2 mm), so the tracker may change in its last digits but not in what it finds.
    """
    recipe = datasets.DATASETS["phantom-small"]
    phase = datasets.open("phantom-small", "phase").isel(time=slice(0, 2))
    body = datasets.build("phantom-small", ("tagged",))["body"]
    again = track(phase, body, progress=False, **recipe.track)
    stored = datasets.open("phantom-small", "tracked").isel(time=slice(0, 2))
    change = np.abs(again.displacement.values - stored.displacement.values).max()
    assert change < 0.02, f"tracked displacement changed by {change:.3g} mm"


def test_missing_archive_says_how_to_make_it(tmp_path):
    with pytest.raises(FileNotFoundError, match="python -m harpx.datasets regenerate lv-small"):
        datasets.open("lv-small", "tracked", root=tmp_path)


def test_regenerate_writes_the_folder_and_its_readme(tmp_path, capsys):
    assert (
        datasets.main(
            ["regenerate", "phantom-small", "--kinds", "tagged", "--output", str(tmp_path)]
        )
        == 0
    )
    assert (tmp_path / "phantom-small" / "tagged.nc").is_file()
    readme = (tmp_path / "README.md").read_text()
    assert "python -m harpx.datasets regenerate" in readme
    assert "scene = harpx.scenes.phantom(size='small')" in readme
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize("bits", [1, 12, 16, 52])
def test_shortened_mantissa_truncates_towards_zero(rng, bits):
    values = np.concatenate([rng.uniform(-np.pi, np.pi, 1000), [np.nan, np.inf, -0.0, np.pi]])
    out = datasets.shorten_mantissa(values, bits)
    finite = np.isfinite(values)
    assert np.all(np.abs(out[finite]) <= np.abs(values[finite]))  # phases stay in [-π, π)
    assert np.all(np.sign(out[finite]) == np.sign(values[finite]))
    rel = np.abs(out[finite] - values[finite]) / np.maximum(np.abs(values[finite]), 1e-300)
    assert rel.max() < 2.0**-bits
    assert np.isnan(out[-4]) and out[-3] == np.inf
    with pytest.raises(ValueError, match="bits=0 must be between 1 and 52"):
        datasets.shorten_mantissa(values, 0)


# --- listing: what `list` shows opens, errors name what list_datasets() shows ---------------


def test_list_shows_only_what_open_and_path_accept(capsys):
    from harpx.io.mesh import read_body_mesh

    assert datasets.main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name in NAMES:
        line = next(x for x in lines if x.startswith(f"{name} "))
        archives = line.split("[archives: ")[1].split(";")[0].split(", ")
        assert archives == list(datasets.KINDS), line
        for kind in archives:  # every archive listed opens as its kind
            ds = datasets.open(name, kind, chunks={"time": 1})
            assert ds.attrs["harpx_schema"] == f"{kind}/1"
            ds.close()
        assert line.endswith("mesh: mesh.vtu]"), line  # and the mesh is a file path() gives
        assert read_body_mesh(datasets.path(name, "mesh")).mesh.nelements > 0
    assert "harpx.datasets.path(NAME, 'mesh')" in "\n".join(lines)


def test_open_mesh_says_how_to_read_the_mesh():
    with pytest.raises(ValueError, match=r"harpx.datasets.path\('lv-small', 'mesh'\) gives it"):
        datasets.open("lv-small", "mesh")


def test_unknown_name_lists_the_stored_datasets_apart_from_the_recipes():
    with pytest.raises(ValueError) as err:
        datasets.open("brain")
    stored, _, others = str(err.value).partition("not stored")
    assert repr(sorted(datasets.list_datasets())) in stored and "paper" not in stored
    assert "'phantom-paper'" in others  # still named, as what regenerate() makes


@pytest.mark.parametrize("kind", datasets.KINDS)
def test_open_keeps_the_archives_conventions(tmp_path, kind):
    import netCDF4

    from harpx.io.netcdf import open_dataset, to_netcdf

    file = datasets.path("phantom-small", kind)
    with netCDF4.Dataset(file) as nc:
        stored = nc.getncattr("Conventions")
    ds = datasets.open("phantom-small", kind)
    assert ds.attrs["Conventions"] == stored
    assert stored.startswith("CF-") and ("UGRID-1.0" in stored) == (kind == "tracked")
    # written again and reopened by harpx.io, it is kept as the dataset's own
    assert open_dataset(to_netcdf(ds, tmp_path / "again.nc")).attrs["Conventions"] == stored
