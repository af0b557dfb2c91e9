"""LV-frame strain, AHA segments, twist and torsion against closed forms of analytic motions."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.anatomy.ventricle import VentricleGeometry
from harpx.anatomy.ventricle_fit import VentricleTemplate
from harpx.cardiac.strain import AHA_NAMES, aha_segments, cardiac_strain
from harpx.errors import HarpxWarning
from tests.cardiac._lv import GEOMETRY, TEMPLATE, WithAnterior, body_of, centroid_z, fe_dataset

# a harpx warning a test does not expect fails it (whatever module it is attributed to)
pytestmark = pytest.mark.filterwarnings("error::harpx.errors.HarpxWarning")

S = 0.1  # in-plane dilation
K = 0.2  # twist rate, degrees per mm along the long axis


def _dilation(p: np.ndarray) -> np.ndarray:
    u = np.zeros_like(p)
    u[:, :2] = S * (p[:, :2] - TEMPLATE.centre[:2])
    return u


def _twist(p: np.ndarray) -> np.ndarray:
    q = p - TEMPLATE.centre
    phi = np.deg2rad(K * q[:, 2])  # right-handed about the apex-to-base axis
    c, s = np.cos(phi), np.sin(phi)
    moved = np.stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1], q[:, 2]], axis=1)
    return moved - q


def test_in_plane_dilation_gives_the_exact_circumferential_strain():
    out = cardiac_strain(fe_dataset(_dilation), TEMPLATE, anterior=0.0)
    # a linear field is reproduced exactly by hex8 and e_c is horizontal, so every cell
    # has E_cc = ((1+s)^2 - 1)/2 and an engineering strain s (round-off only)
    ecc = out.strain_lv.sel(component="circumferential").isel(time=1)
    assert np.allclose(ecc, ((1 + S) ** 2 - 1) / 2, atol=1e-12)
    eng = out.peak_engineering_strain.sel(component="circumferential")
    assert np.allclose(eng, S, atol=1e-12)
    assert out.peak_time.sel(component="circumferential").values.tolist() == [100.0] * 17
    # radial motion does not rotate anything
    assert np.allclose(out.twist, 0.0, atol=1e-10)
    assert set(np.unique(out.aha_segment.values)) == set(range(1, 18))
    assert out.segment_strain.attrs["units"] == "1"
    # every direction seen by the tags: every component observed, nothing listed
    assert set(out.strain_source.values.ravel()) == {"observed"}
    assert out.attrs["strain_inferred"] == "" and out.attrs["segments_without_data"].size == 0


def _sphere(tilt_deg: float) -> VentricleTemplate:
    """A spherical-shell ventricle (radii 25 and 35 mm) whose long axis is tilted."""
    a = np.deg2rad(tilt_deg)
    rotation = np.array(
        [[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]]
    )
    geometry = VentricleGeometry(inner=(25.0, 25.0), outer=(35.0, 35.0), truncation=10.0)
    return VentricleTemplate(geometry, centre=(2.0, -1.0, 3.0), rotation=rotation)


SPHERE = _sphere(20.0)
ALPHA, R_MID = 1.2, 30.0  # radial map R -> ALPHA (R - R_MID) + R_MID: wall 10 -> 12 mm
KAPPA = 0.9  # meridian map: polar angle from the apex nu -> KAPPA nu


def _spherical(p: np.ndarray) -> tuple[np.ndarray, ...]:
    q = SPHERE.to_local(p)
    radius = np.linalg.norm(q, axis=1)
    nu = np.arctan2(np.hypot(q[:, 0], q[:, 1]), -q[:, 2])  # 0 at the apex
    return q, radius, nu, np.arctan2(q[:, 1], q[:, 0])


def _point(radius: np.ndarray, nu: np.ndarray, theta: np.ndarray) -> np.ndarray:
    s = np.sin(nu)
    q = radius[:, None] * np.stack([s * np.cos(theta), s * np.sin(theta), -np.cos(nu)], 1)
    return SPHERE.to_image(q)


def _thickening(p: np.ndarray) -> np.ndarray:
    _, radius, nu, theta = _spherical(p)
    return _point(ALPHA * (radius - R_MID) + R_MID, nu, theta) - p


def _shortening(p: np.ndarray) -> np.ndarray:
    _, radius, nu, theta = _spherical(p)
    return _point(radius, KAPPA * nu, theta) - p


def test_uniform_radial_thickening_gives_the_closed_form_radial_strain():
    # on a spherical shell e_r is the radius and e_l the meridian; R -> r = α (R - R_m) + R_m
    # stretches every radial fibre by α: E_rr = (α² - 1)/2 = 0.22 in every segment, while
    # the tangential fibres stretch by r/R: E_ll = E_cc = ((r/R)² - 1)/2 at radius R.
    # Tolerance: hex8 interpolation of the curved field errs by O((h/R)²): measured
    # 3e-4 (segment means) and 1.6e-3 (single cells) on this mesh, 4x that on one twice
    # as coarse
    ds = fe_dataset(_thickening, body_of(SPHERE, (32, 12, 3)))
    out = cardiac_strain(ds, SPHERE, anterior=0.0)
    err = out.segment_strain.isel(time=1).sel(component="radial")
    assert np.allclose(err, (ALPHA**2 - 1) / 2, atol=1e-3)
    centres = ds.points.values[ds.cells.values[:, :8]].mean(axis=1)
    radius = np.linalg.norm(SPHERE.to_local(centres), axis=1)
    tangential = ((ALPHA * (radius - R_MID) + R_MID) ** 2 / radius**2 - 1) / 2
    cells = out.strain_lv.isel(time=1)
    for component in ("longitudinal", "circumferential"):  # -0.025 .. +0.020 across the wall
        assert np.allclose(cells.sel(component=component), tangential, atol=3e-3)


def test_longitudinal_shortening_gives_the_closed_form_longitudinal_strain():
    # ν -> κν shortens every meridian by κ at constant radius: E_ll = (κ² - 1)/2 = -0.095
    # in every segment and E_rr = 0 (same tolerance as the thickening; measured 2.4e-4 and
    # 6.1e-4)
    out = cardiac_strain(
        fe_dataset(_shortening, body_of(SPHERE, (32, 12, 3))), SPHERE, anterior=0.0
    )
    seg = out.segment_strain.isel(time=1)
    assert np.allclose(seg.sel(component="longitudinal"), (KAPPA**2 - 1) / 2, atol=1e-3)
    assert np.allclose(seg.sel(component="radial"), 0.0, atol=1e-3)
    # engineering strain along the meridian: the stretch κ - 1
    eng = out.peak_engineering_strain.sel(component="longitudinal")
    assert np.allclose(eng, KAPPA - 1, atol=1e-3)


def test_linear_twist_gives_the_closed_form_rotations_and_twist():
    # rotation by K degrees per mm of the long-axis coordinate z (right-handed about the
    # apex-to-base axis), i.e. -K z in the cardiac convention. Level rotations are volume
    # means over the basal and apical rings, so they are -K times the rings' centroids,
    # known in closed form; twist = K (z_base - z_apex), torsion K.
    z_base = centroid_z(TEMPLATE, -70.0 + 160.0 / 3.0, 10.0)
    z_apex = centroid_z(TEMPLATE, -70.0, -70.0 + 80.0 / 3.0)
    out = cardiac_strain(fe_dataset(_twist, body_of(n=(32, 12, 3))), TEMPLATE, anterior=0.0)
    base, apex = (float(out.rotation.sel(level=k)[1]) for k in ("base", "apex"))
    # Tolerances: cells join a ring by their centre, which moves the mesh ring's centroid
    # by a fraction of a mm (0.1° at K), and a cell centre's angle is the radius-weighted
    # mean of its nodes' (about 1 % of the rotation on the sloped apical wall); measured
    # 0.016°, 0.087° and 0.071°
    assert base == pytest.approx(-K * z_base, abs=0.1)  # 0.66°
    assert apex == pytest.approx(-K * z_apex, abs=0.2)  # 11.06°: apex turns positive
    assert float(out.twist[1]) == pytest.approx(K * (z_base - z_apex), abs=0.2)  # 10.4°
    assert out.torsion.attrs["level_distance_mm"] == pytest.approx(z_base - z_apex, rel=0.01)
    assert float(out.torsion[1]) == pytest.approx(K, rel=0.01)


def test_grid_displacement_gives_the_same_segment_strain():
    step = 2.0  # mm voxels, coarse grid so the test is fast
    x = np.arange(-40.0, 44.0, step)
    z = np.arange(-80.0, 14.0, step)
    Z, Y, X = np.meshgrid(z, x, x, indexing="ij")
    pts = np.stack([X, Y, Z], -1).reshape(-1, 3)
    inside = GEOMETRY.inside(TEMPLATE.to_local(pts)).reshape(Z.shape)
    u = _dilation(pts).reshape(*Z.shape, 3).transpose(3, 0, 1, 2)
    u = np.where(inside[None] > 0, u, np.nan)
    disp = np.stack([np.zeros_like(u), u])
    ds = xr.Dataset(
        {"displacement_true": (("time", "axis", "z", "y", "x"), disp),
         "body": (("z", "y", "x"), inside)},
        coords={"time": [0.0, 50.0], "axis": ["x", "y", "z"], "z": z, "y": x, "x": x},
    )  # fmt: skip
    out = cardiac_strain(ds, TEMPLATE, anterior=0.0)
    # central differences are exact for a linear field: every segment E_cc as on the mesh
    peak = out.peak_strain.sel(component="circumferential")
    assert np.allclose(peak, ((1 + S) ** 2 - 1) / 2, atol=1e-12)
    assert set(np.unique(out.aha_segment_grid.values)) == set(range(18))
    # a prescribed displacement is known in every direction
    assert set(out.strain_source.values.ravel()) == {"observed"}


def test_segments_follow_the_anterior_angle_and_the_thirds():
    # the cavity runs from z = -70 (endocardial apex) to 10 (base): thirds of 80/3 mm
    r = 30.0
    pts = TEMPLATE.to_image([[r, 0.1, 0.0], [r, 0.1, -30.0], [r, 0.1, -60.0], [0, 0, -74.0]])
    # without an anterior angle (argument or template) the +x axis is taken, with a warning
    with pytest.warns(HarpxWarning, match="the anterior direction is unknown"):
        assert aha_segments(pts, TEMPLATE).tolist() == [1, 7, 13, 17]  # centred on anterior
    # numbers run counter-clockwise seen from the apex, i.e. clockwise about +z: with the
    # anterior wall 35° counter-clockwise (about +z) of these points, they lie 35° on the
    # septal side: anteroseptal in the 60° rings, still anterior in the 90° apical ring
    assert aha_segments(pts, TEMPLATE, anterior=35.0).tolist() == [2, 8, 13, 17]
    assert aha_segments(pts, TEMPLATE, anterior=-35.0).tolist() == [6, 12, 13, 17]


def test_the_septum_is_on_the_patients_right_in_scanner_coordinates():
    # DICOM patient coordinates (LPS: x left, y posterior, z head) are right-handed. The long
    # axis points from the apex (left, anterior, inferior) to the base: L ~ (-1, 1, 1). The
    # right ventricle, hence the septum, lies on the patient's right of the LV, the lateral
    # wall on the left. Anterior: the patient's anterior (-y) projected on the short axis.
    axis = np.array([-1.0, 1.0, 1.0]) / np.sqrt(3.0)
    front = np.array([0.0, -1.0, 0.0]) - (-axis[1]) * axis
    front /= np.linalg.norm(front)
    rotation = np.column_stack([front, np.cross(axis, front), axis])
    template = VentricleTemplate(GEOMETRY, centre=(10.0, 20.0, -30.0), rotation=rotation)

    def wall_point(direction: np.ndarray, z: float) -> np.ndarray:
        d = direction - (direction @ axis) * axis
        d = d / np.linalg.norm(d)
        return template.centre + 27.0 * d + z * axis  # mid-wall of the ring at height z

    left, right = np.array([1.0, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    pts = [wall_point(right, -30.0), wall_point(right, 0.0), wall_point(left, -30.0)]
    names = [AHA_NAMES[k - 1] for k in aha_segments(pts, template, anterior=0.0)]
    assert "septal" in names[0] and "septal" in names[1], names
    assert "lateral" in names[2], names


def test_anterior_comes_from_the_template_or_is_flagged_unknown():
    ds = fe_dataset(_dilation)
    given = cardiac_strain(ds, TEMPLATE, anterior=30.0)
    fitted = cardiac_strain(ds, WithAnterior(TEMPLATE, 30.0))
    assert fitted.attrs["anterior_deg"] == 30.0 and fitted.attrs["anterior_source"] == "template"
    assert np.array_equal(fitted.aha_segment, given.aha_segment)
    # an explicit argument wins over the template's angle
    assert (
        cardiac_strain(ds, WithAnterior(TEMPLATE, 30.0), anterior=0.0).attrs["anterior_deg"] == 0.0
    )
    with pytest.warns(HarpxWarning, match="anterior direction is unknown"):
        unknown = cardiac_strain(ds, TEMPLATE)
    assert unknown.attrs["anterior_source"].startswith("unknown")


def test_dataset_without_displacement_is_named():
    with pytest.raises(ValueError, match="needs a finite-element tracked/1 dataset"):
        cardiac_strain(xr.Dataset({"a": ("x", [1.0])}), TEMPLATE, anterior=0.0)


def test_segment_coordinates_survive_on_the_result():
    out = cardiac_strain(fe_dataset(_dilation), TEMPLATE, anterior=0.0)
    assert str(out.segment_name.sel(segment=17).values) == "apex"
    assert out.component.values.tolist() == ["radial", "circumferential", "longitudinal"]
    # the source travels with a selected variable (for the plots)
    assert out.peak_strain.sel(component="radial").strain_source.dims == ("segment",)


def test_peaks_taken_at_a_frame_that_missed_its_target_are_named():
    # the tracker marks a frame whose fit missed its target ('target_reached' False):
    # every segment's peak of this two-frame dilation is taken there, so each is marked and
    # the warning says so; a result whose frames all reached theirs carries no mark
    tracked = fe_dataset(_dilation)
    ok = tracked.assign(target_reached=("time", [True, True]), converged=("time", [True, True]))
    good = cardiac_strain(ok, TEMPLATE, anterior=0.0)
    assert good.attrs["frames_missing_target"].size == 0
    assert "peak_at_missed_frame" not in good
    missed = tracked.assign(target_reached=("time", [True, False]),
                            converged=("time", [True, True]))  # fmt: skip
    with pytest.warns(HarpxWarning, match=r"at t = 100 ms .*: 51 of 51 segment peaks"):
        out = cardiac_strain(missed, TEMPLATE, anterior=0.0)
    assert out.attrs["frames_missing_target"].tolist() == [100.0]
    assert bool(out.peak_at_missed_frame.all())
    np.testing.assert_allclose(out.peak_strain, good.peak_strain)  # flagged, not changed
