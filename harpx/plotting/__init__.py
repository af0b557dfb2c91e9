"""Figures (matplotlib): slices of harpx datasets, cardiac strain, comparison figures.

The functions draw with :mod:`matplotlib.pyplot` and never select or switch the matplotlib
backend: in a notebook the figures show inline, in a script they go wherever the user's
backend sends them (``plt.show()``, ``fig.savefig``). New figures use constrained layout and
sizes that keep every title, label and colour bar inside the figure. Each function names
the dataset kind it draws; any other kind raises :class:`~harpx.errors.SchemaError` naming
the expected and the actual kind.

The modules: :mod:`harpx.plotting.maps` (one slice of a dataset, behind ``ds.harp.plot``),
:mod:`harpx.plotting.strain` (strain on a slice, radial/circumferential/longitudinal or
Cartesian), :mod:`harpx.plotting.regions` (fibre stretch per region),
:mod:`harpx.plotting.cardiac` (the AHA bull's-eye and segment curves) and
:mod:`harpx.plotting.figures` (method comparisons, run time, opening angle, stretch
agreement); every public name is importable from :mod:`harpx.plotting`.
"""

from __future__ import annotations

from harpx.plotting.cardiac import bullseye, segment_curves, segment_wedges
from harpx.plotting.figures import (
    displacement_maps,
    error_vs_runtime,
    opening_angle_view,
    plot_stretch_agreement,
)
from harpx.plotting.maps import displacement_map, phase_map, tag_image
from harpx.plotting.regions import fiber_stretch_by_region
from harpx.plotting.strain import strain_map

__all__ = [
    "bullseye",
    "displacement_map",
    "displacement_maps",
    "error_vs_runtime",
    "fiber_stretch_by_region",
    "opening_angle_view",
    "phase_map",
    "plot_stretch_agreement",
    "segment_curves",
    "segment_wedges",
    "strain_map",
    "tag_image",
]
