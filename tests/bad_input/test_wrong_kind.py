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
