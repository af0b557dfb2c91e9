"""Twist and torsion need the coverage a segment needs: a level imaged in a sliver is NaN.

The motion is a linear twist about the long axis (K degrees per mm of height, as in
``test_strain``), so a level's rotation is -K times its ring's centroid height, a closed
form that does not depend on which sectors of the ring carry data. Cells lose their tag
data through ``observed_directions`` 0, as a tracked result records it.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from harpx.cardiac.strain import aha_segments, cardiac_strain
from tests.cardiac._lv import TEMPLATE, body_of, centroid_z, fe_dataset
from tests.cardiac.test_strain import K, _twist

BODY = body_of(n=(32, 12, 3))
SEGMENT = aha_segments(BODY.dof_points[BODY.cells[:, :8]].mean(axis=1), TEMPLATE, anterior=0.0)
Z_BASE = centroid_z(TEMPLATE, -70.0 + 160.0 / 3.0, 10.0)
Z_APEX = centroid_z(TEMPLATE, -70.0, -70.0 + 80.0 / 3.0)


def _strain(no_data: np.ndarray, **options: float) -> tuple[object, list[str]]:
    """cardiac_strain of the twist with the cells ``no_data`` without tag data; warnings."""
    rank = np.where(no_data, 0, 3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = cardiac_strain(fe_dataset(_twist, BODY, rank=rank), TEMPLATE, anterior=0.0, **options)
    return out, [str(w.message) for w in caught]


def test_an_apex_imaged_in_a_sliver_gives_no_twist() -> None:
    # tag data in 2 cells of the apical ring only (segment 13): every apical segment is
    # below min_coverage, so the apical rotation would rest on 2 of its 600 cells
    apical = (SEGMENT >= 13) & (SEGMENT <= 16)
    no_data = apical.copy()
    no_data[np.flatnonzero(SEGMENT == 13)[:2]] = False
    out, messages = _strain(no_data)
    assert any("no image data in AHA segment(s) 13-16" in m for m in messages)
    assert any(
        "twist and torsion are NaN" in m and "apex (AHA 13-16: 0.000)" in m for m in messages
    ), messages
    # unfixed: twist 10.4 degrees at 100 ms with source 'observed' and no warning
    assert np.isnan(out.twist.values).all() and np.isnan(out.torsion.values).all()
    assert np.isnan(out.rotation.sel(level="apex").values).all()
    assert out.twist.attrs["source"] == out.torsion.attrs["source"] == "no data"
    assert out.attrs["levels_without_data"] == "apex"
    assert float(out.level_coverage.sel(level="apex")) == 0.0  # no apical segment counts
    # the basal level is untouched: its closed-form rotation, measured by the tags
    base = float(out.rotation.sel(level="base")[1])
    assert base == pytest.approx(-K * Z_BASE, abs=0.1)  # 0.66 degrees; measured 0.016 off
    assert out.rotation.attrs["source"] == "observed"


def test_half_an_apical_ring_still_gives_the_closed_form_twist() -> None:
    # segments 15 and 16 without data: the apex level is segments 13 and 14 (about half
    # its template volume), whose rotation is the whole ring's for this axisymmetric twist
    no_data = (SEGMENT == 15) | (SEGMENT == 16)
    out, messages = _strain(no_data)
    assert not any("twist and torsion are NaN" in m for m in messages), messages
    assert out.attrs["levels_without_data"] == ""
    # twist = K (z_base - z_apex) = 10.4 degrees; measured 0.07 off (the same mesh
    # tolerance as the whole ring in test_strain)
    assert float(out.twist[1]) == pytest.approx(K * (Z_BASE - Z_APEX), abs=0.2)
    assert out.twist.attrs["source"] == "observed"
    # the level's coverage counts its segments with data only (13, 14), not the Gauss
    # points of neighbouring cells that fall in 15 and 16 (coverage 0.007, 0.011)
    vol, template_vol = out.segment_volume.values, out.segment_template_volume.values
    expected = vol[12:14].sum() / template_vol[12:16].sum()
    assert float(out.level_coverage.sel(level="apex")) == pytest.approx(expected, rel=1e-12)
    assert 0.45 < expected < 0.5  # two of four equal sectors, each 97 % covered


def test_a_level_below_min_coverage_gives_no_twist_even_if_its_segments_have_data() -> None:
    # the same half ring with min_coverage 0.6: segments 13 and 14 are 97 % covered and
    # keep their values, but the apical level (0.49 of its volume) falls below 0.6
    no_data = (SEGMENT == 15) | (SEGMENT == 16)
    out, messages = _strain(no_data, min_coverage=0.6)
    assert any("twist and torsion are NaN" in m and "below min_coverage 0.6" in m for m in messages)
    assert np.isfinite(out.segment_strain.sel(segment=[13, 14]).values).all()
    assert np.isnan(out.twist.values).all() and np.isnan(out.torsion.values).all()
    assert out.attrs["levels_without_data"] == "apex"
    assert float(out.rotation.sel(level="base")[1]) == pytest.approx(-K * Z_BASE, abs=0.1)
