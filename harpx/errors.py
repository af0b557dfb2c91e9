"""Exception and warning classes of harpx.

Every error derives from :class:`HarpxError` and, where a builtin fits, from that builtin
too, so users can catch either the family or the builtin (``ValueError``, ``RuntimeError``).
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Sequence

__all__ = [
    "ArchiveError",
    "CoincidentNodesWarning",
    "ConvergenceError",
    "ElementInversionError",
    "HarpxError",
    "HarpxWarning",
    "SchemaError",
    "user_stacklevel",
]


class HarpxError(Exception):
    """Base class of every harpx error."""


class SchemaError(HarpxError, ValueError):
    """A dataset does not follow the harpx conventions.

    Parameters
    ----------
    problems : sequence of str
        One human-readable problem per entry; each names the variable, dimension or
        value that is wrong and how to fix it.
    """

    def __init__(self, problems: Sequence[str] | str) -> None:
        if isinstance(problems, str):
            problems = [problems]
        self.problems: list[str] = list(problems)
        super().__init__("\n".join(self.problems))


class ConvergenceError(HarpxError, RuntimeError):
    """An iterative solver did not reach its tolerance.

    Parameters
    ----------
    message : str
        What failed and what to try.
    history : sequence of float, optional
        Residual norms of the iterations that were run.
    """

    def __init__(self, message: str, history: Sequence[float] = ()) -> None:
        self.history: list[float] = [float(h) for h in history]
        super().__init__(message)


class ElementInversionError(ConvergenceError):
    """Elements inverted (J <= 0) and step cut-back could not recover.

    Parameters
    ----------
    message : str
        What failed and what to try.
    cells : sequence of int
        Ids of the cells with a non-positive Jacobian.
    history : sequence of float, optional
        Residual norms of the iterations that were run.
    """

    def __init__(self, message: str, cells: Iterable[int], history: Sequence[float] = ()) -> None:
        self.cells: list[int] = [int(c) for c in cells]
        super().__init__(message, history)


class ArchiveError(HarpxError, OSError):
    """A NetCDF archive cannot be read or written."""


class HarpxWarning(UserWarning):
    """Base class of harpx warnings."""


class CoincidentNodesWarning(HarpxWarning):
    """A mesh has coincident (unmerged duplicate) nodes: its cells there are not connected.

    Intended for cut bodies (:func:`harpx.physiology.cut.opening_angle`); anywhere else it
    usually means a mesh export did not merge the nodes of its blocks.
    """


def user_stacklevel() -> int:
    """``stacklevel`` for :func:`warnings.warn` that names the first caller outside harpx.

    Call it where the warning is issued: ``warnings.warn(msg, HarpxWarning,
    stacklevel=user_stacklevel())``. The warning then points at the user's line however
    deep inside harpx it was raised (through the accessor, the CLI or helpers).

    Returns
    -------
    int
        Number of frames from the caller of this function up to the first frame whose
        module is not part of harpx (1 when the caller is called from outside harpx).
    """
    frame = sys._getframe(1)
    level = 1
    while frame.f_back is not None and frame.f_globals.get("__name__", "").startswith("harpx."):
        frame = frame.f_back
        level += 1
    return level
