"""Silent wrong results: input that used to give a plausible but wrong number."""

from __future__ import annotations

import re

import numpy as np
import pytest
import xarray as xr

from harpx.errors import HarpxWarning
from harpx.tracking.results import tracking_error


def _grid_pair(times_tracked: list[float], times_truth: list[float]) -> tuple[xr.Dataset, ...]:
    """Uniform x displacement 0.1 mm/ms on a 2 x 3 x 4 grid; tracked is exact."""
    coords = {"z": [0.0, 2.0], "y": [0.0, 2.0, 4.0], "x": [0.0, 2.0, 4.0, 6.0]}

    def field(times: list[float], name: str) -> xr.Dataset:
        u = np.zeros((len(times), 3, 2, 3, 4))
        u[:, 0] = 0.1 * np.asarray(times)[:, None, None, None]
        dims = ("time", "axis", "z", "y", "x")
        return xr.Dataset(
            {name: (dims, u)}, coords={"time": times, "axis": ["x", "y", "z"], **coords}
        )

    return field(times_tracked, "displacement_grid"), field(times_truth, "displacement_true")


def test_tracking_error_compares_frames_by_time_not_index() -> None:
    # tracked frames 0, 20 ms against a truth with frames 0, 10, 20 ms: by index, frame 20
    # would be compared with the truth at 10 ms (error 1 mm); by time it is exact
    tracked, truth = _grid_pair([0.0, 20.0], [0.0, 10.0, 20.0])
    # the truth's frame at 10 ms has no tracked frame: left out, and named
    with pytest.warns(HarpxWarning, match=r"t = 10 ms were not tracked"):
        err = tracking_error(tracked, truth)
    assert err.time.values.tolist() == [0.0, 20.0]
    np.testing.assert_allclose(err["max_all"], 0.0, atol=1e-12)  # exact tracking


def test_tracking_error_without_common_frames_is_named() -> None:
    tracked, truth = _grid_pair([0.0, 15.0], [5.0, 10.0])
    with pytest.raises(ValueError, match=r"share no frame time: tracked has time \[0.0, 15.0\]"):
        tracking_error(tracked, truth)


# --- meshes: every volume cell is used or the mesh is refused ------------------------------


def _hex_blocks() -> tuple[np.ndarray, np.ndarray]:
    """Points and 18 hexahedra (VTK order) of a 3 x 3 x 2 box."""
    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean
    from harpx.mechanics.mesh import box

    m = Body(box((3.0, 3.0, 2.0), (3, 3, 2)), NeoHookean(c1=1.0, kappa=120.0)).to_meshio()
    return np.asarray(m.points), np.asarray(m.cells_dict["hexahedron"])


def test_two_hexahedron_blocks_are_merged_not_the_first_taken(tmp_path) -> None:
    # before: Body.from_meshio used the first block only (9 of 18 cells)
    import meshio

    from harpx.io.mesh import read_body, read_body_mesh
    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean

    points, cells = _hex_blocks()
    fibers = np.tile([1.0, 0.0, 0.0], (18, 1))
    fibers[9:] = [0.0, 1.0, 0.0]  # the second block's fibres differ: order must be kept
    mesh = meshio.Mesh(
        points, [("hexahedron", cells[:9]), ("hexahedron", cells[9:])],
        cell_data={"fiber": [fibers[:9], fibers[9:]]},
    )  # fmt: skip
    body = Body.from_meshio(mesh, NeoHookean(c1=1.0, kappa=120.0))
    assert body.ncell == 18 and body.nodes.shape[0] == points.shape[0]
    np.testing.assert_allclose(body.fibers, fibers)
    path = tmp_path / "two.vtu"
    meshio.write(path, mesh)
    assert read_body(path, NeoHookean(c1=1.0, kappa=120.0)).ncell == 18
    assert read_body_mesh(path).mesh.t.shape[1] == 18


def test_hexahedra_with_a_tetrahedron_are_refused_with_the_counts(tmp_path) -> None:
    # before: read_body kept the hexahedra and dropped the tetrahedron silently
    import meshio

    from harpx.errors import SchemaError
    from harpx.io.mesh import read_body, read_body_mesh
    from harpx.mechanics.materials import NeoHookean

    points, cells = _hex_blocks()
    tet = cells[:1, [0, 1, 3, 4]]
    path = tmp_path / "mixed.vtu"
    meshio.write(path, meshio.Mesh(points, [("hexahedron", cells), ("tetra", tet)]))
    counts = r"\{'hexahedron': 18, 'tetra': 1\}"
    with pytest.raises(ValueError, match=rf"mixed\.vtu' mixes volume cells of .* {counts}"):
        read_body(path, NeoHookean(c1=1.0, kappa=120.0))
    with pytest.raises(SchemaError, match=rf"mixes volume cells of several kinds {counts}"):
        read_body_mesh(path)
    wedge = meshio.Mesh(points, [("hexahedron", cells), ("wedge", cells[:2, :6])])
    with pytest.raises(ValueError, match=r"\{'hexahedron': 18, 'wedge': 2\}"):
        from harpx.mechanics.body import Body

        Body.from_meshio(wedge, NeoHookean(c1=1.0, kappa=120.0))


def test_cells_listed_twice_are_refused_not_counted_twice() -> None:
    # before: a cell repeated (e.g. once per physical group of an export) doubled its volume
    import meshio

    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean

    points, cells = _hex_blocks()
    mesh = meshio.Mesh(points, [("hexahedron", cells), ("hexahedron", cells[4:6])])
    with pytest.raises(ValueError, match=r"2 'hexahedron' cells that repeat .*cells \[18, 19\]"):
        Body.from_meshio(mesh, NeoHookean(c1=1.0, kappa=120.0))


def test_boundary_blocks_beside_the_volume_are_not_a_mix() -> None:
    import meshio

    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean

    points, cells = _hex_blocks()
    mesh = meshio.Mesh(points, [("quad", cells[:3, :4]), ("hexahedron", cells)])
    assert Body.from_meshio(mesh, NeoHookean(c1=1.0, kappa=120.0)).ncell == 18


# --- a body partly outside the images: warned, with the fraction ---------------------------


def _coverage(shift_x: float, mask_half: bool = False) -> tuple[float, list[str]]:
    import warnings

    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean
    from harpx.mechanics.mesh import box
    from harpx.tracking.constraint import PhaseConstraint
    from harpx.tracking.image_fit import check_coverage
    from tests.test_schema import make_phase

    phase = make_phase()  # x, y in [0, 16] mm, z in [-2, 6] mm
    if mask_half:  # the slices were acquired over x < 8 mm only
        phase["mask"] = phase["mask"] & (phase.x < 8.0)
    origin = (4.0 + shift_x, 4.0, 0.0)
    body = Body(box((8.0, 8.0, 4.0), (2, 2, 1), origin=origin), NeoHookean(c1=1.0, kappa=120.0))
    constraint = PhaseConstraint(body, phase)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fraction = check_coverage(
            phase, constraint.points, constraint.volume, constraint.reference_valid
        )
    return fraction, [str(w.message) for w in caught if issubclass(w.category, HarpxWarning)]


def test_a_body_half_outside_the_field_of_view_is_warned_with_the_fraction() -> None:
    # before: tracked with a ~25 % bias inside, noted only as observed_directions = 0
    fraction, messages = _coverage(shift_x=8.0)  # x from 12 to 20 mm: half beyond 16 mm
    assert fraction == pytest.approx(0.5)
    assert len(messages) == 1
    assert re.match(r"50 % of the body \(\d+ of \d+ constraint points\) lies outside", messages[0])
    assert "50 % outside the field of view" in messages[0] and "Crop the mesh" in messages[0]


def test_a_body_half_outside_the_masks_is_warned() -> None:
    fraction, messages = _coverage(shift_x=0.0, mask_half=True)  # x from 4 to 12 mm
    assert fraction == pytest.approx(0.5)
    assert "0 % outside the field of view" in messages[0]
    assert "and 50 % outside every tag's mask" in messages[0]


def test_a_body_inside_the_images_is_not_warned() -> None:
    assert _coverage(shift_x=0.0) == (0.0, [])


def test_harp_points_without_data_are_counted_not_hidden() -> None:
    # before: NaN in every frame while points_lost said 0 and nothing was said
    from harpx.imaging.harptrack import track_harp
    from tests.test_schema import make_phase

    points = [[5.0, 5.0, 0.0], [500.0, 5.0, 0.0], [7.0, 7.0, 0.0], [5.0, -90.0, 0.0]]
    with pytest.warns(HarpxWarning, match=r"2 of 4 points have no valid phase .*rows \[1, 3\]"):
        out = track_harp(make_phase(), points=points)
    assert out.attrs["points_unseen"] == 2 and out.attrs["points_lost"] == 0
    assert np.isnan(out.displacement.values[:, [1, 3]]).all()
    assert np.isfinite(out.displacement.values[:, [0, 2]]).all()
