"""Shared pieces of the synthetic scenes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx.imaging.stacks import resample_stacks, tagged_dataset
from harpx.mechanics.body import Body, ElementName
from harpx.mechanics.meshspec import MeshSpec


class MeshScene:
    """What the scenes with one tracking mesh share: :meth:`body`, their tracking model.

    A scene dataclass derives from it and has the fields ``mesh`` and ``material``.
    """

    mesh: MeshSpec
    material: Any
    #: Element order of :meth:`body` unless another is asked for.
    default_element: ClassVar[ElementName] = "hex8"

    def body(self, element: ElementName | None = None, material: Any = None) -> Body:
        """The tracking model: the scene's mesh (with its regions and fibres) and material.

        Parameters
        ----------
        element : {"hex8", "hex20"}, optional
            Element order (default: the scene's ``default_element``).
        material : object, optional
            A material instead of the scene's ``material``.

        Returns
        -------
        Body
        """
        chosen = self.material if material is None else material
        return Body(self.mesh, chosen, element=element or self.default_element)


def cspamm_dataset(
    stacks: Sequence[xr.Dataset],
    grid: tuple[ArrayLike, ArrayLike, ArrayLike],
    truth: ArrayLike,
    attrs: dict[str, Any],
    snr: float | None,
    *,
    body: ArrayLike,
) -> xr.Dataset:
    """The ``tagged/1`` dataset of a CSPAMM scene: its ``stacks`` resampled to the grid
    ``(z, y, x)``, mm (:func:`~harpx.imaging.stacks.resample_stacks`).

    The tags (labels, directions, frequencies, slice axes) are those of the stacks, in order,
    and the frame times those of the first. ``truth`` is the true displacement (mm) and
    ``body`` the body density on the grid; ``attrs`` gains ``snr`` when one is given
    (``None``: noise-free).
    """
    if snr is not None:
        attrs["snr"] = float(snr)
    z, y, x = grid
    image, mask = resample_stacks(stacks, x, y, z)

    def per_tag(name: str) -> Any:
        return np.concatenate([np.asarray(ds[name].values) for ds in stacks])

    return tagged_dataset(
        image,
        tag=[str(t) for t in per_tag("tag")],
        tag_direction=per_tag("tag_direction"),
        tag_frequency=per_tag("tag_frequency"),
        slice_axis=[str(a) for a in per_tag("slice_axis")],
        time=stacks[0]["time"].values,
        z=z,
        y=y,
        x=x,
        sequence="CSPAMM",
        mask=mask,
        body=body,
        displacement_true=truth,
        attrs=attrs,
    )
