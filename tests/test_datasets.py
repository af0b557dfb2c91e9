"""The stored datasets: present, valid, small, and exactly what their recipe makes."""

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
    with pytest.raises(ValueError, match=r"unknown dataset 'brain'; known: \['lv-paper'"):
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


def test_phantom_tagged_and_phase_regenerate_exactly():
    made = datasets.build("phantom-small", ("tagged", "phase"))
    for kind in ("tagged", "phase"):
        # same code, same seed: bit-identical (regenerate the archives after changing it)
        xr.testing.assert_identical(made[kind], datasets.open("phantom-small", kind))


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
