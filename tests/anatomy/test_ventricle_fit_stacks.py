"""The template fitted to the stacks scans give: short-axis only, with long-axis slices, 3-D.

The masks are the truncated spheroid of ``_lv_masks`` (endocardial apex z = -70 mm, base
plane z = 10 mm, in-plane centre (2, -3) mm) sampled on 1.5 mm voxels, so every fitted
number has a known truth.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from harpx.anatomy.mask_fit import _aha
from harpx.anatomy.segmentation import mesh_from_labels
from harpx.anatomy.ventricle_fit import (
    VentricleFitWarning,
    VentricleTemplate,
    fit_ventricle_to_mask,
)
from harpx.cardiac.strain import aha_segments
from tests.anatomy._lv_masks import (
    CENTRE,
    GEOMETRY,
    TRUTH,
    long_axis_slice,
    short_axis_stack,
    volume,
    with_rv,
)

MID = list(range(7, 13))


def _endo_apex(template: VentricleTemplate) -> float:
    return float(template.to_image([[0.0, 0.0, -template.geometry.inner[1]]])[0, 2])


def test_mid_ventricular_stack_gives_the_slice_normal_and_mid_segments():
    # the user's case: four mid slices, apex and base out of view; base side and level given
    with pytest.warns(VentricleFitWarning) as record:
        fit = fit_ventricle_to_mask(short_axis_stack(), base_side="high", base_level=10.0)
    t = fit.template
    # the axis is the slice normal (it was 90 degrees off before: [1, 0, 0] in-plane)
    assert t.axis @ [0.0, 0.0, 1.0] == pytest.approx(1.0, abs=1e-12)
    # in-plane centre: the rings' 0.5 contours are symmetric about it, measured 0.026 mm off
    assert np.allclose(t.centre[:2], CENTRE[:2], atol=0.032)
    # radii: measured 0.44 and 0.45 mm too large, under a third of a voxel (the ellipsoid is
    # stretched along the axis, c_endo 78 for 70, since four slices barely bend)
    assert t.geometry.inner[0] == pytest.approx(25.0, abs=0.55)
    assert t.geometry.outer[0] == pytest.approx(35.0, abs=0.55)
    # binary contours: about a voxel / sqrt(12) = 0.43 mm expected, measured 0.35 mm
    assert fit.rms < 0.42
    # the base plane is where the user put it
    assert float(t.to_image([[0.0, 0.0, t.geometry.truncation]])[0, 2]) == pytest.approx(10.0)
    # the apex is extrapolated, flagged, and the truth lies within the stated uncertainty
    # (measured -72.3 +- 2.4 mm for -70)
    assert "apex_extrapolated" in fit.flags and fit.apex_uncertainty is not None
    assert abs(_endo_apex(t) + 70.0) <= fit.apex_uncertainty
    # every slice lies in the mid third: only segments 7-12 hold voxels, about a sixth each
    # (measured within 1.4 % of the mean)
    counts = fit.segment_voxels
    assert counts is not None
    assert np.nonzero(counts)[0].tolist() == [k - 1 for k in MID]
    mid = counts[6:12]
    assert mid.min() > 0.983 * mid.mean() and mid.max() < 1.017 * mid.mean()
    # basal, apical and apex levels are reported out of view, not invented
    assert fit.out_of_view == (1, 2, 3, 4, 5, 6, 13, 14, 15, 16, 17)
    # the base plane is 24 mm above the stack: a mesh of the mask has no base facets
    assert "base_out_of_view" in fit.flags
    assert sorted(str(w.message)[:20] for w in record) == sorted(
        fit.flags[k][:20] for k in ("apex_extrapolated", "base_out_of_view")
    )


def test_apex_level_from_the_user_replaces_the_extrapolation():
    # the stack upside down (z -> -z): the base lies towards low z
    stack = short_axis_stack()
    flipped = stack.assign_coords(z=-stack.z.values).sortby("z")
    with pytest.warns(VentricleFitWarning) as record:
        fit = fit_ventricle_to_mask(flipped, base_side="low", base_level=-10.0, apex_level=70.0)
    assert fit.template.axis @ [0.0, 0.0, -1.0] == pytest.approx(1.0, abs=1e-12)
    # the apex and the base sit where they were put (up to round-off)
    assert _endo_apex(fit.template) == pytest.approx(70.0, abs=1e-9)
    t = fit.template
    assert float(t.to_image([[0.0, 0.0, t.geometry.truncation]])[0, 2]) == pytest.approx(-10.0)
    assert "apex_extrapolated" not in fit.flags and fit.apex_uncertainty is None
    assert [w.message.args[0] for w in record] == [fit.flags["base_out_of_view"]]
    assert np.nonzero(fit.segment_voxels)[0].tolist() == [k - 1 for k in MID]


def test_rv_label_sets_the_anterior_wall():
    # septum (the RV contact) from 150 to 270 degrees about +z; the anterior insertion is
    # its end at 270 (from it, the negative sense about the apex-to-base axis, i.e.
    # counter-clockwise seen from the apex, crosses the septum) and the anterior wall lies
    # 90 degrees from the septum's middle towards the lateral wall: 300 degrees
    mask = with_rv(short_axis_stack(), 150.0, 270.0)
    with pytest.warns(VentricleFitWarning):
        fit = fit_ventricle_to_mask(mask, myocardium=1, rv=2, base_side="high", base_level=10.0)
    t = fit.template
    assert fit.insertions is not None
    # the contact band is the myocardium within 2 voxels of the RV: it reaches past the
    # insertions by at most 2 voxels / 35 mm = 4.9 degrees (measured 1.92 and 2.45), at both
    # ends, so its middle stays put (measured 299.74)
    assert fit.insertions[0] == pytest.approx(270.0, abs=2.3)
    assert fit.insertions[1] == pytest.approx(150.0, abs=2.9)
    assert t.anterior == pytest.approx(300.0, abs=0.32)
    assert "anterior_unknown" not in fit.flags
    # mid-wall points at the anterior wall and 60 degrees either side, in a mid slice:
    # mid anterior, mid anteroseptal (towards the RV), mid anterolateral
    angles = np.deg2rad(t.anterior + np.array([0.0, -60.0, 60.0]))
    local = np.column_stack([30.0 * np.cos(angles), 30.0 * np.sin(angles), np.full(3, -30.0)])
    points = TRUTH.to_image(local)
    assert aha_segments(points, t, anterior=t.anterior).tolist() == [7, 8, 12]
    assert _aha(t, points).tolist() == [7, 8, 12]
    # the wrap-around: a septum from 300 to 60 degrees gives the anterior wall at 90; the
    # masks are mirror-symmetric about the septum's middle (y = -3 mm is a grid line), so
    # it is exact to round-off (measured 6e-11 degrees off)
    mask = with_rv(short_axis_stack(), 300.0, 420.0)
    with pytest.warns(VentricleFitWarning):
        fit = fit_ventricle_to_mask(mask, myocardium=1, rv=2, base_side="high", base_level=10.0)
    assert fit.template.anterior == pytest.approx(90.0, abs=1e-9)


def test_anterior_from_the_user_as_angle_or_point():
    stack = short_axis_stack()
    with pytest.warns(VentricleFitWarning):
        by_angle = fit_ventricle_to_mask(stack, base_side="high", base_level=10.0, anterior=400.0)
    assert by_angle.template.anterior == pytest.approx(40.0, abs=1e-12)  # modulo 360
    point = TRUTH.to_image([[0.0, 30.0, -30.0]])[0]  # 90 degrees about +z from the centre
    with pytest.warns(VentricleFitWarning):
        by_point = fit_ventricle_to_mask(stack, base_side="high", base_level=10.0, anterior=point)
    # the fitted centre is 0.026 mm off the truth: 0.05 degree at 30 mm (measured 0.050)
    assert by_point.template.anterior == pytest.approx(90.0, abs=0.06)


def test_segment_convention_matches_cardiac_strain(rng):
    # the occupancy count uses its own copy of the AHA rule (anatomy cannot import cardiac)
    template = VentricleTemplate(GEOMETRY, centre=CENTRE, anterior=75.0)
    points = TRUTH.to_image(
        np.column_stack([rng.uniform(-35, 35, 2000), rng.uniform(-35, 35, 2000),
                         rng.uniform(-80, 10, 2000)])
    )  # fmt: skip
    np.testing.assert_array_equal(
        _aha(template, points), aha_segments(points, template, anterior=75.0)
    )


def test_long_axis_slices_give_the_apex_the_base_and_the_sense():
    # no base_side, base_level or apex_level: the long-axis slices show them
    lax = [long_axis_slice("y"), long_axis_slice("x")]
    with pytest.warns(VentricleFitWarning, match="base plane lies"):
        fit = fit_ventricle_to_mask(short_axis_stack(), long_axis_slices=lax)
    t = fit.template
    # measured: axis 0.082 degrees off, apex -70.024, c_endo 69.985, base 9.748 (the mask's
    # top voxels lie below z = 10 by up to a voxel), rms 0.36 mm; bounds at 1.2 × the error
    assert np.degrees(np.arccos(t.axis @ [0.0, 0.0, 1.0])) < 0.1
    assert _endo_apex(t) == pytest.approx(-70.0, abs=0.03)
    base = float(t.to_image([[0.0, 0.0, t.geometry.truncation]])[0, 2])
    assert 10.0 - 0.3 < base < 10.0
    assert t.geometry.inner[1] == pytest.approx(70.0, abs=0.02)
    assert "apex_extrapolated" not in fit.flags
    assert fit.rms < 0.43


def test_volume_with_a_tilted_axis_is_fitted_in_3d():
    # a 3-D segmentation that shows the apex: the axis is fitted, here 25 degrees off z
    b = np.deg2rad(25.0)
    rotation = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    truth = VentricleTemplate(GEOMETRY, centre=CENTRE, rotation=rotation)
    fit = fit_ventricle_to_mask(volume(truth))  # no warning: apex cap gives the sense
    # measured 0.018 degrees (the flag is for > 30 degrees) and the centre 0.49 mm off, along
    # the axis (at most 0.44 mm in a coordinate)
    assert np.degrees(np.arccos(min(fit.template.axis @ truth.axis, 1.0))) < 0.022
    assert np.allclose(fit.template.centre, truth.centre, atol=0.53)
    assert set(fit.flags) == {"anterior_unknown"}
    assert fit.out_of_view == ()  # the whole ventricle is imaged: every segment has voxels
    assert fit.segment_voxels is not None and fit.segment_voxels.min() > 0


def _messages(record) -> str:
    return "\n".join(str(w.message) for w in record)


def test_questionable_fits_warn_with_their_numbers():
    stack = short_axis_stack()
    # residual above the limit (measured rms 0.35 mm)
    with pytest.warns(VentricleFitWarning) as record:
        fit = fit_ventricle_to_mask(stack, base_side="high", base_level=10.0, max_residual=0.2)
    assert re.search(r"rms residual is 0\.3\d mm, above 0\.20", _messages(record))
    assert "residual" in fit.flags
    # a ring broken open inside the stack is left out, by name
    broken = stack.copy()
    broken.values[1, :, 33:] = 0
    with pytest.warns(VentricleFitWarning) as record:
        fit = fit_ventricle_to_mask(broken, base_side="high", base_level=10.0)
    assert "no closed cavity (z = [-34.0] mm)" in _messages(record)
    assert "open_slices" in fit.flags
    # slices 32 mm apart skip the mid third: its segments are empty although in view
    gap = short_axis_stack((-46.0, -14.0))
    with pytest.warns(VentricleFitWarning) as record:
        fit = fit_ventricle_to_mask(gap, base_side="high", base_level=10.0, apex_level=-70.0)
    assert "segments [7, 8, 9, 10, 11, 12] hold no tissue" in _messages(record)
    assert fit.out_of_view == (17,)
    # an RV label all round the LV is not a septum (measured 357 degrees)
    ring = with_rv(stack, 0.0, 360.0)
    with pytest.warns(VentricleFitWarning) as record:
        fit = fit_ventricle_to_mask(ring, myocardium=1, rv=2, base_side="high", base_level=10.0)
    assert re.search(r"touches the LV myocardium over 3[56]\d degrees", _messages(record))
    assert "rv_contact" in fit.flags


def test_mesh_of_a_stack_covers_the_slab_and_reports_a_real_offset():
    # 4 slices 8 mm apart fill z = -46 .. -14 mm (each voxel its full thickness), not
    # only -42 .. -18 between slice centres as before
    result = mesh_from_labels(short_axis_stack(), element_size=3.0)
    z = result.spec.mesh.p[2]
    # measured -46.20 and -13.78: the smoothed faces bulge by 0.2 mm
    assert z.min() == pytest.approx(-46.0, abs=0.26) and z.max() == pytest.approx(-14.0, abs=0.26)
    # the offset is a distance (it was 5e11 mm: a division by the zero gradient beyond the
    # grid); the 8 mm slices are smoothed by one slice, so corners sit up to 3.28 mm from
    # the rounded level set (measured); bounds at 1.2 × and / 1.2
    assert 2.7 < result.quality.max_boundary_offset < 4.0
    assert result.quality.inverted == 0


def test_scanner_path_from_dicom(tmp_path):
    # a short-axis cine stack written as a scanner would (4 slices 8 mm thick, 1.5 mm
    # pixels, tags along x and y), read back onto the reader's isotropic 1.5 mm grid, and
    # the user's labels drawn on the slices, resampled onto that grid (nearest slice)
    pytest.importorskip("pydicom")
    import xarray as xr

    from harpx.io.dicom import read_tagged
    from harpx.io.dicom_write import write_tagged
    from harpx.schema import fill_standard_attrs

    labels = short_axis_stack()
    z, y, x = (labels[d].values for d in ("z", "y", "x"))
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    waves = np.stack([np.cos(2 * np.pi * X / 8.0), np.cos(2 * np.pi * Y / 8.0)])
    ds = xr.Dataset(
        {"image": (("tag", "time", "z", "y", "x"), np.repeat(waves[:, None], 2, axis=1)),
         "mask": (("tag", "z", "y", "x"), np.ones((2, *Z.shape), dtype=bool))},
        coords={"tag": ["x", "y"], "axis": ["x", "y", "z"],
                "tag_direction": (("tag", "axis"), np.eye(3)[:2]),
                "tag_frequency": ("tag", [0.125, 0.125]), "slice_axis": ("tag", ["z", "z"]),
                "time": ("time", [0.0, 30.0]), "z": z, "y": y, "x": x},
        attrs={"harpx_schema": "tagged/1", "sequence": "CSPAMM"},
    )  # fmt: skip
    series = write_tagged(fill_standard_attrs(ds), tmp_path / "dicom")
    tagged = read_tagged(
        tmp_path / "dicom", tag_period=8.0,
        tag_directions={series["x"]: ("x", (1, 0, 0)), series["y"]: ("y", (0, 1, 0))},
    )  # fmt: skip
    grid_z = tagged.z.values
    # the reader's grid samples the slab -46 .. -14 mm (SliceThickness 8 mm)
    assert grid_z.min() > -46.0 and grid_z.max() < -14.0
    assert grid_z.min() < -46.0 + 1.5 and grid_z.max() > -14.0 - 1.5
    on_grid = labels.sel(z=grid_z, method="nearest").assign_coords(z=grid_z)
    # the mesh of either label volume covers the slab the images cover (it stopped at the
    # slice centres, -42 .. -18, before); measured -46.12 .. -13.80
    mesh = mesh_from_labels(on_grid, element_size=3.0).spec.mesh
    assert mesh.p[2].min() == pytest.approx(-46.0, abs=0.15)
    assert mesh.p[2].max() == pytest.approx(-14.0, abs=0.25)
    # the fit on the isotropic grid: refused without the base side (it put the axis in the
    # image plane before), and with it the slice normal, the centre (measured 0.025 mm off)
    # and the mid segments
    with pytest.raises(ValueError, match="cannot tell the base from the apex"):
        fit_ventricle_to_mask(on_grid)
    with pytest.warns(VentricleFitWarning):
        fit = fit_ventricle_to_mask(on_grid, base_side="high", base_level=10.0)
    assert fit.template.axis @ [0.0, 0.0, 1.0] == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(fit.template.centre[:2], CENTRE[:2], atol=0.03)
    assert fit.rms < 0.6  # measured 0.53 mm (0.35 on the slices): the plates step every 8 mm
    counts = fit.segment_voxels
    assert counts is not None and counts[6:12].min() > 0


def test_axis_far_off_the_slice_normal_is_flagged():
    b = np.deg2rad(35.0)
    rotation = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    truth = VentricleTemplate(GEOMETRY, centre=CENTRE, rotation=rotation)
    with pytest.warns(VentricleFitWarning, match=r"35\.0 degrees off the slice normal \(z\)"):
        fit = fit_ventricle_to_mask(volume(truth))
    assert "axis" in fit.flags
    # the fit itself is still good (measured 0.064 degrees, rms 0.55 mm): a flag, not an error
    assert np.degrees(np.arccos(min(fit.template.axis @ truth.axis, 1.0))) < 0.077
    assert fit.rms < 0.66


def test_a_speck_is_dropped_and_flagged_without_moving_the_fit():
    stack = short_axis_stack()
    speckled = stack.copy()
    speckled.values[0, 1, 1] = 1  # one voxel in a corner, far from the wall
    with pytest.warns(VentricleFitWarning):
        clean = fit_ventricle_to_mask(stack, base_side="high", base_level=10.0)
    with pytest.warns(VentricleFitWarning):
        fit = fit_ventricle_to_mask(speckled, base_side="high", base_level=10.0)
    assert re.match(
        r"1 specks of 1 voxels in all \(< 1 % of the \d+-voxel", fit.flags["dropped_specks"]
    )
    assert "dropped_specks" not in clean.flags
    # the speck takes no part in the fit: the same template to rounding
    assert np.allclose(fit.template.centre, clean.template.centre, atol=1e-9)
    assert fit.template.geometry.inner == pytest.approx(clean.template.geometry.inner, abs=1e-9)
    assert np.array_equal(fit.segment_voxels, clean.segment_voxels)
