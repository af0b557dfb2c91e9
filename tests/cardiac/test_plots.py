"""The clinical figures: the AHA bull's-eye in the standard orientation, segment curves."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure

from harpx.cardiac.strain import aha_segments, cardiac_strain, lv_measures
from harpx.errors import HarpxWarning
from harpx.plotting import bullseye, segment_curves
from tests.cardiac._lv import GEOMETRY, TEMPLATE, body_of, fe_dataset, wall_samples

pytestmark = pytest.mark.filterwarnings("error::harpx.errors.HarpxWarning")


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _wedges(fig: Figure) -> dict[str, object]:
    return {p.get_gid(): p for p in fig.axes[0].patches if p.get_gid()}


def _field_in(direction_deg: float, z_range: tuple[float, float], anterior: float):
    """Segment means of a radial strain of 0.1 only near one template angle and height."""
    pts = wall_samples(step=2.0)
    q = TEMPLATE.to_local(pts)
    off = np.rad2deg(
        np.angle(np.exp(1j * (np.arctan2(q[:, 1], q[:, 0]) - np.deg2rad(direction_deg))))
    )
    hot = (np.abs(off) < 20.0) & (q[:, 2] > z_range[0]) & (q[:, 2] < z_range[1])
    strain = np.zeros((2, len(pts), 3, 3))
    e_r = TEMPLATE.local_basis(pts)[0]
    strain[1, hot] = 0.1 * np.einsum("ni,nj->nij", e_r[hot], e_r[hot])  # E_rr = 0.1
    out = lv_measures(
        pts, strain, np.stack([pts, pts]), np.ones(len(pts)), TEMPLATE, time=[0.0, 10.0],
        anterior=anterior,
    )  # fmt: skip
    return out, hot


@pytest.mark.parametrize(
    ("where", "direction", "z_range", "segment", "angles"),
    [
        # the inferior wall is opposite the anterior one; the mid ring spans z -43 .. -17 mm
        ("mid inferior", 30.0 + 180.0, (-38.0, -22.0), 10, (240.0, 300.0)),
        # the septum lies 90° clockwise about the apex-to-base axis from anterior (seen
        # from the apex, anterior up: on the left); the apical ring spans z -70 .. -43 mm
        ("apical septal", 30.0 - 90.0, (-65.0, -48.0), 14, (135.0, 225.0)),
    ],
)
def test_a_one_segment_field_is_drawn_at_its_standard_place(
    where, direction, z_range, segment, angles
):
    out, hot = _field_in(direction, z_range, anterior=30.0)
    peak = out.peak_strain.sel(component="radial")
    assert float(peak.sel(segment=segment)) > 0.01  # the hot points all fell in the segment
    assert np.count_nonzero(peak) == 1
    fig = bullseye(out, component="radial")
    wedges = _wedges(fig)
    zero = wedges[f"aha-{17 if segment != 17 else 1}"].get_facecolor()
    coloured = [gid for gid, w in wedges.items() if w.get_facecolor() != zero]
    assert coloured == [f"aha-{segment}"], where
    drawn = wedges[f"aha-{segment}"]
    assert (drawn.theta1, drawn.theta2) == angles
    # the value, in %, is written in that wedge
    value = f"{100 * float(peak.sel(segment=segment)):.1f}"
    mid = np.deg2rad(np.mean(angles))
    texts = {t.get_text(): t.get_position() for t in fig.axes[0].texts}
    x, y = texts[value]
    assert np.isclose(np.arctan2(y, x) % (2 * np.pi), mid % (2 * np.pi), atol=0.15)


@pytest.fixture(scope="module")
def partial():
    """x/y tags only, and no tag data in segments 7 and 8 (anterior at +x)."""
    body = body_of(n=(32, 12, 2))
    centres = body.dof_points[body.cells[:, :8]].mean(axis=1)
    rank = np.where(np.isin(aha_segments(centres, TEMPLATE, anterior=0.0), [7, 8]), 0, 2)

    def motion(p):
        q = p - TEMPLATE.centre
        return np.column_stack([-0.1 * q[:, :2], -0.08 * (q[:, 2] - GEOMETRY.truncation)])

    ds = fe_dataset(motion, body, seen=(1.0, 1.0, 0.0), rank=rank)
    with pytest.warns(HarpxWarning):  # segments 7, 8 empty; longitudinal inferred
        return cardiac_strain(ds, TEMPLATE, anterior=0.0)


def test_the_bullseye_is_clinical(partial):
    fig = bullseye(partial, component="longitudinal")
    assert isinstance(fig, Figure)
    ax = fig.axes[0]
    texts = [t.get_text() for t in ax.texts]
    assert not any("nan" in t.lower() for t in texts)
    assert {str(k) for k in range(1, 18)} <= set(texts)  # every segment numbered
    for side in ("anterior", "septal", "inferior", "lateral"):
        assert side in texts
    # values in %: segment 1's peak Ell printed with one decimal
    peak = float(partial.peak_strain.sel(component="longitudinal", segment=1))
    assert f"{100 * peak:.1f}".replace("-", "\u2212") in texts
    wedges = _wedges(fig)
    # segments without data: blank (white), no value written
    for k in (7, 8):
        assert wedges[f"aha-{k}"].get_facecolor()[:3] == (1.0, 1.0, 1.0)
    # the model's longitudinal strain is hatched where the tags did not see it
    assert "aha-1-inferred" in wedges and "aha-10-inferred" in wedges
    assert "aha-7-inferred" not in wedges  # no data: nothing to hatch
    caption = " ".join(texts)
    assert "inferred by the model" in caption and "blank: no data" in caption
    assert "anterior 0°" in caption
    assert ax.get_title().startswith("peak longitudinal strain")
    assert fig.axes[1].get_ylabel() == "peak longitudinal strain (%)"
    # the circumferential strain was observed: no hatching
    observed = bullseye(partial, component="circumferential")
    assert not any(gid.endswith("-inferred") for gid in _wedges(observed))


def test_bullseye_of_one_frame_numbers_or_an_array(partial):
    fig = bullseye(partial, variable="segment_strain", time=100.0)
    assert "t = 100 ms" in fig.axes[0].get_title()
    with pytest.raises(ValueError, match="select one frame"):
        bullseye(partial, variable="segment_strain")
    with pytest.raises(ValueError, match="17 segment values"):
        bullseye(np.zeros(5))
    fig = bullseye(np.linspace(-0.2, 0.2, 17))  # plain numbers: segment 1 first, in %
    assert "-20.0".replace("-", "\u2212") in [t.get_text() for t in fig.axes[0].texts]
    # a derived DataArray (an error against a truth) draws in a given axes
    _, axes = plt.subplots(1, 2)
    error = np.abs(partial.peak_strain.sel(component="circumferential") - 0.01)
    assert bullseye(error, ax=axes[1], cmap="viridis", vmin=0) is axes[1].figure


def test_segment_curves_by_ring(partial):
    fig = segment_curves(partial, component="longitudinal")
    basal, mid, apical, apex = fig.axes[:4]
    assert [ax.get_title() for ax in (basal, apical, apex)] == ["basal", "apical", "apex"]
    assert mid.get_title() == "mid\nno data: 7, 8"
    # one curve per segment with data (plus the zero line), in %
    lines = [line for line in basal.get_lines() if line.get_label().startswith("1 ")]
    expected = 100 * partial.segment_strain.sel(component="longitudinal", segment=1).values
    assert np.allclose(lines[0].get_ydata(), expected)
    assert len(mid.get_lines()) == 4 + 1
    # inferred segments are dashed and say so
    assert lines[0].get_linestyle() == "--" and "(inferred)" in lines[0].get_label()
    solid = segment_curves(partial, component="circumferential").axes[0].get_lines()[0]
    assert solid.get_linestyle() == "-"
    assert "%" in basal.get_ylabel()


def test_under_reported_radial_strain_says_so_on_the_radial_plots(partial):
    flagged = partial.copy()
    flagged.attrs["radial_strain_caution"] = "the radial strain is likely under-reported"
    texts = [t.get_text() for t in bullseye(flagged, component="radial").axes[0].texts]
    assert any("under-reported" in t for t in texts)
    assert "under-reported" in segment_curves(flagged, component="radial").get_suptitle()
    # the other components, and a result without the flag, carry no such note
    texts = [t.get_text() for t in bullseye(flagged, component="circumferential").axes[0].texts]
    assert not any("under-reported" in t for t in texts)
    texts = [t.get_text() for t in bullseye(partial, component="radial").axes[0].texts]
    assert not any("under-reported" in t for t in texts)
    assert "under-reported" not in segment_curves(partial, component="radial").get_suptitle()
