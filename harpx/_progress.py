"""When to show a progress bar: one rule for the Python API and the ``harpx`` command.

``progress=None`` (the default of the long-running calls that take it) means *auto*: a bar
is shown when someone is watching, i.e. when standard error is a terminal or the code runs
in a Jupyter kernel, and only once the call has run for :data:`DELAY` seconds, so that quick
calls print nothing. ``True`` and ``False`` force it on or off. Bars come from
:mod:`tqdm.auto` (a widget in notebooks when ipywidgets is installed, text otherwise).

Examples
--------
>>> show_progress(False), show_progress(True)
(False, True)
>>> with progress_bar(total=3, progress=False) as bar:
...     bar.update(3)
...     bar.disable
True
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from typing import Any

from tqdm.auto import tqdm

__all__ = ["DELAY", "in_notebook", "progress_bar", "show_progress"]

#: Seconds a call runs before its automatic (``progress=None``) bar appears.
DELAY = 2.0


def in_notebook() -> bool:
    """Whether the code runs in a Jupyter kernel (IPython is only inspected if imported).

    Returns
    -------
    bool
        True inside a Jupyter kernel (``IPKernelApp``), False in a plain interpreter, an
        IPython terminal or when IPython is not loaded.
    """
    ipython = sys.modules.get("IPython")
    if ipython is None:
        return False
    try:
        shell = ipython.get_ipython()
        return shell is not None and "IPKernelApp" in shell.config
    except Exception:  # an unusual IPython set-up: treat as no notebook
        return False


def show_progress(progress: bool | None = None) -> bool:
    """Resolve a ``progress`` argument to on or off.

    Parameters
    ----------
    progress : bool or None, default None
        True or False: as given. None: on when standard error is a terminal or the code
        runs in a Jupyter notebook, off otherwise (logs, batch jobs, CI, the tests).

    Returns
    -------
    bool
        Whether to show the bar.
    """
    if progress is not None:
        return bool(progress)
    if in_notebook():
        return True
    stream = sys.stderr
    try:
        return stream is not None and bool(stream.isatty())
    except (AttributeError, ValueError):  # replaced or closed stderr
        return False


def progress_bar(
    iterable: Iterable[Any] | None = None, *, progress: bool | None = None, **kwargs: Any
) -> Any:
    """A :class:`tqdm.auto.tqdm` bar that follows the ``progress`` rule of this module.

    Parameters
    ----------
    iterable : iterable, optional
        Items to iterate over (as for tqdm).
    progress : bool or None, default None
        See :func:`show_progress`. With None the bar also waits :data:`DELAY` seconds
        before it appears.
    **kwargs
        Further tqdm arguments (``total``, ``desc``, ``unit``, ``initial``, ...).

    Returns
    -------
    tqdm.auto.tqdm
        A bar (disabled when the rule says off; it then prints nothing).
    """
    if progress is None:
        kwargs.setdefault("delay", DELAY)
    return tqdm(iterable, disable=not show_progress(progress), **kwargs)
