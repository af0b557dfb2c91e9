"""The extraction settings of a phase dataset, read back as extract_phase wrote them."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.errors import HarpxWarning, SchemaError
from harpx.imaging.harp import extract_phase
from harpx.imaging.phase_parameters import PhaseParameters
from harpx.imaging.stacks import tagged_dataset


def _tagged(spacing: tuple[float, float, float]) -> xr.Dataset:
    """A small SPAMM dataset with one x tag (all-constant images: only the grid matters)."""
    shape = (4, 6, 8)
    axes = [s * np.arange(n) for s, n in zip(spacing, shape, strict=True)]
    return tagged_dataset(
        np.ones((1, 1, *shape)), tag=["x"], tag_frequency=[0.2],
        tag_direction=[[1.0, 0.0, 0.0]], slice_axis=["z"], time=[0.0],
        z=axes[0], y=axes[1], x=axes[2], sequence="SPAMM", check=False,
    )  # fmt: skip


def test_what_extract_phase_writes_is_read_back():
    tagged = _tagged((3.0, 1.0, 1.0))
    with pytest.warns(HarpxWarning, match="constant"):  # constant images: only the grid matters
        phase = extract_phase(tagged, upsample=2, radius=0.4)
    p = PhaseParameters.from_dataset(phase)
    assert (p.sequence, p.upsample, p.radius, p.disk_bandpass) == ("SPAMM", 2, 0.4, True)
    # the slice axis z is in no tag's plane: unrefined; y and x by upsample (refinement_factors)
    assert p.upsample_factors == (1, 2, 2)


def test_tagged_images_read_as_the_defaults():
    p = PhaseParameters.from_dataset(_tagged((1.0, 1.0, 1.0)))
    assert p == PhaseParameters(sequence="SPAMM")
    assert (p.upsample, p.radius, p.bandpass, p.upsample_factors) == (1, 0.5, None, (1, 1, 1))


def test_netcdf_style_attributes_are_accepted():
    ds = xr.Dataset(attrs={"upsample": np.int64(3), "radius": np.float32(0.5),
                           "upsample_factors": np.array([1, 3, 3])})  # fmt: skip
    p = PhaseParameters.from_dataset(ds)
    assert p.upsample == 3 and isinstance(p.upsample, int)
    assert p.upsample_factors == (1, 3, 3)


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("upsample", 0),
        ("upsample", 1.5),
        ("upsample", True),
        ("radius", 0.0),
        ("radius", 1.5),
        ("radius", float("nan")),
        ("sequence", "tagged"),
        ("bandpass", 3),
        ("upsample_factors", [1, 2]),
        ("upsample_factors", [1, 0, 2]),
    ],
)
def test_a_bad_attribute_is_refused_by_name(name, value):
    with pytest.raises(SchemaError, match=f"'{name}' is"):
        PhaseParameters.from_dataset(xr.Dataset(attrs={name: value}))
