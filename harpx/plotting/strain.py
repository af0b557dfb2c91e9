"""Strain on a slice: the mesh's cells cut by a plane, coloured by one strain component.

A tracked result holds one strain tensor per cell (``green_strain``, Cartesian) and, after
:func:`harpx.cardiac.strain.cardiac_strain`, its radial, circumferential and longitudinal
normal components in the ventricle's local frame (``strain_lv``). :func:`strain_map` cuts
the reference mesh (the geometry at the first frame, where the strain is measured from)
with the plane ``z`` = const of an image slice and draws each cut cell as the polygon of
its cross-section, coloured by its value in % on a diverging colour map centred at 0. The
corners of a cell define its cross-section (straight edges; the mid-edge nodes of hex20 and
tet10 cells are not used).

A tag sees motion along its wave vector only; a component the tags did not observe in a
cell was inferred by the mechanical model (:mod:`harpx.cardiac.quality`: the fraction of
the direction the tags see, ``strain_lv_observed`` for the cardiac components and
``observed_fraction`` of the two axes for a Cartesian one). Such cells are hatched, and
when every cell on the slice is, the title says that the component is inferred.
"""

from __future__ import annotations

import warnings
from typing import Any

import matplotlib
import numpy as np
import xarray as xr
from matplotlib.collections import PolyCollection

from harpx.cardiac.quality import source_labels
from harpx.conventions import ELEMENT_CORNERS
from harpx.errors import HarpxWarning, SchemaError, user_stacklevel
from harpx.plotting._common import _axes, _map_doc, _nearest, _number, _require

__all__ = ["CARDIAC_COMPONENTS", "CARTESIAN_COMPONENTS", "strain_map", "strain_on_slice"]

#: cardiac component name -> index in ``strain_lv``'s ``component`` dim, and subscript
CARDIAC_COMPONENTS: dict[str, tuple[int, str]] = {
    "radial": (0, "rr"),
    "circumferential": (1, "cc"),
    "longitudinal": (2, "ll"),
}
#: Cartesian component name -> (i, j) of ``green_strain``
CARTESIAN_COMPONENTS: dict[str, tuple[int, int]] = {
    "xx": (0, 0), "yy": (1, 1), "zz": (2, 2), "xy": (0, 1), "xz": (0, 2), "yz": (1, 2),
}  # fmt: skip
# other spellings: Err, E_rr, rr, Exy, E_yx, yx, ...
_ALIASES = {
    **{f"{p}{s}": name for name, (_, s) in CARDIAC_COMPONENTS.items() for p in ("E", "E_", "")},
    **{f"{p}{a}{b}": f"{min(a, b)}{max(a, b)}"
       for a in "xyz" for b in "xyz" for p in ("E", "E_", "")},
}  # fmt: skip
# corner vertices of each element kind, and the edges between them (VTK order)
_EDGES = {
    8: ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4),
        (0, 4), (1, 5), (2, 6), (3, 7)),
    6: ((0, 1), (1, 2), (2, 0), (3, 4), (4, 5), (5, 3), (0, 3), (1, 4), (2, 5)),
    4: ((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)),
}  # fmt: skip
# hatch of a cell whose component the tags did not fully observe
_HATCH = {"inferred": "////", "partly inferred": "//"}


def _component(ds: xr.Dataset, component: str | None, i: int | None, j: int | None) -> str:
    """The canonical component name ("circumferential", "xy", ...) asked for."""
    if i is not None or j is not None:
        if component is not None:
            raise ValueError(f"strain_map: give component={component!r} or i, j, not both")
        a, b = (0 if i is None else i), (0 if j is None else j)
        if a not in (0, 1, 2) or b not in (0, 1, 2):
            raise ValueError(f"strain_map: i and j must be 0, 1 or 2 (x, y, z); got {i!r}, {j!r}")
        return "xyz"[min(a, b)] + "xyz"[max(a, b)]
    if component is None:
        return "circumferential" if "strain_lv" in ds else "xx"
    name = _ALIASES.get(str(component), str(component))
    if name not in CARDIAC_COMPONENTS and name not in CARTESIAN_COMPONENTS:
        known = [*CARDIAC_COMPONENTS, *CARTESIAN_COMPONENTS, "Err", "Ecc", "Ell"]
        raise ValueError(f"strain_map: unknown component {component!r}; one of {known}")
    return name


def _cut(points: np.ndarray, cells: np.ndarray, element: str, z: float) -> tuple[list, np.ndarray]:
    """Cross-sections (x, y polygons) of the cells that the plane ``z`` cuts, and their
    indices. A cell counts when its lowest corner is at or below the plane and its highest
    above it, so a plane through a layer of nodes cuts each column of cells once."""
    k = ELEMENT_CORNERS.get(element, 8 if cells.shape[1] >= 8 else cells.shape[1])
    corners = points[cells[:, :k]]  # (n, k, 3)
    scale = float(np.ptp(points, axis=0).max()) or 1.0
    s = corners[..., 2] - z
    s[np.abs(s) < 1e-9 * scale] = 0.0
    hit = np.flatnonzero((s.min(axis=1) <= 0.0) & (s.max(axis=1) > 0.0))
    a, b = (np.array(e) for e in zip(*_EDGES[k], strict=True))
    sa, sb = s[hit][:, a], s[hit][:, b]
    crosses = (np.minimum(sa, sb) <= 0.0) & (np.maximum(sa, sb) >= 0.0) & ((sa != 0) | (sb != 0))
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(crosses, sa / (sa - sb), 0.0)
    xa, xb = corners[hit][:, a, :2], corners[hit][:, b, :2]
    at = xa + t[..., None] * (xb - xa)  # (cut cells, edges, 2)
    polygons, kept = [], []
    for n, cell in enumerate(hit):  # cells on the slice
        p = at[n][crosses[n]]
        p = p[np.unique(np.round(p / (1e-7 * scale)), axis=0, return_index=True)[1]]
        if len(p) < 3:
            continue
        centre = p.mean(axis=0)
        p = p[np.argsort(np.arctan2(p[:, 1] - centre[1], p[:, 0] - centre[0]))]
        polygons.append(p)
        kept.append(cell)
    return polygons, np.asarray(kept, dtype=np.int64)


def strain_on_slice(
    ds: xr.Dataset,
    component: str,
    *,
    time: float | None = None,
    z: float | None = None,
    plot: str = "strain_on_slice",
) -> dict[str, Any]:
    """What :func:`strain_map` draws: the cut cells, their strain and where it came from.

    Parameters
    ----------
    ds : xarray.Dataset
        ``tracked/1`` dataset with ``points``, ``cells`` and ``green_strain`` (and
        ``strain_lv`` for a cardiac component).
    component : str
        ``"radial"``, ``"circumferential"``, ``"longitudinal"`` (also ``"Err"``,
        ``"Ecc"``, ``"Ell"``) or a Cartesian ``"xx"``, ``"yy"``, ``"zz"``, ``"xy"``,
        ``"xz"``, ``"yz"`` (also ``"E_xy"``, ``"yx"``).
    time : float, optional
        Frame time, ms (default the last; nearest frame).
    z : float, optional
        Slice position, mm (default the middle of the mesh); the nearest slice of the
        image grid (``z`` coordinate) when the dataset has one.
    plot : str
        Name of the caller, for messages.

    Returns
    -------
    dict
        ``polygons`` (list of (k, 2) arrays, mm), ``cells`` (int array), ``values``
        (strain of those cells, dimensionless), ``source`` (per cell ``"observed"``,
        ``"partly inferred"``, ``"inferred"`` or ``"not recorded"``), ``component``,
        ``time`` and ``z`` shown (ms, mm) and ``notes`` (title notes on what was asked).

    Raises
    ------
    SchemaError
        If ``ds`` is not a finite-element ``tracked/1`` dataset, or a cardiac component is
        asked of a dataset without ``strain_lv``.
    ValueError
        If the component is unknown or the plane ``z`` does not cut the mesh.
    """
    _require(ds, "tracked", ["green_strain", "points", "cells"], plot)
    name = _component(ds, component, None, None)
    cardiac = name in CARDIAC_COMPONENTS
    if cardiac and "strain_lv" not in ds:
        raise SchemaError(
            f"{plot}: the {name} strain needs 'strain_lv' (the strain in the ventricle's "
            "frame); compute it with ds.harp.cardiac_strain(template) and plot that result"
        )
    points = np.asarray(ds["points"].values, dtype=np.float64)
    cells = np.asarray(ds["cells"].values, dtype=np.int64)
    element = str(ds["cells"].attrs.get("element", "hex8"))
    k = ELEMENT_CORNERS.get(element, min(cells.shape[1], 8))
    low, high = points[cells[:, :k], 2].min(), points[cells[:, :k], 2].max()
    notes: list[str] = []
    if z is None:
        z = 0.5 * (low + high)
        if "z" in ds.coords and ds["z"].size:
            z, _ = _nearest(ds["z"].values, "z", z, plot)
    elif "z" in ds.coords and ds["z"].size:
        z, note = _nearest(ds["z"].values, "z", float(z), plot)
        notes += [note] if note else []
    z = float(z)
    polygons, cut = _cut(points, cells, element, z)
    if not cut.size:
        raise ValueError(
            f"{plot}: the plane z = {_number(z)} mm does not cut the mesh, which spans "
            f"z = {_number(low)} to {_number(high)} mm"
        )
    data = ds["strain_lv"] if cardiac else ds["green_strain"]
    if time is None:
        data = data.isel(time=-1)
    else:
        shown, note = _nearest(data["time"].values, "time", float(time), plot)
        data = data.sel(time=shown)
        notes += [note] if note else []
    if cardiac:
        index = CARDIAC_COMPONENTS[name][0]
        values = np.asarray(data.transpose("cell", "component").values)[cut, index]
        seen = (
            np.asarray(ds["strain_lv_observed"].transpose("cell", "component").values)[cut, index]
            if "strain_lv_observed" in ds
            else np.full(cut.size, np.nan)
        )
    else:
        i, j = CARTESIAN_COMPONENTS[name]
        values = np.asarray(data.transpose("cell", "i", "j").values)[cut, i, j]
        if "observed_fraction" in ds:
            fraction = ds["observed_fraction"].transpose("cell", "axis")
            if "axis" in fraction.coords:
                fraction = fraction.sel(axis=["x", "y", "z"])
            f = np.asarray(fraction.values, dtype=np.float64)
            seen = np.minimum(f[cut, i], f[cut, j])
        else:
            seen = np.full(cut.size, np.nan)
    return {
        "polygons": polygons, "cells": cut, "values": values.astype(np.float64),
        "source": source_labels(seen), "component": name, "z": z,
        "time": float(data["time"]) if "time" in data.coords else np.nan, "notes": notes,
    }  # fmt: skip


@_map_doc(
    "tracked",
    "green_strain",
    "points",
    "cells",
    value_errors=", the component is unknown, or ``vmax`` is not a positive number",
)
def strain_map(
    ds: xr.Dataset,
    *,
    component: str | None = None,
    time: float | None = None,
    z: float | None = None,
    vmax: float | None = None,
    i: int | None = None,
    j: int | None = None,
    ax: Any = None,
) -> Any:
    """Green–Lagrange strain on a slice: the cells cut by the plane ``z``, in %.

    Radial, circumferential or longitudinal strain of a cardiac strain result
    (:func:`harpx.cardiac.strain.cardiac_strain`), or a Cartesian component of any
    tracked result, on the reference mesh (module notes). Diverging colour map centred
    at 0 with symmetric limits; a colour bar in %; a title naming the component, the
    frame and the slice shown (and the slice asked for, when the nearest image slice is
    another); cells where the tags did not observe the component are hatched ("inferred"
    in the title when all are).

    Parameters
    ----------
    ds : xarray.Dataset
        ``tracked/1`` dataset with a mesh (``points``, ``cells``) and ``green_strain``;
        for the cardiac components also ``strain_lv`` (a ``cardiac_strain`` result).
    component : str, optional
        ``"radial"``, ``"circumferential"``, ``"longitudinal"`` (or ``"Err"``, ``"Ecc"``,
        ``"Ell"``), or ``"xx"``, ``"yy"``, ``"zz"``, ``"xy"``, ``"xz"``, ``"yz"``
        (or ``"E_xy"``...). Default ``"circumferential"`` for a cardiac strain result,
        else ``"xx"``.
    time : float, optional
        Frame time, ms (default the last; the nearest frame is shown).
    z : float, optional
        Slice position, mm (default the middle of the mesh); the nearest slice of the
        image grid is shown when the dataset has one (its ``z`` coordinate).
    vmax : float, optional
        Colour limit in %, positive (the map spans ``-vmax`` to ``vmax``); default the
        largest absolute value on the slice. Cells without a value (NaN) are blank and
        counted in the title.
    i, j : int, optional
        The Cartesian component as indices (0 = x, 1 = y, 2 = z), instead of
        ``component``.
    """
    plot = "strain_map (ds.harp.plot.strain)"
    if vmax is not None and not (np.isfinite(vmax) and vmax > 0.0):
        raise ValueError(
            f"{plot}: vmax must be a positive number of % (the map spans -vmax to vmax); "
            f"got vmax={vmax!r}; leave it None to span the slice's values"
        )
    name = _component(ds, component, i, j)
    cut = strain_on_slice(ds, name, time=time, z=z, plot=plot)
    values = 100.0 * cut["values"]
    finite = values[np.isfinite(values)]
    bound = (
        float(vmax) if vmax is not None else (float(np.abs(finite).max()) if finite.size else 0.0)
    )
    norm = matplotlib.colors.Normalize(-(bound or 1.0), bound or 1.0)
    ax = _axes(ax, (5.0, 4.4))
    cells = PolyCollection(cut["polygons"], array=values, cmap="RdBu_r", norm=norm,
                           edgecolors="0.35", linewidths=0.3, gid="strain-cells")  # fmt: skip
    ax.add_collection(cells)
    source = np.asarray(cut["source"])
    hatched = [p for p, s in zip(cut["polygons"], source, strict=True) if s in _HATCH]
    for status, hatch in _HATCH.items():
        which = [p for p, s in zip(cut["polygons"], source, strict=True) if s == status]
        if which:
            ax.add_collection(PolyCollection(
                which, facecolors="none", edgecolors="0.3", hatch=hatch, linewidths=0.0,
                gid=f"strain-{status}"))  # fmt: skip
    ax.autoscale_view()
    ax.set(xlabel="x (mm)", ylabel="y (mm)", aspect="equal")
    if name in CARDIAC_COMPONENTS:
        symbol = f"$E_{{{CARDIAC_COMPONENTS[name][1]}}}$"
        quantity = f"{name} strain {symbol}"
    else:
        symbol = f"$E_{{{name}}}$"
        quantity = f"strain {symbol}"
    when = f"t = {_number(cut['time'])} ms, " if np.isfinite(cut["time"]) else ""
    lines = [quantity, f"{when}z = {_number(cut['z'])} mm", *cut["notes"]]
    blank = int(values.size - finite.size)
    if blank and finite.size:  # all blank warns below
        lines.append(f"{blank} of {values.size} cells without a value (blank)")
    inferred = source.size > 0 and all(s in _HATCH for s in source)
    if inferred:
        lines.append("inferred by the model: the tags do not see it")
    elif hatched:
        lines.append("hatched: inferred by the model, not observed by the tags")
    elif source.size and all(s == "not recorded" for s in source):
        lines.append("what the tags observed is not recorded")
    ax.set_title("\n".join(lines), fontsize=10)
    ax.figure.colorbar(cells, ax=ax, label=f"{symbol} (%)", extend="both" if vmax else "neither")
    if not finite.size:
        warnings.warn(f"{plot}: no finite {name} strain on the slice", HarpxWarning,
                      stacklevel=user_stacklevel())  # fmt: skip
    return ax
