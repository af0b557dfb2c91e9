"""The harpx command: subcommands, help, exit codes and one-line errors."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from harpx.cli import main


@pytest.mark.parametrize("command", ["demo", "phase", "track", "report"])
def test_every_subcommand_has_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert "usage: harpx" in capsys.readouterr().out


def test_usage_error_exits_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["frobnicate"])
    assert exc.value.code == 2


def test_missing_archive_is_one_clear_line(tmp_path, capsys):
    code = main(["report", str(tmp_path / "missing.nc")])
    err = capsys.readouterr().err.strip()
    assert code == 1
    assert (
        len(err.splitlines()) == 1
        and "missing.nc" in err
        and err.startswith("harpx report: error:")
    )


def test_demo_small_writes_archives_figures_and_table(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--size", "small", "--output", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "| conventional HARP |" in text and "| FE penalty hex8" in text
    # the closing summary: per-frame ε against its target, warnings, time, files
    assert "| frame | time (ms) | epsilon (rad) | target (rad) |" in text
    assert "4 frames tracked: target missed in none" in text
    assert "warnings: none" in text and "\ntotal " in text
    assert "wrote phantom_hex8.nc, phantom_harp.nc" in text
    for name in (
        "phantom_hex8.nc",
        "phantom_harp.nc",
        "phantom_displacement_maps.png",
        "phantom_error_vs_runtime.png",
    ):
        assert (out / name).stat().st_size > 0, name
    # the archive it wrote is a valid tracked/1 result with the same diagnostics
    figure = tmp_path / "map.png"
    assert main(["report", str(out / "phantom_hex8.nc"), "--figure", str(figure)]) == 0
    report = capsys.readouterr().out
    # units in the header; frame 0's wall_time is set-up, said so and not in the table
    assert "| epsilon (rad) | target (rad) | penalty (relative) | iterations | wall time (s) |" in (
        report
    )
    assert "| 0 | 0 | 0 | " in report and "|  |  |  | reference |" in report
    assert "frame 0 is the reference: its wall_time" in report and "is the set-up and the blur" in (
        report
    )
    assert figure.stat().st_size > 0


def test_dicom_subcommand_writes_a_tagged_archive(tmp_path, capsys):
    from harpx.io.netcdf import open_dataset
    from tests.io.test_dicom import SA, write_classic

    write_classic(tmp_path / "sa", SA)
    out = tmp_path / "tagged.nc"
    code = main(
        [
            "dicom",
            str(tmp_path / "sa"),
            str(out),
            "--tag",
            f"{SA.uid}:x:row",
            "--tag",
            f"{SA.uid}:y:column",
            "--tag-period",
            "8",
            "--sequence",
            "CSPAMM",
        ]
    )
    assert code == 0, capsys.readouterr().err
    ds = open_dataset(out)
    assert ds.attrs["harpx_schema"] == "tagged/1" and list(ds.tag.values) == ["x", "y"]


def test_dicom_subcommand_bad_tag_is_one_line(tmp_path, capsys):
    code = main(
        ["dicom", str(tmp_path), str(tmp_path / "o.nc"), "--tag", "nonsense", "--tag-period", "8"]
    )
    err = capsys.readouterr().err.strip()
    assert code == 1 and "SERIES:LABEL:DIRECTION" in err and len(err.splitlines()) == 1


# --- version, help, report refusals, track options, scene export ---------------------------


def test_version(capsys):
    import harpx

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"harpx {harpx.__version__}"


@pytest.mark.parametrize("command", [[], ["track"], ["phase"], ["demo"], ["scene"]])
def test_help_is_plain_text_with_defaults(command, capsys):
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    text = capsys.readouterr().out
    assert "``" not in text and ":mod:" not in text and ":func:" not in text
    assert "(default: None)" not in text and "(default: [])" not in text
    expected = {
        "track": "(default: 1.5)",  # --epsilon-factor: the library's own default
        "phase": "(default: 2)",
        "demo": "(default: harpx-demo)",
        "scene": "(default: harpx-scene)",
    }
    if command:
        assert expected[command[0]] in " ".join(text.split())
    else:
        assert "Exit codes: 0 success" in " ".join(text.split())


@pytest.mark.parametrize(
    ("kind", "hint"),
    [
        pytest.param("tagged", "run `harpx phase` and `harpx track` on it first", id="tagged"),
        pytest.param("phase", "run `harpx track` on it first", id="phase"),
    ],
)
def test_report_refuses_an_archive_that_is_not_tracked(tmp_path, capsys, kind, hint):
    from harpx.io.netcdf import to_netcdf
    from tests.test_schema import make_phase, make_tagged

    path = to_netcdf({"tagged": make_tagged, "phase": make_phase}[kind](), tmp_path / "a.nc")
    code = main(["report", str(path)])
    captured = capsys.readouterr()
    assert code == 1 and captured.out == ""  # no empty table
    assert f"is a '{kind}/1' archive; report needs a 'tracked/1' archive: {hint}" in captured.err


def _cylinder_inputs(tmp_path):
    """Ideal phase of a turning cylinder and its coarse mesh (so the test is fast)."""
    import meshio

    from harpx.io.netcdf import to_netcdf
    from tests.test_batch import _subject, body_factory

    phase = to_netcdf(_subject(3.0), tmp_path / "phase.nc")
    mesh = tmp_path / "mesh.vtu"
    meshio.write(mesh, body_factory(None).to_meshio())
    return phase, mesh


def test_track_fixes_named_faces_and_takes_the_penalty(tmp_path, capsys):
    from harpx.io.netcdf import open_dataset

    phase, mesh = _cylinder_inputs(tmp_path)
    out = tmp_path / "tracked.nc"
    args = ["track", str(phase), str(out), "--mesh", str(mesh), "--no-progress"]
    # the images turn the whole cylinder rigidly, so holding its bottom contradicts them: the
    # last frame cannot reach its target ε (0.14 rad against 0.03) and the tracker warns
    code = main([*args, "--fix", "bottom", "--fix", "top:z", "--penalty", "2"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    # ...and the summary says which frame, with the warning's count and first line
    text = captured.out
    assert "| 2 | 36 | 0.14 | 0.03 | " in text and text.count("target missed |") == 1, text
    assert "2 frames tracked: target missed in frame 2; plateau in frame 1" in text
    assert "warnings (1):\n  - HarpxWarning: 1 frame(s) missed the tracking target: frame 2" in (
        text
    )
    assert "\ntotal " in text and text.rstrip().endswith(f"wrote {out}")
    assert captured.err == ""  # the warning is in the summary, not printed twice
    ds = open_dataset(out)
    z = ds.points.values[:, 2]
    u = ds.displacement.values  # (time, node, axis)
    bottom, top = np.isclose(z, z.min()), np.isclose(z, z.max())
    assert np.all(u[:, bottom] == 0.0)  # held exactly
    assert np.all(u[:, top, 2] == 0.0) and np.abs(u[-1, top, :2]).max() > 1.0  # top turns
    assert float(ds.attrs["penalty_start"]) == 2.0


def test_track_names_the_boundaries_for_an_unknown_face(tmp_path, capsys):
    phase, mesh = _cylinder_inputs(tmp_path)
    code = main(["track", str(phase), str(tmp_path / "t.nc"), "--mesh", str(mesh), "--fix", "lid"])
    err = capsys.readouterr().err
    assert code == 1
    assert "no boundary 'lid'; its boundaries are ['bottom', 'outer', 'top']" in err
    code = main(
        ["track", str(phase), str(tmp_path / "t.nc"), "--mesh", str(mesh), "--fix", "top:w"]
    )
    assert code == 1 and "must be distinct letters of 'xyz'" in capsys.readouterr().err


def test_scene_exports_an_input_archive_and_mesh(tmp_path, capsys):
    from harpx.io.mesh import read_body
    from harpx.io.netcdf import open_dataset
    from harpx.mechanics.materials import NeoHookean

    assert main(["scene", "phantom-small", "--output", str(tmp_path / "try")]) == 0
    text = capsys.readouterr().out
    tagged = open_dataset(tmp_path / "try" / "tagged.nc")
    assert tagged.attrs["harpx_schema"] == "tagged/1" and "displacement_true" in tagged
    # what `harpx track --mesh` reads: cells and the named faces that --fix takes
    body = read_body(tmp_path / "try" / "mesh.vtu", NeoHookean(c1=1.0, kappa=120.0))
    assert body.ncell == 432 and sorted(body.boundaries) == ["bottom", "outer", "top"]
    assert f"harpx track {tmp_path / 'try' / 'phase.nc'}" in text and "--mesh" in text


@pytest.mark.parametrize("command", ["track", "demo"])
def test_tracking_defaults_are_the_librarys(command):
    # no tracking option on the command line: the settings are TrackingSettings() (noise-floor
    # target, blur correction), as in a notebook
    import argparse

    from harpx.cli import _tracking, build_parser
    from harpx.tracking.settings import TrackingSettings

    parser = build_parser()
    argv = [command] if command == "demo" else ["track", "in.nc", "out.nc", "--mesh", "m.vtu"]
    args = parser.parse_args(argv)
    assert isinstance(args, argparse.Namespace)
    # the progress bar too: auto (terminal or notebook), the library's rule
    assert TrackingSettings.build(**_tracking(args)) == TrackingSettings()
    given = parser.parse_args([*argv, "--epsilon", "0.1", "--blur-passes", "0", "--no-progress"])
    chosen = TrackingSettings.build(**_tracking(given))
    assert (chosen.epsilon, chosen.effective_blur_passes, chosen.progress) == (0.1, 0, False)


def test_phase_defaults_are_the_librarys():
    # `harpx phase in out` and `harpx demo` extract the phase as ds.harp.phase() does
    import inspect

    from harpx.cli import build_parser
    from harpx.imaging.harp import extract_phase

    library = inspect.signature(extract_phase).parameters
    parser = build_parser()
    phase = parser.parse_args(["phase", "in.nc", "out.nc"])
    assert (phase.upsample, phase.radius) == (
        library["upsample"].default,
        library["radius"].default,
    )
    assert parser.parse_args(["demo"]).upsample == library["upsample"].default


# --- dicom: the series it found whenever it cannot choose ----------------------------------


@pytest.fixture
def two_series(tmp_path):
    from tests.io.test_dicom import LA, SA, write_classic

    write_classic(tmp_path / "sa", SA)
    write_classic(tmp_path / "la", LA)
    return tmp_path


def _listed_series(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("  - SeriesDescription")]


def test_dicom_without_tag_lists_the_series_found(two_series, capsys):
    out = two_series / "o.nc"
    assert main(["dicom", str(two_series), str(out)]) == 1  # not argparse's usage error (2)
    err = capsys.readouterr().err
    assert err.startswith("harpx dicom: error: no --tag given: say which series carries")
    listed = _listed_series(err)
    assert len(listed) == 2 and "'SA tagged'" in err and "'LA tagged'" in err, err
    assert not out.exists()


def test_dicom_with_an_unknown_series_lists_the_series_found(two_series, capsys):
    args = ["dicom", str(two_series), str(two_series / "o.nc"), "--tag-period", "8"]
    assert main([*args, "--tag", "SA tagging:x:row"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(
        "harpx dicom: error: --tag names series 'SA tagging', which matches no SeriesInstanceUID"
    )  # the command's words, not the library's tag_directions
    assert len(_listed_series(err)) == 2, err  # the list, not only the first line


def test_dicom_tag_without_tag_period_says_so(two_series, capsys):
    from tests.io.test_dicom import SA

    code = main(["dicom", str(two_series), str(two_series / "o.nc"), "--tag", f"{SA.uid}:x:row"])
    err = capsys.readouterr().err.strip()
    assert code == 1 and err == (
        "harpx dicom: error: --tag-period is required: DICOM does not record the tag spacing; "
        "give it in mm, e.g. --tag-period 8"
    )


# --- the docs agree with the parser --------------------------------------------------------


def test_docs_name_every_subcommand_and_the_demo_default():
    from pathlib import Path

    from harpx.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    docs = (Path(__file__).parents[1] / "docs" / "cli.md").read_text()
    for name in sub.choices:
        assert f"`harpx {name}" in docs, f"docs/cli.md does not describe `harpx {name}`"
    size = sub.choices["demo"].get_default("size")
    assert f"default `{size}`" in docs  # the size the demo runs without --size


def test_phase_says_the_tag_period_the_images_show(tmp_path, capsys):
    from harpx.imaging.synth import synthesize_tagged
    from harpx.io.netcdf import to_netcdf

    tagged = synthesize_tagged(
        lambda X, t: 0 * X, shape=(2, 48, 48), spacing=(3.0, 1.5, 1.5), times=[0.0],
        tags=("x", "z"), tag_period=6.0, snr=None, oversample=1,
    )  # fmt: skip
    source = to_netcdf(tagged, tmp_path / "tagged.nc")
    assert main(["phase", str(source), str(tmp_path / "phase.nc")]) == 0
    # x: 12 periods across 72 mm, measured; z: 6 mm of slab, 1 period, not measured
    line = capsys.readouterr().out.splitlines()[-1]
    assert line == (
        "tag period seen in the images / stated (mm; - not measured): x 6.00 / 6.00, z - / 6.00"
    )
