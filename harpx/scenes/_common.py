"""Shared pieces of the synthetic scenes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import xarray as xr
from numpy.typing import ArrayLike

from harpx.imaging.stacks import tagged_dataset
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
    image: ArrayLike,
    mask: ArrayLike,
    truth: ArrayLike,
    attrs: dict[str, Any],
    snr: float | None,
    *,
    tag: Sequence[str],
    tag_period: float,
    slice_axis: Sequence[str],
    times: ArrayLike,
    grid: tuple[ArrayLike, ArrayLike, ArrayLike],
    body: ArrayLike,
) -> xr.Dataset:
    """The ``tagged/1`` dataset of a CSPAMM scene resampled to the grid ``(z, y, x)``, mm.

    ``truth`` is the true displacement (mm), ``body`` the body density on the grid; ``attrs``
    gains ``snr`` when one is given (``None``: noise-free).
    """
    if snr is not None:
        attrs["snr"] = float(snr)
    z, y, x = grid
    return tagged_dataset(
        image,
        tag=list(tag),
        tag_frequency=1.0 / tag_period,
        slice_axis=list(slice_axis),
        time=times,
        z=z,
        y=y,
        x=x,
        sequence="CSPAMM",
        mask=mask,
        body=body,
        displacement_true=truth,
        attrs=attrs,
    )
