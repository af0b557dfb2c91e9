"""When and how to show progress: one rule for the Python API and the ``harpx`` command.

``progress=None`` (the default of every long-running call that takes it: tracking, the
solver, cohorts, dataset builds) means *auto*: a bar is shown when someone is watching, i.e.
when the code runs in a Jupyter kernel or standard error is a terminal, and only once the
call has run for :data:`DELAY` seconds, so that quick calls print nothing. Output that
nobody watches (a log file, a pipe, a batch job, a dask worker of a cohort, the tests) gets
no bar. ``True`` and ``False`` force it on or off.

In a notebook the bar is a widget when :mod:`ipywidgets` is installed, and plain text
otherwise (no ``TqdmWarning``: this module never imports :mod:`tqdm.auto`, which warns when
it is imported in a kernel without ipywidgets). In a terminal it is tqdm's text bar.

:func:`progress_bar` counts steps (frames, subjects, load increments); :func:`elapsed`
shows the running time of a step that has no count (building a scene).

Examples
--------
>>> show_progress(False), show_progress(True)
(False, True)
>>> with progress_bar(total=3, progress=False) as bar:
...     bar.update(3)
...     bar.disable
True
>>> with elapsed("building", progress=False) as bar:
...     bar.disable
True
"""

from __future__ import annotations

import importlib.util
import sys
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["DELAY", "elapsed", "in_notebook", "progress_bar", "show_progress"]

#: Seconds a call runs before its automatic (``progress=None``) bar appears.
DELAY = 2.0
#: Seconds between refreshes of an :func:`elapsed` line.
TICK = 0.5


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


def _in_dask_worker() -> bool:
    """Whether the code runs in a dask.distributed worker (only checked if it is imported)."""
    distributed = sys.modules.get("distributed")
    if distributed is None:
        return False
    try:
        distributed.get_worker()
    except Exception:  # ValueError outside a worker
        return False
    return True


def show_progress(progress: bool | None = None) -> bool:
    """Resolve a ``progress`` argument to on or off.

    Parameters
    ----------
    progress : bool or None, default None
        True or False: as given. None: on when the code runs in a Jupyter notebook or
        standard error is a terminal, off otherwise (logs, pipes, batch jobs, the tests)
        and always off in a dask worker (the subjects of :func:`harpx.batch.track_many`:
        their bars would interleave with the cohort's own).

    Returns
    -------
    bool
        Whether to show the bar.
    """
    if progress is not None:
        return bool(progress)
    if _in_dask_worker():
        return False
    if in_notebook():
        return True
    stream = sys.stderr
    try:
        return stream is not None and bool(stream.isatty())
    except (AttributeError, ValueError):  # replaced or closed stderr
        return False


def _bar_class() -> Any:
    """tqdm's widget bar in a notebook that has ipywidgets, its text bar everywhere else."""
    if in_notebook() and importlib.util.find_spec("ipywidgets") is not None:
        from tqdm.notebook import tqdm as notebook_bar

        return notebook_bar
    from tqdm.std import tqdm as text_bar

    return text_bar


def progress_bar(
    iterable: Iterable[Any] | None = None, *, progress: bool | None = None, **kwargs: Any
) -> Any:
    """A tqdm bar that follows the ``progress`` rule of this module.

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
    tqdm.std.tqdm
        A bar (a :class:`tqdm.notebook.tqdm` widget in a notebook with ipywidgets);
        disabled, printing nothing, when the rule says off.
    """
    show = show_progress(progress)
    if progress is None:
        kwargs.setdefault("delay", DELAY)
    return _bar_class()(iterable, disable=not show, **kwargs)


@contextmanager
def elapsed(desc: str, *, progress: bool | None = None) -> Iterator[Any]:
    """Show ``desc`` and the running time while the ``with`` block runs.

    For a wait that has no steps to count. The line follows the rule of
    :func:`progress_bar` (with None it appears after :data:`DELAY` seconds, and only when
    someone watches) and is refreshed every :data:`TICK` seconds by a daemon thread,
    which stops when the block ends (also on an error); the line is then cleared.

    Parameters
    ----------
    desc : str
        What is running, e.g. ``"building phantom-paper"``.
    progress : bool or None, default None
        See :func:`show_progress`.

    Yields
    ------
    tqdm.std.tqdm
        The bar (disabled when the rule says off).
    """
    bar = progress_bar(progress=progress, desc=desc, bar_format="{desc}: {elapsed}", leave=False)
    stop = threading.Event()

    def tick() -> None:
        while not stop.wait(TICK):
            bar.update(0)  # redraws once the delay has passed; closing then clears the line

    worker = None
    if not bar.disable:
        worker = threading.Thread(target=tick, name="harpx-elapsed", daemon=True)
        worker.start()
    try:
        yield bar
    finally:
        stop.set()
        if worker is not None:
            worker.join()
        bar.close()
