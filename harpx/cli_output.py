"""What the command line prints: per-frame tables, the warnings of a run, tag periods.

The ``harpx`` commands (:mod:`harpx.cli`) print these; the tables are Markdown with units,
so that ``harpx report`` output pastes into a lab notebook.
"""

from __future__ import annotations

import textwrap
import warnings
from collections.abc import Sequence
from typing import Any

__all__ = ["frames_table", "print_frames", "print_warnings", "tag_periods"]

#: Width of wrapped summary lines.
_WIDTH = 100


def tag_periods(phase: Any) -> str:
    """One line: per tag, the tag period the images show against the stated one (mm); ""
    for a phase without ``tag_frequency_measured``."""
    import numpy as np

    if "tag_frequency_measured" not in phase.variables:
        return ""
    seen = np.asarray(phase["tag_frequency_measured"].values, dtype=float)
    stated = np.asarray(phase["tag_frequency"].values, dtype=float)
    parts = [
        f"{tag} {1 / s:.2f} / {1 / f:.2f}" if np.isfinite(s) and s > 0 else f"{tag} - / {1 / f:.2f}"
        for tag, s, f in zip(np.asarray(phase["tag"].values), seen, stated, strict=True)
    ]
    return "tag period seen in the images / stated (mm; - not measured): " + ", ".join(parts)


def print_frames(ds: Any, title: str | None = None) -> None:
    """What happened in each frame of a tracked dataset (:func:`frames_table`), and a count."""
    if title is None:
        element = ds["cells"].attrs.get("element", "") if "cells" in ds else ""
        title = f"{ds.attrs.get('method', '?')}, {ds.sizes.get('cell', 0)} {element} cells"
    passes = ds.attrs.get("blur_passes_applied")
    blur = f", blur correction {passes} pass{'es' if passes != 1 else ''}" if passes else ""
    print(f"{title}{blur}; per frame:")
    for line in frames_table(ds):
        print(line)
    flags = ("target_reached", "plateau", "converged")
    if all(k in ds for k in flags):
        frames = range(1, ds.sizes["time"])
        missed = [n for n in frames if not bool(ds["target_reached"].values[n])]
        plateau = [n for n in frames if bool(ds["plateau"].values[n])]
        stopped = [n for n in frames if not bool(ds["converged"].values[n])]
        print(
            f"{len(frames)} frames tracked: target missed {_which(missed)}; plateau "
            f"{_which(plateau)}; not converged {_which(stopped)}"
        )


def _which(frames: Sequence[int]) -> str:
    if not frames:
        return "in none"
    return ("in frame " if len(frames) == 1 else "in frames ") + ", ".join(map(str, frames))


def frames_table(ds: Any, *, wall_time: bool = False) -> list[str]:
    """A tracked dataset's per-frame diagnostics as a Markdown table, with units.

    ε and its target for every frame; the penalty, iterations (and ``wall_time``) of the
    tracked frames; and a note: ``reference`` for frame 0, ``target missed``, ``plateau``
    (ε levelled off within what the data allow), ``not converged``. Columns the dataset
    lacks (a HARP result has no target) are left out.
    """
    columns: list[tuple[str, str, str]] = [
        ("epsilon", "epsilon (rad)", "{:.3g}"),
        ("epsilon_target", "target (rad)", "{:.3g}"),
        ("penalty", "penalty (relative)", "{:.3g}"),
        ("iterations", "iterations", "{:.0f}"),
    ]
    if wall_time:
        columns.append(("wall_time", "wall time (s)", "{:.2f}"))
    present = [c for c in columns if c[0] in ds]
    flags = [k for k in ("target_reached", "plateau", "converged") if k in ds]
    header = ["frame", "time (ms)", *(c[1] for c in present), *(["note"] if flags else [])]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for n, t in enumerate(ds["time"].values):
        cells = [str(n), f"{float(t):g}"]
        for name, _, fmt in present:
            tracked_only = name in ("penalty", "iterations", "wall_time")
            cells.append("" if n == 0 and tracked_only else fmt.format(float(ds[name].values[n])))
        if flags:
            notes = ["reference"] if n == 0 else []
            if n and "target_reached" in ds and not bool(ds["target_reached"].values[n]):
                notes.append("target missed")
            if n and "plateau" in ds and bool(ds["plateau"].values[n]):
                notes.append("plateau")
            if n and "converged" in ds and not bool(ds["converged"].values[n]):
                notes.append("not converged")
            cells.append(", ".join(notes))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def print_warnings(caught: Sequence[warnings.WarningMessage]) -> None:
    """The warnings of a run: their count and the first line of each (repeats counted)."""
    counts: dict[str, int] = {}
    for item in caught:
        lines = str(item.message).strip().splitlines()
        key = f"{item.category.__name__}: {lines[0] if lines else ''}"
        counts[key] = counts.get(key, 0) + 1
    if not counts:
        print("warnings: none")
        return
    print(f"warnings ({len(caught)}):")
    for text, count in counts.items():
        repeat = f" (×{count})" if count > 1 else ""
        print(textwrap.fill(text + repeat, _WIDTH, initial_indent="  - ", subsequent_indent="    "))
