"""Values of the wrong kind (lists for strings, strings for numbers, arrays for datasets)
get a named error; validate() keeps every problem it found."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.errors import SchemaError
from harpx.schema import validate
from tests.test_schema import make_phase, make_tagged


@pytest.mark.parametrize(
    ("value", "match"),
    [
        pytest.param(["SPAMM"], r"'sequence' is \['SPAMM'\]; expected one of", id="list"),
        pytest.param({"a": 1}, r"'sequence' is \{'a': 1\}", id="dict"),
        pytest.param(np.array(["SPAMM"]), r"'sequence' is array\(\['SPAMM'\]", id="array"),
    ],
)
def test_list_valued_sequence_is_a_problem_not_a_type_error(value: object, match: str) -> None:
    ds = make_tagged()
    ds.attrs["sequence"] = value
    ds = ds.assign_coords(time=("time", [0.0, np.nan], ds.time.attrs))  # a second problem
    with pytest.raises(SchemaError, match=match) as info:
        validate(ds)
    assert len(info.value.problems) == 2, info.value.problems  # nothing lost


def test_list_valued_schema_attribute_is_named() -> None:
    ds = make_tagged()
    ds.attrs["harpx_schema"] = ["tagged/1"]
    with pytest.raises(SchemaError, match=r"'harpx_schema' is \['tagged/1'\]; known schemas"):
        validate(ds)
    with pytest.raises(SchemaError, match=r"'harpx_schema' is \['tagged/1'\] but 'tagged/1'"):
        validate(ds, kind="tagged")


@pytest.mark.parametrize(
    "directions",
    [[["x", "0", "0"], ["0", "y", "0"]], [["1", "0", "0"], ["0", "1", "0"]]],
    ids=["letters", "digits"],
)
def test_string_tag_directions_are_named_and_other_problems_kept(directions: list) -> None:
    ds = make_tagged()
    ds = ds.assign_coords(tag_direction=(("tag", "axis"), directions, ds.tag_direction.attrs))
    ds.attrs["sequence"] = "GRE"
    with pytest.raises(SchemaError, match=r"'tag_direction' has dtype '<U1'") as info:
        validate(ds)
    assert any("'sequence' is 'GRE'" in p for p in info.value.problems), info.value.problems


@pytest.mark.parametrize(
    ("name", "value", "match"),
    [
        ("upsample", [1, 2], r"'upsample' is \[1, 2\]; expected a positive integer"),
        ("upsample", "two", r"'upsample' is 'two'"),
        ("upsample", 1.5, r"'upsample' is 1.5"),
        ("upsample", 0, r"'upsample' is 0"),
        ("radius", float("nan"), r"'radius' is nan; expected a positive finite number"),
        ("radius", -0.5, r"'radius' is -0.5"),
    ],
)
def test_bad_filter_settings_of_a_phase_dataset_are_named(
    name: str, value: object, match: str
) -> None:
    ds = make_phase()
    ds.attrs[name] = value
    with pytest.raises(SchemaError, match=match):
        validate(ds)


def test_validate_of_a_non_dataset_names_the_type() -> None:
    with pytest.raises(TypeError, match=r"needs an xarray.Dataset, got 'DataArray'.*to_dataset"):
        validate(make_tagged().image)  # type: ignore[arg-type]


def test_validate_with_a_non_string_kind_names_it() -> None:
    with pytest.raises(TypeError, match=r"kind=\['tagged'\] must be a str"):
        validate(make_tagged(), kind=["tagged"])  # type: ignore[arg-type]


def test_object_tag_labels_are_named_and_earlier_problems_kept() -> None:
    ds = make_tagged().assign_attrs(sequence="GRE")
    ds = ds.assign_coords(tag=("tag", np.array([None, 3.5], dtype=object), ds.tag.attrs))
    with pytest.raises(SchemaError) as info:
        validate(ds)
    assert info.value.problems[0].startswith("dataset attribute 'sequence' is 'GRE'")
    assert len(info.value.problems) >= 2, info.value.problems


def test_track_many_with_one_path_string_is_named_not_iterated(tmp_path) -> None:
    from harpx.batch import track_many

    with pytest.raises(TypeError, match=r"got the single path 's0.nc'.*pass a list: \['s0.nc'\]"):
        track_many("s0.nc", lambda ds: None, output_dir=tmp_path)  # type: ignore[arg-type]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("name", "value", "expected"),
    [
        pytest.param("ramp", np.int64(2), 2, id="int64"),
        pytest.param("max_iterations", np.uint8(5), 5, id="uint8"),
        pytest.param("ramp", np.float64(3.0), 3, id="whole-float64"),
        pytest.param("epsilon", np.float32(0.25), 0.25, id="float32"),
        pytest.param("penalty", np.int32(8), 8.0, id="int32-penalty"),
    ],
)
def test_numpy_scalar_settings_are_taken_as_python_numbers(
    name: str, value: object, expected: float
) -> None:
    # before: TrackingSettings(ramp=np.int64(2)) was refused as "not a whole number"
    from harpx.tracking.settings import TrackingSettings

    got = getattr(TrackingSettings(**{name: value}), name)
    assert got == expected and type(got) is type(expected)  # plain int/float in the archive


@pytest.mark.parametrize(
    ("value", "match"),
    [
        pytest.param(np.array([2]), r"ramp=array\(\[2\]\) must be a whole number, not ndarray "
                     r"\(a scalar, not an array: e\.g\. value\.item\(\)\)", id="array"),
        pytest.param(np.True_, r"ramp=np.True_ must be a whole number, not bool", id="np-bool"),
        pytest.param(True, r"ramp=True must be a whole number, not bool", id="bool"),
        pytest.param("2", r"ramp='2' must be a whole number, not str", id="str"),
    ],
)  # fmt: skip
def test_non_scalar_settings_are_named_with_their_type(value: object, match: str) -> None:
    from harpx.tracking.settings import TrackingSettings

    with pytest.raises(TypeError, match=match):
        TrackingSettings(ramp=value)
    with pytest.raises(ValueError, match=r"ramp=np.int64\(0\) must be a whole number ≥ 1"):
        TrackingSettings(ramp=np.int64(0))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"chunks": {"time": -3}}, r"chunks\['time'\] is -3; expected", id="chunk"),
        pytest.param({"chunks": 5}, r"chunks=5 must be None, 'auto' or a mapping", id="chunks"),
        pytest.param({"max_bytes": "1GB"}, r"max_bytes='1GB' must be a positive", id="str"),
        pytest.param({"max_bytes": -1}, r"max_bytes=-1 must be a positive whole", id="negative"),
    ],
)
def test_open_dataset_arguments_are_named_not_a_corrupt_file(tmp_path, kwargs, match) -> None:
    # before: ArchiveError "... the file may be truncated, corrupt or not NetCDF"
    from harpx.io.netcdf import open_dataset, to_netcdf

    path = to_netcdf(make_tagged(), tmp_path / "a.nc")
    with pytest.raises(ValueError, match=match):
        open_dataset(path, **kwargs)


@pytest.mark.parametrize("upsample", [0, -1, 2.5, True], ids=["zero", "negative", "float", "bool"])
def test_refinement_factors_refuses_a_bad_upsample(upsample: object) -> None:
    # before: (1, 0, 0) for upsample=0, silently
    from harpx.imaging.harp import refinement_factors

    with pytest.raises(ValueError, match=r"'upsample' must be an integer >= 1"):
        refinement_factors(make_tagged(), upsample)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        pytest.param({"paths": None}, TypeError, r"paths must be an iterable", id="none"),
        pytest.param({"paths": [None]}, TypeError, r"paths holds 1 entries that are", id="entry"),
        pytest.param({"paths": []}, ValueError, r"paths is empty: there is no subject", id="empty"),
        pytest.param(
            {"n_workers": 1.5}, ValueError, r"n_workers=1.5 must be a whole", id="workers"
        ),
        pytest.param(
            {"track_kwargs": {"epsilon": -1}},
            ValueError,
            r"track_kwargs: epsilon=-1 must be a positive",
            id="setting",
        ),
        pytest.param(
            {"output_dir": "file"}, FileExistsError, r"output_dir '.*file' is a file", id="output"
        ),
    ],
)
def test_track_many_arguments_are_refused_before_any_work(tmp_path, kwargs, error, match) -> None:
    # before: raw TypeErrors, an empty cohort returned [], and a bad setting failed every
    # subject on the workers after a cluster had started
    from harpx.batch import track_many

    (tmp_path / "file").write_text("not a folder")
    args = {"paths": [tmp_path / "s0.nc"], "output_dir": tmp_path / "out", **kwargs}
    if args["output_dir"] == "file":
        args["output_dir"] = tmp_path / "file"
    with pytest.raises(error, match=match):
        track_many(body_factory=len, progress=False, **args)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # no output folder made
