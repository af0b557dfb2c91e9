"""Shapes of the arrays :func:`harpx.imaging.stacks.tagged_dataset` assembles, checked first.

Every array of a ``tagged/1`` dataset is laid out along the lengths of its labels and
coordinates (``tag``, ``time``, ``z``, ``y``, ``x``). :func:`check_tagged_shapes` compares
each given array with the shape those lengths imply and names the array, its shape and
the expected one, before numpy or xarray broadcast them into an error that names neither
(or, for a mask of one tag, silently into another layout).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["check_tagged_shapes"]


def _shape(value: ArrayLike) -> tuple[int, ...]:
    return tuple(int(n) for n in np.shape(value))


def check_tagged_shapes(image: ArrayLike, arrays: Mapping[str, Any]) -> None:
    """Check that the arrays of a ``tagged/1`` dataset agree with its labels and coordinates.

    Parameters
    ----------
    image : array_like
        Expected shape (tag, time, z, y, x).
    arrays : mapping of str to object
        The other arguments of :func:`~harpx.imaging.stacks.tagged_dataset` by name:
        ``tag`` (sequence of str: the ``tag`` length), ``tag_frequency`` (a scalar or shape
        (tag,), cycles/mm), ``slice_axis`` (one axis name per tag), ``time``, ``z``, ``y``,
        ``x`` (one-dimensional coordinates, ms and mm: the lengths of those dims) and, where
        not None, ``tag_direction`` (tag, 3), ``mask`` (tag, z, y, x) or (z, y, x) for one
        mask shared by every tag, ``body`` (z, y, x) and ``displacement_true`` (time, 3, z,
        y, x).

    Raises
    ------
    ValueError
        Naming every array whose shape is wrong, with its shape and the expected one
        spelled out in dims.
    """
    tag, tag_frequency, slice_axis = arrays["tag"], arrays["tag_frequency"], arrays["slice_axis"]
    tag_direction, mask, body = arrays.get("tag_direction"), arrays.get("mask"), arrays.get("body")
    displacement_true = arrays.get("displacement_true")
    coords = {name: arrays[name] for name in ("time", "z", "y", "x")}
    problems = [
        f"coordinate {name!r} has shape {_shape(value)!r}; expected one dimension (its values)"
        for name, value in coords.items()
        if np.ndim(value) != 1
    ]
    if problems:
        raise ValueError("; ".join(problems))
    n = {name: int(np.size(value)) for name, value in coords.items()}
    n["tag"] = len(tag)
    grid = (n["z"], n["y"], n["x"])
    spelled = f"z={n['z']}, y={n['y']}, x={n['x']}"

    def expect(name: str, value: ArrayLike, shapes: list[tuple[int, ...]], dims: str) -> None:
        if _shape(value) not in shapes:
            problems.append(f"{name} has shape {_shape(value)!r}; expected {dims}")

    expect(
        "image",
        image,
        [(n["tag"], n["time"], *grid)],
        f"(tag, time, z, y, x) = {(n['tag'], n['time'], *grid)!r} for {n['tag']} tag "
        f"label(s), {n['time']} time(s) and the grid {spelled} (a 4-D image of one tag: "
        "image[None])",
    )
    expect(
        "tag_frequency",
        tag_frequency,
        [(), (n["tag"],)],
        f"a scalar or one frequency (cycles/mm) per tag label, shape ({n['tag']},)",
    )
    if len(slice_axis) != n["tag"]:
        problems.append(
            f"slice_axis has {len(slice_axis)} entries ({slice_axis!r}); expected one axis "
            f"name per tag label ({n['tag']}), e.g. {['z'] * n['tag']!r}"
        )
    if tag_direction is not None:
        expect(
            "tag_direction",
            tag_direction,
            [(n["tag"], 3)],
            f"(tag, 3) = ({n['tag']}, 3): one unit vector (x, y, z) per tag label",
        )
    if mask is not None:
        expect(
            "mask",
            mask,
            [(n["tag"], *grid), (1, *grid), grid],
            f"(tag, z, y, x) = {(n['tag'], *grid)!r}, or (z, y, x) = {grid!r} for one mask "
            "shared by every tag",
        )
    if body is not None:
        expect("body", body, [grid], f"(z, y, x) = {grid!r}, the grid {spelled}")
    if displacement_true is not None:
        expect(
            "displacement_true",
            displacement_true,
            [(n["time"], 3, *grid)],
            f"(time, axis, z, y, x) = {(n['time'], 3, *grid)!r}",
        )
    if problems:
        raise ValueError("; ".join(problems))
