"""Left-ventricle scene with a regional infarct: truth per AHA segment, FE finds the infarct."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.cardiac.strain import aha_segments, cardiac_strain
from harpx.errors import HarpxWarning
from harpx.imaging.harp import extract_phase
from harpx.scenes.lv import ANTERIOR, Systole, aha_segment, base_conditions, lv, simulate_systole
from harpx.schema import validate
from harpx.tracking.track import track

INFARCT = (7, 8, 13, 14)  # mid anterior, mid anteroseptal, apical anterior, apical septal
SCAR = 0.5  # half the active tension: a hypokinetic infarct
SHORT_AXIS = slice(0, 16)  # segments 1-16: segment 17 has no short-axis data


@pytest.fixture(scope="module")
def scene(lv_small_infarct):
    # small: 5 frames, 2 mm pixels, a 456-cell tracking model, a 1539-cell truth
    # (tests/conftest.py, shared with the scanner-path test)
    attrs = lv_small_infarct.tagged.attrs
    assert tuple(attrs["infarct_segments"]) == INFARCT and attrs["scar_activation"] == SCAR
    return lv_small_infarct


@pytest.fixture(scope="module")
def truth(scene):
    return cardiac_strain(scene.truth_result(), scene.template())


@pytest.fixture(scope="module")
def fe(scene):
    # the setting for thick-slice CSPAMM short-axis stacks (guide, "Wall thickening"):
    # CSPAMM has no DC peak, so the band-pass may be 0.8 of the tag frequency, and three
    # blur-correction passes remove the band-pass and slice blur across the 10 mm wall
    phase = extract_phase(scene.tagged, upsample=2, radius=0.8)
    tracked = track(phase, scene.body(), dirichlet=scene.dirichlet(), blur_passes=3)
    # the apical cap (17) has long-axis data only: its Ecc and Ell come from the model,
    # and so does much of its thickening, which the through-plane tag sees across the cap
    # (the guide, "Wall thickening": FE 0.129 there against 0.265 true)
    with pytest.warns(
        HarpxWarning, match=r"radial strain partly inferred in segment\(s\) 17;.*circumf"
    ):
        return cardiac_strain(tracked, scene.template())


def _ecc(ds):
    return ds.peak_strain.sel(component="circumferential").values


def test_infarct_cells_are_those_of_the_analysis_segments(scene):
    body = scene.truth.body
    centres = body.nodes[body.cells[:, :8]].mean(axis=1)
    template = scene.template()
    assert template.anterior == ANTERIOR
    # the scene's copy of the AHA rule (the scene layer cannot import harpx.cardiac) is the
    # analysis rule, cell by cell
    ours = aha_segment(centres, template)
    np.testing.assert_array_equal(ours, aha_segments(centres, template, anterior=ANTERIOR))
    assert set(np.unique(ours)) == set(range(1, 18))
    infarct = np.isin(ours, INFARCT)
    np.testing.assert_allclose(body.t_max[infarct], SCAR * 60.0, rtol=1e-12)
    np.testing.assert_allclose(body.t_max[~infarct], 60.0, rtol=1e-12)
    assert scene.info["infarct_cells"] == int(infarct.sum()) > 0
    assert scene.tagged.attrs["infarct_segments"] == list(INFARCT)
    assert scene.infarct == INFARCT and scene.scar_activation == SCAR
    # the tracking mesh names its cells after the same segments (it was centred on +x
    # while the scene's anterior wall is +y: every name 90° off the analysis's segments)
    spec = scene.mesh
    centres = spec.mesh.p[:, spec.mesh.t].mean(axis=1).T
    named = np.zeros(len(centres), dtype=np.int64)
    for k in range(1, 18):
        named[spec.regions[f"aha_{k:02d}"]] = k
    np.testing.assert_array_equal(named, aha_segment(centres, template))


def test_truth_result_is_the_forward_simulation(scene):
    result = scene.truth_result()
    validate(result, "tracked")
    truth = scene.tagged.displacement_true.transpose(*result.displacement_grid.dims).values
    grid = result.displacement_grid.values
    both = np.isfinite(truth) & np.isfinite(grid)
    # both interpolate the same fine-mesh displacement at the voxel centres (round-off)
    assert both.sum() > 0.9 * np.isfinite(truth).sum()
    np.testing.assert_allclose(grid[both], truth[both], atol=1e-9)
    with pytest.raises(ValueError, match="not the motion's"):
        scene.truth.as_tracked(scene.tagged.isel(time=[0, 1]))


def test_infarct_contracts_least_and_lowers_the_ejection(scene, truth):
    ecc = _ecc(truth)
    infarct = np.isin(np.arange(1, 18), INFARCT)
    # measured on the 1539-cell truth: peak Ecc -0.023 to -0.062 in the infarct
    # (hypokinetic), -0.080 (basal anterior, beside it) to -0.136 elsewhere (healthy
    # ventricle: -0.11 to -0.14): a gap of 0.018
    assert ecc[infarct].max() < 0.0, ecc[infarct]
    assert ecc[infarct].min() > ecc[~infarct].max() + 0.015, ecc
    # radial strain: the mid infarct barely thickens (measured +0.024, -0.015) where the
    # healthy mid wall thickens by 0.17-0.23
    err = truth.peak_strain.sel(component="radial").values
    assert np.all(np.abs(err[[6, 7]]) < 0.05), err[[6, 7]]
    assert np.all(err[[8, 9, 10, 11]] > 0.15), err
    # ejection fraction: measured 0.235 against 0.348 for the healthy ventricle
    ef = scene.info["forward"]["ejection_fraction"][-1]
    assert 0.2 < ef < 0.3, ef


def test_fe_tracking_finds_the_infarct_and_its_ecc(truth, fe):
    ecc, true = _ecc(fe)[SHORT_AXIS], _ecc(truth)[SHORT_AXIS]
    # the four segments with the least |peak Ecc| are the infarct (measured FE -0.033 to
    # -0.061 there, -0.093 at most elsewhere)
    least = np.sort(np.argsort(np.abs(ecc))[: len(INFARCT)] + 1)
    assert least.tolist() == list(INFARCT), ecc.round(3)
    # per-segment peak Ecc within 0.01 on average: measured mean |error| 0.0030 (max 0.0157,
    # in the apical septal infarct segment 14); bounds at measured x 1.2
    error = np.abs(ecc - true)
    assert error.mean() < 1.2 * 0.0030, error.round(4)
    assert error.max() < 1.2 * 0.0157, error.round(4)
    # wall thickening within 10 % (issue 23): mean |error| of the peak radial strain
    # measured 8.5 % of the mean true peak Err (31.8 % with the library's defaults, radius
    # 0.5 and one pass; HARP 36.9 %); the bound is the goal, 1.2 x measured would be 10.2 %
    err = fe.peak_strain.sel(component="radial").values[SHORT_AXIS]
    true_err = truth.peak_strain.sel(component="radial").values[SHORT_AXIS]
    ratio = np.abs(err - true_err).mean() / np.abs(true_err).mean()
    assert ratio < 0.10, ratio
    # these settings leave nothing to caution about; the truth has no note either
    assert fe.attrs["radial_strain_caution"] == ""
    assert truth.attrs["radial_strain_caution"] == ""


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(infarct=(0, 7)), "infarct=\\(0, 7\\)"),
        (dict(infarct=(18,)), "infarct=\\(18,\\)"),
        (dict(infarct=(7, 7)), "distinct"),
        (dict(infarct=(7,), scar_activation=1.5), "scar_activation=1.5"),
        (dict(infarct=(7,), scar_activation=-0.1), "scar_activation=-0.1"),
    ],
)
def test_bad_infarcts_are_clear_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        lv(size="small", **kwargs)


def test_tension_factors_outside_0_1_are_refused_before_solving(scene):
    body = scene.truth.body
    for tension in (np.full(body.ncell, 1.5), np.ones(body.ncell - 1)):
        with pytest.raises(ValueError, match="one factor in \\[0, 1\\] per cell"):
            simulate_systole(body, 3, Systole(), base_conditions(), tension=tension)
