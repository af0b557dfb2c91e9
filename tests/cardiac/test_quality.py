"""What a cardiac strain result may claim: refused inputs, coverage, observed components."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.anatomy.ventricle import VentricleGeometry
from harpx.anatomy.ventricle_fit import VentricleTemplate
from harpx.cardiac.quality import VentricleShapeError, seen_fraction, template_segment_volume
from harpx.cardiac.strain import aha_segments, cardiac_strain, lv_measures
from harpx.errors import HarpxWarning, SchemaError
from harpx.mechanics.body import Body
from harpx.mechanics.materials import NeoHookean
from harpx.mechanics.mesh import cylinder
from tests.cardiac._lv import GEOMETRY, TEMPLATE, body_of, fe_dataset, wall_samples

pytestmark = pytest.mark.filterwarnings("error::harpx.errors.HarpxWarning")


def _shrink(p: np.ndarray) -> np.ndarray:
    """Systole-like motion: 10 % in-plane contraction and 8 % shortening about the base."""
    q = p - TEMPLATE.centre
    u = np.zeros_like(p)
    u[:, :2] = -0.1 * q[:, :2]
    u[:, 2] = -0.08 * (q[:, 2] - GEOMETRY.truncation)
    return u


def _scaled(factor: float) -> VentricleTemplate:
    g = VentricleGeometry(
        inner=tuple(factor * v for v in GEOMETRY.inner),
        outer=tuple(factor * v for v in GEOMETRY.outer),
        truncation=factor * GEOMETRY.truncation,
    )
    return VentricleTemplate(g, centre=factor * TEMPLATE.centre)


def test_a_cylinder_in_the_cavity_is_not_a_left_ventricle():
    # a solid cylinder (radius 20 mm) filling the cavity of the template (radius 25 mm)
    spec = cylinder(
        20.0, 40.0, n_radial=1, n_circumferential=8, n_axial=2, center=(2.0, -1.0, -30.0)
    )
    body = Body(spec, NeoHookean(c1=1.0, kappa=10.0))
    with pytest.raises(VentricleShapeError, match=r"only 0 % .* lies in the wall.*in the cavity"):
        cardiac_strain(fe_dataset(_shrink, body), TEMPLATE, anterior=0.0)


@pytest.mark.parametrize(
    ("factor", "hint"),
    [(1e-3, "metres\\? multiply every coordinate by 1000"), (1e3, "µm\\? divide")],
    ids=["metres", "micrometres"],
)
def test_a_ventricle_in_metres_or_micrometres_is_refused_with_the_conversion(factor, hint):
    template = _scaled(factor)
    ds = fe_dataset(lambda p: 0.0 * p, body_of(template))
    with pytest.raises(SchemaError, match=hint):
        cardiac_strain(ds, template, anterior=0.0)


def test_a_body_in_metres_against_a_template_in_mm_names_the_units():
    ds = fe_dataset(lambda p: 0.0 * p, body_of(_scaled(1e-3)))
    with pytest.raises(VentricleShapeError, match="metres or µm rather than mm"):
        cardiac_strain(ds, TEMPLATE, anterior=0.0)


def test_a_small_animal_heart_passes_with_its_own_size_bounds():
    template = _scaled(0.1)  # 7 mm across: refused as a human heart, fine for a mouse
    ds = fe_dataset(_shrink, body_of(template))
    with pytest.raises(SchemaError, match="heart_size"):
        cardiac_strain(ds, template, anterior=0.0)
    out = cardiac_strain(ds, template, anterior=0.0, heart_size=(4.0, 20.0))
    assert np.isfinite(out.peak_strain).all()


def test_template_segment_volumes_add_up_to_the_wall():
    volume = template_segment_volume(TEMPLATE)
    # GEOMETRY.wall_volume is an independent closed form (difference of truncated ellipsoids)
    assert volume.sum() == pytest.approx(GEOMETRY.wall_volume(), rel=1e-12)
    assert np.ptp(volume[:6]) == 0 and np.ptp(volume[6:12]) == 0 and np.ptp(volume[12:16]) == 0


def _ring(z1: float, z2: float) -> float:
    """Wall volume between the planes z1 < z2 (above the endocardial apex), closed form."""
    (ai, ci), (ao, co) = GEOMETRY.inner, GEOMETRY.outer
    return float(
        np.pi * (ao**2 - ai**2) * (z2 - z1)
        - np.pi * (ao**2 / co**2 - ai**2 / ci**2) * (z2**3 - z1**3) / 3.0
    )


def test_coverage_of_a_slab_of_slices_and_segments_without_data():
    # four 3.75 mm slices from z = -35 to -20 (template coordinates): inside the mid ring
    # (-43.3 .. -16.7 mm), so only segments 7-12 have data, each covered by the fraction
    # V(-35, -20) / V(mid ring) of its volume; the others are NaN and named
    pts = wall_samples(step=1.0)
    z = TEMPLATE.to_local(pts)[:, 2]
    slab = (z >= -35.0) & (z < -20.0)
    strain = np.zeros((2, len(pts), 3, 3))
    strain[1, :, 0, 0] = 0.05
    # neither the basal nor the apical level has data: twist and torsion are NaN, and named
    with (
        pytest.warns(HarpxWarning, match=r"no image data in AHA segment\(s\) 1-6, 13-17"),
        pytest.warns(HarpxWarning, match=r"twist and torsion are NaN: .* base .* apex "),
    ):
        out = lv_measures(
            pts, strain, np.stack([pts, pts]), np.ones(len(pts)), TEMPLATE, time=[0.0, 10.0],
            anterior=0.0, has_data=slab,
        )  # fmt: skip
    expected = _ring(-35.0, -20.0) / _ring(-70.0 + 80.0 / 3.0, -70.0 + 160.0 / 3.0)
    # 1 mm point sampling of the curved wall: the ring's volume within 0.5 % of itself
    # (measured 0.05 %), a 60° sector's, cut along oblique lines, within 2 % (measured 1.1 %)
    coverage = out.segment_coverage.sel(segment=range(7, 13))
    assert float(coverage.mean()) == pytest.approx(expected, rel=0.005)
    assert np.allclose(coverage, expected, atol=0.02)
    assert out.segment_coverage.sel(segment=[*range(1, 7), *range(13, 18)]).max() == 0.0
    assert out.attrs["segments_without_data"].tolist() == [1, 2, 3, 4, 5, 6, 13, 14, 15, 16, 17]
    peak = out.peak_strain.sel(component="radial")
    assert np.isnan(peak.sel(segment=[1, 6, 13, 17])).all()
    assert np.isfinite(peak.sel(segment=range(7, 13))).all()
    assert (out.strain_source.sel(segment=4) == "no data").all()
    assert np.isnan(out.peak_time.sel(segment=4)).all()


def test_cells_without_tag_data_leave_their_segments_empty():
    # a short-axis stack that misses part of the mid ring: cells of segments 7, 8, 10, 11
    # have no tag data (observed_directions 0); their values are NaN, not the model's
    body = body_of(n=(32, 12, 2))
    centres = body.dof_points[body.cells[:, :8]].mean(axis=1)
    segment = aha_segments(centres, TEMPLATE, anterior=0.0)
    rank = np.where(np.isin(segment, [7, 8, 10, 11]), 0, 3)
    full = cardiac_strain(fe_dataset(_shrink, body), TEMPLATE, anterior=0.0)
    # the segment means integrate over each cell's Gauss points: the cells of the
    # neighbouring segments that reach across the border cover 3-4 % of each empty segment
    # (32 cells around the ring, 6 segments: a border every 5.3 cells), below min_coverage
    with pytest.warns(HarpxWarning, match=r"segment\(s\) 7-8, 10-11: 7 mid anterior \(0\.03\)"):
        out = cardiac_strain(fe_dataset(_shrink, body, rank=rank), TEMPLATE, anterior=0.0)
    empty = [7, 8, 10, 11]
    assert out.attrs["segments_without_data"].tolist() == empty
    assert np.isnan(out.segment_strain.sel(segment=empty)).all()
    assert (out.segment_coverage.sel(segment=empty) < 0.05).all()
    others = [k for k in range(1, 18) if k not in empty]
    # the other segments lose only the Gauss points of the empty cells that reach into
    # them; the shrink's strain in the local frame hardly varies across a segment (largest
    # change measured 2.6e-6 of peak strains ~0.08)
    np.testing.assert_allclose(
        out.peak_strain.sel(segment=others), full.peak_strain.sel(segment=others), atol=1e-5
    )


def test_in_plane_tags_leave_longitudinal_strain_and_twist_inferred():
    # x/y tags only (short-axis slices): every cell sees x and y fully, z not at all. Then
    # the seen fraction of a direction e is e_x² + e_y²: exactly 1 for e_c (horizontal) and
    # s(e_r) + s(e_l) = 1 (both lie in the meridian plane, which holds z). In the basal and
    # mid rings (z >= -43.3 mm) the meridians are within 17° of z: s(e_l) < sin²(17°) = 0.08
    with pytest.warns(HarpxWarning) as record:
        out = cardiac_strain(fe_dataset(_shrink, seen=(1.0, 1.0, 0.0)), TEMPLATE, anterior=0.0)
    seen = out.strain_observed_fraction
    assert np.allclose(seen.sel(component="circumferential"), 1.0, atol=1e-12)
    total = seen.sel(component="radial") + seen.sel(component="longitudinal")
    assert np.allclose(total, 1.0, atol=1e-12)
    rings = list(range(1, 13))
    assert float(seen.sel(component="longitudinal", segment=rings).max()) < 0.08
    source = out.strain_source.sel(segment=rings)
    assert (source.sel(component="longitudinal") == "inferred").all()
    assert (source.sel(component=["radial", "circumferential"]) == "observed").all()
    for name in ("rotation", "twist", "torsion"):
        assert out[name].attrs["source"] == "inferred"
    message = str(record[0].message)
    assert "longitudinal strain inferred in segment(s) 1-" in message
    assert "rotation, twist and torsion inferred" in message
    assert "longitudinal strain inferred" in out.attrs["strain_inferred"]


def test_a_dataset_that_does_not_record_what_the_tags_saw_says_so():
    with pytest.warns(HarpxWarning, match="does not record which directions its tags observed"):
        out = cardiac_strain(fe_dataset(_shrink, seen=None), TEMPLATE, anterior=0.0)
    assert set(out.strain_source.values.ravel()) == {"not recorded"}
    assert out.twist.attrs["source"] == "not recorded"


@pytest.mark.parametrize(
    ("attrs", "names"),
    [
        # the settings that remove the blur across the wall: nothing to say
        (
            {
                "sequence": "CSPAMM",
                "phase_radius": 0.8,
                "phase_upsample": 2,
                "blur_passes_applied": 3,
            },
            [],
        ),
        # a displacement that does not record its phase extraction (a synthetic truth)
        ({"sequence": "CSPAMM", "blur_passes_applied": 0}, []),
        # the library's defaults on CSPAMM images: both settings named, with their fix
        (
            {"sequence": "CSPAMM", "phase_radius": 0.5, "blur_passes_applied": 1},
            ["band-pass radius 0.5 < 0.8", "radius=0.8", "1 blur-correction pass(es) < 3"],
        ),
        # SPAMM cannot widen its band-pass: the DC peak is named instead of radius=0.8
        (
            {"sequence": "SPAMM", "phase_radius": 0.5, "blur_passes_applied": 3},
            ["band-pass radius 0.5 < 0.8", "DC peak"],
        ),
        # the phase not upsampled: the correction samples a wall a few voxels thick
        (
            {
                "sequence": "CSPAMM",
                "phase_radius": 0.8,
                "phase_upsample": 1,
                "blur_passes_applied": 3,
            },
            ["phase upsampling 1 < 2", "upsample=2"],
        ),
        # conventional HARP never corrects the blur, whatever its radius
        ({"method": "harp", "sequence": "CSPAMM", "phase_radius": 0.8}, ["conventional HARP"]),
    ],
)
def test_radial_strain_caution_names_the_settings_that_under_report_thickening(attrs, names):
    from harpx.cardiac.quality import radial_strain_caution

    caution = radial_strain_caution(attrs)
    assert bool(caution) == bool(names), caution
    for name in names:
        assert name in caution, caution
    if attrs.get("sequence") == "SPAMM":
        assert "radius=0.8" not in caution


def test_a_default_target_at_a_low_epsilon_min_is_named():
    # noise-free images (floor 0): the default target falls to epsilon_min. On the small LV
    # infarct scene without noise (radius 0.8, 3 passes) the radial error was 31.1 % at
    # epsilon_min = 0.02 against 6.4 % at 0.03 (and at SNR 20, where the floor sets 0.05)
    from harpx.cardiac.quality import radial_strain_caution

    attrs = {"sequence": "CSPAMM", "phase_radius": 0.8, "blur_passes_applied": 3,
             "setting_epsilon": "auto", "setting_epsilon_min": 0.02}  # fmt: skip
    caution = radial_strain_caution(attrs, [0.0, 0.02, 0.045, 0.02])
    assert "epsilon_min=0.02 rad in frame(s) [1, 3]" in caution and "epsilon_min=0.03" in caution
    # the noise set every target, the user set epsilon_min or epsilon: nothing to name
    assert radial_strain_caution(attrs, [0.0, 0.045, 0.05]) == ""
    assert radial_strain_caution({**attrs, "setting_epsilon_min": 0.03}, [0.0, 0.03]) == ""
    assert radial_strain_caution({**attrs, "setting_epsilon": 0.02}, [0.0, 0.02]) == ""
    assert radial_strain_caution(attrs) == ""


def test_cardiac_strain_warns_and_flags_under_reported_thickening():
    ds = fe_dataset(_shrink)
    ds.attrs.update(sequence="CSPAMM", phase_radius=0.5, blur_passes_applied=1)
    with pytest.warns(HarpxWarning, match=r"radial strain \(wall thickening\) is likely under"):
        out = cardiac_strain(ds, TEMPLATE, anterior=0.0)
    assert "1 blur-correction pass(es) < 3" in out.attrs["radial_strain_caution"]
    ds.attrs.update(phase_radius=0.8, blur_passes_applied=3)
    out = cardiac_strain(ds, TEMPLATE, anterior=0.0)  # no warning (they are errors here)
    assert out.attrs["radial_strain_caution"] == ""


def test_segment_means_integrate_over_the_gauss_points_of_trilinear_cells(rng):
    # independent truths: an affine motion has F = I + A at every point; for any motion the
    # Gauss points' volumes add up to skfem's cell volumes and their volume-weighted strain
    # is the cell mean harpx's Body integrates with its own 2 × 2 × 2 rule
    from harpx.cardiac.wall_points import _hex8_gauss_points

    body = body_of()
    points = body.dof_points
    cells = np.asarray(body.cells, dtype=np.int64)
    A = 0.05 * rng.standard_normal((3, 3))
    affine = (points @ A.T)[None]
    X, E, current, weights = _hex8_gauss_points(points, cells, affine)
    F = np.eye(3) + A
    np.testing.assert_allclose(E[0], np.broadcast_to(0.5 * (F.T @ F - np.eye(3)), E[0].shape),
                               atol=1e-13)  # fmt: skip
    np.testing.assert_allclose(current[0], X + X @ A.T, atol=1e-12)
    np.testing.assert_allclose(weights.reshape(-1, 8).sum(axis=1), body.cell_volume, rtol=1e-12)
    bent = points + 0.002 * np.stack([points[:, 1] ** 2, points[:, 2] * points[:, 0],
                                      np.zeros(len(points))], axis=1)  # fmt: skip
    _, E, _, weights = _hex8_gauss_points(points, cells, (bent - points)[None])
    w = weights.reshape(-1, 8, 1, 1)
    mean = (w * E[0].reshape(-1, 8, 3, 3)).sum(axis=1) / w.sum(axis=1)
    np.testing.assert_allclose(mean, body.green_strain((bent - points).ravel()), atol=1e-12)


@pytest.mark.parametrize(
    ("element", "tetrahedra", "bound"),
    [("hex20", False, 2e-5), ("tet4", True, 2e-4), ("tet10", True, 2e-4)],
)
def test_other_elements_take_one_point_per_cell_and_agree_with_trilinear_gauss_points(
    element, tetrahedra, bound
):
    # hex20 and tetrahedral cells are not split into Gauss points: each counts at the centre
    # of its corner vertices with its mean strain and its volume. The same smooth motion on
    # the same mesh (its hexahedra split into tetrahedra) then gives the segment peaks of
    # the hex8 result's Gauss points, to the difference of the discretisations (measured
    # 7.8e-6 for hex20; 1.3e-4 for the tetrahedra, several to a hexahedron, which
    # fall on either side of a border by their own centres). Tetrahedra raised before.
    from harpx.mechanics.mesh import tetrahedralize

    spec = TEMPLATE.mesh(n_circumferential=24, n_longitudinal=6, n_transmural=2)
    peaks = {}
    for name, mesh in (("hex8", spec), (element, tetrahedralize(spec) if tetrahedra else spec)):
        body = Body(mesh, NeoHookean(c1=1.0, kappa=10.0), element=name)
        ds = fe_dataset(_shrink, body)
        assert ds["cells"].attrs["element"] == name
        peaks[name] = cardiac_strain(ds, TEMPLATE, anterior=0.0).peak_strain
    difference = np.abs(peaks[element] - peaks["hex8"]).sel(segment=range(1, 17))
    assert float(difference.max()) < bound


def test_thickening_seen_across_the_wall_alone_is_not_observed():
    # the through-plane tag alone (long-axis slices): at the apical cap (17) it runs across
    # the wall, so the radial direction is seen, but neither in-wall direction is (e_c is
    # horizontal, e_l nearly so at the cap); the thickening there rests on the model
    body = body_of()
    with pytest.warns(HarpxWarning, match=r"radial strain (partly )?inferred in segment\(s\) "):
        out = cardiac_strain(fe_dataset(_shrink, body, seen=(0.0, 0.0, 1.0)), TEMPLATE,
                             anterior=0.0)  # fmt: skip
    lv = out.strain_lv_observed
    cap = (out.aha_segment == 17).values
    assert cap.any()
    centres = body.dof_points[body.cells[:, :8]].mean(axis=1)
    basis = TEMPLATE.local_basis(centres[cap])
    direction = seen_fraction(basis, np.tile([0.0, 0.0, 1.0], (int(cap.sum()), 1)))
    # the radial direction itself is mostly seen (e_r within 45° of z in every cap cell of
    # this coarse mesh; 0.53-0.84 of it) ...
    assert direction[:, 0].min() > 0.5
    assert direction[:, 0].mean() > 0.6
    # ... but its in-wall partners are not (s_r + s_l = 1 in the meridian plane), so the
    # component counts as observed no further than they are: below one half, inferred
    assert lv.values[cap, 0].max() <= 0.5
    assert out.strain_source.sel(segment=17, component="radial") == "inferred"
    assert float(out.strain_observed_fraction.sel(segment=17, component="radial")) < 0.5
