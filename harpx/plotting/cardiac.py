"""Clinical figures of a cardiac strain result: the AHA bull's-eye and segment curves.

The bull's-eye follows the standard layout of Cerqueira et al. (2002): the left ventricle
seen from the apex, anterior at the top, septum on the left, lateral wall on the right,
inferior wall at the bottom; rings from outside in basal (1–6), mid (7–12), apical (13–16)
and the apex (17), numbered counter-clockwise from the anterior segment, which is centred
at the top. The angle that tied the segments to the anatomy (``anterior``) was used when
:func:`~harpx.cardiac.strain.cardiac_strain` assigned cells to segments; the figure names
it. Dimensionless values (strains) are drawn in %. Segments without data are left blank;
components that the tags did not observe (``strain_source``, see
:mod:`harpx.cardiac.quality`) are hatched: the model inferred them.

References
----------
.. [1] Cerqueira MD et al. Standardized myocardial segmentation and nomenclature for
   tomographic imaging of the heart. Circulation 105:539--542, 2002.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from matplotlib import patheffects
from matplotlib.patches import Wedge

from harpx.cardiac.strain import AHA_NAMES
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.plotting._common import _nearest, _number

__all__ = ["RINGS", "bullseye", "segment_curves", "segment_wedges"]

#: ring name -> (segments, inner radius, outer radius) of the bull's-eye (outer radius 1)
RINGS: dict[str, tuple[range, float, float]] = {
    "basal": (range(1, 7), 0.75, 1.0),
    "mid": (range(7, 13), 0.5, 0.75),
    "apical": (range(13, 17), 0.25, 0.5),
    "apex": (range(17, 18), 0.0, 0.25),
}
_TITLES = {
    "peak_strain": "peak {c} strain (Green-Lagrange)",
    "peak_engineering_strain": "peak {c} strain (engineering)",
    "segment_strain": "{c} strain (Green-Lagrange)",
    "segment_engineering_strain": "{c} strain (engineering)",
    "peak_time": "time of peak {c} strain",
}
# hatch of a segment whose component the tags did not fully observe
_HATCH = {"inferred": "////", "partly inferred": "//"}


def segment_wedges() -> dict[int, tuple[float, float, float, float]]:
    """Where each AHA segment sits in the bull's-eye.

    Returns
    -------
    dict of int to tuple
        Segment k -> ``(inner radius, outer radius, start angle, end angle)``, radii in
        units of the outer radius, angles in degrees counter-clockwise from east (the
        screen's +x), e.g. segment 1 spans 60°–120° (top) and 10 spans 240°–300°
        (bottom); the apex (17) is the full disc.
    """
    out: dict[int, tuple[float, float, float, float]] = {}
    for ids, r0, r1 in RINGS.values():
        width = 360.0 / len(ids)
        for j, k in enumerate(ids):  # one sector per segment, the anterior one at 90°
            centre = 90.0 + width * j
            out[k] = (r0, r1, centre - width / 2.0, centre + width / 2.0)
    return out


def _select(
    values: xr.Dataset | xr.DataArray | Sequence[float],
    variable: str,
    component: str | None,
    time: float | None,
) -> tuple[Any, str, str, str]:
    """The 17-value DataArray (or numbers), its title, the frame it shows and its component.

    A dataset's variable is titled by what it is; a DataArray given as such is not titled by
    its name or attributes, which arithmetic keeps (an error against a truth keeps the name
    and ``long_name`` of the strain), only by its component and frame."""
    da: Any = values
    when = ""
    plot = "bullseye"
    trusted = isinstance(da, xr.Dataset)
    if isinstance(da, xr.Dataset):
        if variable not in da:
            raise ValueError(f"the dataset has no {variable!r}; run cardiac_strain first")
        if "time" in da.coords and "time" not in da[variable].dims and da.sizes["time"] > 1:
            when = f"peak over t = {float(da.time[0]):.0f}-{float(da.time[-1]):.0f} ms"
        da = da[variable]
    if not isinstance(da, xr.DataArray):
        if component is not None:
            raise ValueError(
                f"{plot}: component={component!r} cannot be selected from plain numbers; "
                "pass the 17 values of that component without component="
            )
        return da, "", when, ""
    if "component" in da.dims:
        da = da.sel(component="circumferential" if component is None else component)
    elif component is not None:
        has = "component" in da.coords and da["component"].ndim == 0
        if not has or str(da["component"].item()) != component:
            what = f"holds {str(da['component'].item())!r}" if has else "has no 'component'"
            raise ValueError(
                f"{plot}: component={component!r} cannot be selected: the DataArray {what}; "
                "pass the array with its 'component' dim, or drop component="
            )
    if "time" in da.dims:
        if time is None:
            raise ValueError(
                "select one frame first (time=... or .isel(time=-1)): the values have 'time'"
            )
        shown, note = _nearest(da["time"].values, "time", float(time), plot)
        da = da.sel(time=shown)
        when = "\n".join([f"t = {_number(shown)} ms", *([note] if note else [])])
    elif time is not None:
        raise ValueError(
            f"{plot}: time={time!r} cannot be selected: the values have no 'time' dim "
            f"({when or 'one value per segment'}); drop time= or pass a variable with "
            "'time', e.g. variable='segment_strain'"
        )
    elif "time" in da.coords and da["time"].ndim == 0:
        when = f"t = {_number(float(da['time']))} ms"
    named = "component" in da.coords and da["component"].ndim == 0
    c = str(da["component"].item()) if named else ""
    if not trusted:
        return da, " ".join(p for p in (c, "value") if p), when, c
    long_name = da.attrs.get("long_name", variable)
    title = _TITLES.get(variable, str(long_name))
    return da, title.format(c=c).strip().replace("  ", " "), when, c


def _units(
    v: np.ndarray, units: str | None, given: Any, plot: str = "bullseye"
) -> tuple[bool, str, str]:
    """Whether values ``v`` are drawn in % (dimensionless), their unit as drawn, and a
    caption note when that rests on an assumption. ``units``: as the caller gives them;
    ``given``: the data's ``units`` attribute (None for plain numbers)."""
    stated = units if units is not None else given
    if stated is not None:
        dimensionless = str(stated) in ("", "1")
        return dimensionless, "%" if dimensionless else str(stated), ""
    finite = np.abs(v[np.isfinite(v)])
    if finite.size and float(finite.max()) > 1.0:
        warnings.warn(
            f"{plot}: the values state no units and reach {float(finite.max()):.4g}; they are "
            f"drawn as dimensionless strains in % (up to {100 * float(finite.max()):.4g} %); "
            "pass units= (e.g. units='ms' for times, units='1' for strains)",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
        return True, "%", "no units given: drawn as strain (%)"
    return True, "%", ""


def _label(ax: Any, k: int, wedge: tuple[float, ...], value: str, face: Any) -> None:
    """Segment number (and value) at the centre of a wedge, legible on its colour."""
    r0, r1, a0, a1 = wedge
    mid = np.deg2rad(0.5 * (a0 + a1))
    rm = 0.5 * (r0 + r1) if r0 else 0.0
    x, y = rm * np.cos(mid), rm * np.sin(mid)
    rgb = np.asarray(matplotlib.colors.to_rgb(face))
    ink = "white" if float(rgb @ [0.299, 0.587, 0.114]) < 0.5 else "black"
    # a halo of the face colour hides the hatching behind the text
    halo = [patheffects.withStroke(linewidth=2.5, foreground=face)]
    style = {"ha": "center", "va": "center", "color": ink, "path_effects": halo}
    ax.text(x, y + (0.05 if value else 0.0), str(k), fontsize=6.5, fontweight="bold", **style)
    if value:
        ax.text(x, y - 0.045, value.replace("-", "\u2212"), fontsize=7.5, **style)


def bullseye(
    values: xr.Dataset | xr.DataArray | Sequence[float],
    *,
    variable: str = "peak_strain",
    component: str | None = None,
    time: float | None = None,
    units: str | None = None,
    ax: Any = None,
    cmap: str = "RdBu_r",
    vmin: float | None = None,
    vmax: float | None = None,
    label: str | None = None,
    title: str | None = None,
    annotate: bool = True,
) -> Any:
    """AHA 17-segment bull's-eye of one value per segment, in the standard orientation.

    Anterior at the top, septum on the left (see the module notes and
    :func:`segment_wedges`); segment numbers in every segment, values in % for
    dimensionless quantities (others in their own units, e.g. ms), blank segments without
    data, hatched segments whose component the model inferred, a colour bar with units, a
    title naming the quantity and the frame (or the peak). The radial component of a result
    whose ``attrs["radial_strain_caution"]`` is set says "under-reported" in its caption.
    A DataArray is titled by its component and frame only, not by its name or attributes
    (arithmetic keeps them: a difference of two strains keeps the strain's name); give
    ``title`` and ``label`` to say what it is.

    Parameters
    ----------
    values : xarray.Dataset, xarray.DataArray or sequence of 17 floats
        A dataset from :func:`harpx.cardiac.strain.cardiac_strain` (``variable``,
        ``component`` and ``time`` select the value), a DataArray with a ``segment`` dim
        (1..17; its ``strain_source`` coordinate, if any, gives the hatching), or 17 numbers
        (segment 1 first).
    variable : str, default "peak_strain"
        Variable of a dataset.
    component : str, optional
        ``component`` to select from a dataset or DataArray with that dim (default
        ``"circumferential"``); a DataArray already reduced to one component must hold
        this one.
    time : float, optional
        Frame (ms) of a variable with a ``time`` dim (required for those, refused for
        others); the nearest frame is shown and named in the title.
    units : str, optional
        Units of the values: ``"1"`` (dimensionless, drawn in %) or any other (drawn as
        given, e.g. ``"ms"``). Default the ``units`` attribute of the data; values without
        one (plain numbers) are taken as dimensionless strains.
    ax : matplotlib.axes.Axes, optional
        Axes to draw in (default: a new figure).
    cmap : str, default "RdBu_r"
        Colour map.
    vmin, vmax : float, optional
        Colour limits in the drawn unit (default symmetric about 0 over the finite values).
    label : str, optional
        Colour-bar label (default the quantity and its unit).
    title : str, optional
        Title (default the quantity, component and frame).
    annotate : bool, default True
        Write each segment's value in it.

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding the axes; each segment is a
        :class:`~matplotlib.patches.Wedge` with ``gid`` ``"aha-<k>"``, its hatching one
        with ``gid`` ``"aha-<k>-inferred"``.

    Raises
    ------
    ValueError
        If there are not 17 values, the dataset lacks ``variable``, a frame is needed
        (``time``) or given to values without frames, ``time`` is not a finite number, or
        ``component`` cannot be selected from the values.

    Warns
    -----
    HarpxWarning
        If the frame shown, the nearest to ``time``, lies more than half the frame
        interval away from it (``time`` outside the data); or the values state no units
        and exceed 1 in magnitude, so that taking them as strains is doubtful (the caption
        says so too).

    Examples
    --------
    Sixteen segment strains from -0.20 to -0.05 and no value for the apex (17):

    >>> import matplotlib.pyplot as plt
    >>> from harpx.plotting.cardiac import bullseye
    >>> fig = bullseye([*np.linspace(-0.20, -0.05, 16), np.nan], title="peak strain")
    >>> ax = fig.axes[0]
    >>> len(ax.patches), ax.patches[0].get_gid()
    (17, 'aha-1')
    >>> [t.get_text() for t in ax.texts][:4]  # segment number, then its value in %
    ['1', '−20.0', '2', '−19.0']
    >>> ax.texts[-1].get_text(), fig.axes[1].get_ylabel()  # caption, colour bar
    ('blank: no data', 'value (%)')
    >>> plt.close(fig)
    """
    da, quantity, when, shown_component = _select(values, variable, component, time)
    source: Any = None
    anterior = ""
    given: Any = None
    if isinstance(da, xr.DataArray):
        if "segment" in da.dims and da.sizes["segment"] == 17 and "segment" in da.coords:
            da = da.sel(segment=np.arange(1, 18))
        if "strain_source" in da.coords and da["strain_source"].dims == ("segment",):
            source = np.asarray(da["strain_source"].values, dtype=str)
        given = da.attrs.get("units")
    if isinstance(values, xr.Dataset) and "anterior_deg" in values.attrs:
        anterior = (
            f"anterior {float(values.attrs['anterior_deg']):g}° from the template's x axis "
            f"({values.attrs.get('anterior_source', 'given')})"
        )
    v = np.asarray(da, dtype=np.float64).ravel()
    if v.size != 17:
        raise ValueError(f"bullseye needs 17 segment values, got {v.size}")
    percent, unit, assumed = _units(v, units, given)
    shown = 100.0 * v if percent else v
    finite = shown[np.isfinite(shown)]
    if finite.size and (percent or finite.min() < 0.0):
        bound = float(np.abs(finite).max()) or 1.0
        lo, hi = -bound, bound
    else:
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    norm = matplotlib.colors.Normalize(lo if vmin is None else vmin, hi if vmax is None else vmax)
    colours = matplotlib.colormaps[cmap]
    if ax is None:
        ax = plt.subplots(figsize=(5.4, 4.8), layout="constrained")[1]
    notes = set()
    for k, (r0, r1, a0, a1) in segment_wedges().items():  # 17 segments
        value = shown[k - 1]
        face = colours(norm(value)) if np.isfinite(value) else "white"
        ax.add_patch(Wedge((0, 0), r1, a0, a1, width=r1 - r0 if r0 else None, fc=face,
                           ec="k", lw=0.8, gid=f"aha-{k}"))  # fmt: skip
        status = "" if source is None else str(source[k - 1])
        if np.isfinite(value) and status in _HATCH:
            ax.add_patch(Wedge((0, 0), r1, a0, a1, width=r1 - r0 if r0 else None, fill=False,
                               hatch=_HATCH[status], ec="0.4", lw=0.0, hatch_linewidth=0.7,
                               gid=f"aha-{k}-inferred"))  # fmt: skip
            notes.add("hatched: inferred by the model, not observed by the tags")
        if not np.isfinite(value):
            notes.add("blank: no data")
        text = f"{value:.1f}" if percent else f"{value:.3g}"
        _label(ax, k, (r0, r1, a0, a1), text if annotate and np.isfinite(value) else "", face)
    for (x, y, rot), name in zip(
        ((0, 1.1, 0), (-1.1, 0, 90), (0, -1.1, 0), (1.1, 0, -90)),
        ("anterior", "septal", "inferior", "lateral"),
        strict=True,
    ):
        ax.text(x, y, name, ha="center", va="center", rotation=rot, fontsize=8, color="0.3")
    ax.set(xlim=(-1.22, 1.22), ylim=(-1.22, 1.22), aspect="equal")
    ax.axis("off")
    heading = title if title is not None else "\n".join(p for p in (quantity, when) if p)
    ax.set_title(heading, fontsize=10)
    if shown_component == "radial" and _radial_caution(values):
        notes.add("under-reported: see attrs['radial_strain_caution']")
    if assumed:
        notes.add(assumed)
    caption = "; ".join([*sorted(notes), *([anterior] if anterior else [])])
    if caption:
        ax.text(0.5, -0.02, caption, transform=ax.transAxes, ha="center", va="top",
                fontsize=7, color="0.3", wrap=True)  # fmt: skip
    mappable = matplotlib.cm.ScalarMappable(norm=norm, cmap=colours)
    short = quantity.split(" (")[0] if quantity else "value"
    name = label if label is not None else f"{short} ({unit})"
    ax.figure.colorbar(mappable, ax=ax, label=name, shrink=0.8)
    return ax.figure


def segment_curves(
    ds: xr.Dataset,
    *,
    component: str = "circumferential",
    variable: str = "segment_strain",
) -> Any:
    """Segment values over time, one panel per ring (basal, mid, apical, apex).

    Parameters
    ----------
    ds : xarray.Dataset
        A result of :func:`harpx.cardiac.strain.cardiac_strain`.
    component : str, default "circumferential"
        Strain component.
    variable : str, default "segment_strain"
        A (time, segment, component) variable, e.g. ``"segment_engineering_strain"``.

    Returns
    -------
    matplotlib.figure.Figure
        Four panels sharing the value axis (in % for strains); segments the model inferred
        are dashed and labelled "inferred", partly inferred ones dotted; segments without
        data are not drawn and are named in their panel's title. The radial component of
        a result whose ``attrs["radial_strain_caution"]`` is set says so in the title.

    Raises
    ------
    ValueError
        If the dataset lacks ``variable`` or it has no ``time`` and ``segment`` dims.
    """
    if not isinstance(ds, xr.Dataset) or variable not in ds:
        raise ValueError(f"segment_curves needs {variable!r} of a cardiac_strain result")
    da = ds[variable]
    if not {"time", "segment"} <= set(da.dims):
        raise ValueError(f"{variable!r} has dims {da.dims}; expected time and segment")
    if "component" in da.dims:
        da = da.sel(component=component)
    percent = da.attrs.get("units") in (None, "", "1")
    scale, unit = (100.0, "%") if percent else (1.0, str(da.attrs.get("units")))
    source = (
        np.asarray(da["strain_source"].values, dtype=str)
        if "strain_source" in da.coords and da["strain_source"].dims == ("segment",)
        else np.full(da.sizes["segment"], "", dtype="<U15")
    )
    index = {int(k): i for i, k in enumerate(da["segment"].values)}
    times = np.asarray(da["time"].values, dtype=np.float64)
    values = np.asarray(da.transpose("time", "segment").values, dtype=np.float64) * scale
    fig, axes = plt.subplots(1, 4, figsize=(12.5, 4.2), sharey=True, layout="constrained")
    styles = {"inferred": "--", "partly inferred": ":"}
    for ax, (ring, (ids, _, _)) in zip(axes, RINGS.items(), strict=True):  # four rings
        missing = []
        for j, k in enumerate(ids):  # up to six segments
            i = index.get(k)
            if i is None or not np.isfinite(values[:, i]).any():
                missing.append(str(k))
                continue
            status = source[i]
            name = AHA_NAMES[k - 1].removeprefix(f"{ring} ") if k < 17 else "apex"
            tag = f" ({status})" if status in styles else ""
            ax.plot(times, values[:, i], styles.get(status, "-"), color=f"C{j}", lw=1.4,
                    label=f"{k} {name}{tag}")  # fmt: skip
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_title(f"{ring}" + (f"\nno data: {', '.join(missing)}" if missing else ""),
                     fontsize=10)  # fmt: skip
        ax.set_xlabel("time (ms)")
        if ax.get_lines()[:-1]:
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2)
    quantity = _TITLES.get(variable, str(da.attrs.get("long_name", variable)))
    axes[0].set_ylabel(f"{quantity.format(c=component)} ({unit})")
    caution = component == "radial" and _radial_caution(ds)
    fig.suptitle(f"{quantity.format(c=component)} per AHA segment"
                 + (" (likely under-reported: attrs['radial_strain_caution'])" if caution else ""),
                 fontsize=11)  # fmt: skip
    return fig


def _radial_caution(values: Any) -> bool:
    """Whether a cardiac_strain result flags its radial strain as under-reported."""
    return isinstance(values, xr.Dataset) and bool(values.attrs.get("radial_strain_caution"))
