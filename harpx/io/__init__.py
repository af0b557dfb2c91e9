"""Input and output: NetCDF archives (:mod:`harpx.io.netcdf`) and other file formats.

Import the submodule you need, e.g. ``from harpx.io.netcdf import open_dataset, to_netcdf``;
``harpx.open_dataset`` and ``ds.harp.to_netcdf`` forward to it.
"""

from __future__ import annotations
