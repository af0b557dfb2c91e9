"""Label volumes from datasets, NetCDF files and NIfTI files.

A label volume is an :class:`xarray.DataArray` with dims ``(z, y, x)`` and voxel-centre
coordinates in mm: an integer label per voxel (0 = background) or a tissue fraction in
[0, 1]. NIfTI files need nibabel (``pip install "harpx[nifti]"``).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import xarray as xr

__all__ = ["read_labels"]


def read_labels(source: Any, *, variable: str | None = None) -> xr.DataArray:
    """A label volume ``(z, y, x)`` with coordinates in mm from a dataset, array or file.

    Parameters
    ----------
    source : xarray.Dataset, xarray.DataArray, str or os.PathLike
        A dataset (``variable``, else its ``body`` fraction, else its only ``(z, y, x)``
        variable), a DataArray with dims ``(z, y, x)``, a NetCDF file (read like a dataset)
        or a NIfTI file (``.nii``/``.nii.gz``, needs nibabel). NIfTI voxel axes must be
        aligned with the scanner axes (a diagonal affine); its RAS coordinates become the
        DICOM patient (LPS) coordinates that :func:`harpx.io.dicom.read_tagged` uses
        (``x = -R``, ``y = -A``, ``z = S``), so a mask drawn on the same scan lines up.
    variable : str, optional
        Name of the label variable in a dataset or NetCDF file.

    Returns
    -------
    xarray.DataArray
        Labels or fractions with increasing coordinates ``z``, ``y``, ``x`` (mm).

    Raises
    ------
    ValueError
        If no label variable can be chosen, its dims are not ``(z, y, x)`` or a NIfTI
        affine is oblique.
    ImportError
        For a NIfTI file without nibabel (``pip install "harpx[nifti]"``).
    """
    if isinstance(source, str | os.PathLike):
        name = os.fspath(source)
        if name.endswith((".nii", ".nii.gz")):
            return _read_nifti(name)
        with xr.open_dataset(name) as opened:
            return read_labels(opened.load(), variable=variable)
    if isinstance(source, xr.Dataset):
        grid = [k for k, v in source.data_vars.items() if set(v.dims) == {"z", "y", "x"}]
        if variable is None:
            if "body" in source.data_vars:
                variable = "body"
            elif len(grid) == 1:
                variable = str(grid[0])
            else:
                raise ValueError(
                    f"cannot tell which variable holds the labels (candidates {grid!r}); "
                    "pass variable='...'"
                )
        if variable not in source.data_vars:
            raise ValueError(f"variable={variable!r} is not in the dataset ({list(source)!r})")
        source = source[variable]
    if not isinstance(source, xr.DataArray):
        raise TypeError(
            f"labels must be an xarray Dataset/DataArray or a file path, got "
            f"{type(source).__name__!r}"
        )
    if set(source.dims) != {"z", "y", "x"}:
        raise ValueError(
            f"labels have dims {source.dims!r}; expected ('z', 'y', 'x') (select one frame "
            "or tag first)"
        )
    out = source.transpose("z", "y", "x")
    return out.sortby(["z", "y", "x"])


def _read_nifti(path: str) -> xr.DataArray:
    try:
        import nibabel
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            f"reading the NIfTI file {path!r} needs nibabel: pip install 'harpx[nifti]' "
            "(or pip install nibabel)"
        ) from exc
    image = nibabel.load(path)
    data = np.asarray(image.dataobj)
    if data.ndim != 3:
        raise ValueError(f"NIfTI file {path!r} holds a {data.ndim}-D image; expected 3-D labels")
    affine = np.asarray(image.affine, dtype=np.float64)
    linear = affine[:3, :3]
    if np.abs(linear - np.diag(np.diag(linear))).max() > 1e-6 * np.abs(linear).max():
        raise ValueError(
            f"NIfTI file {path!r} has an oblique affine; resample it onto scanner axes first"
        )
    sign = np.array([-1.0, -1.0, 1.0])  # RAS -> LPS
    coords = [sign[a] * (affine[a, 3] + linear[a, a] * np.arange(data.shape[a])) for a in range(3)]
    da = xr.DataArray(
        data.transpose(2, 1, 0), dims=("z", "y", "x"),
        coords={"z": coords[2], "y": coords[1], "x": coords[0]},
    )  # fmt: skip
    return da.sortby(["z", "y", "x"])
