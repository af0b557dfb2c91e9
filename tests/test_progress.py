"""The progress rule: explicit on/off, auto = terminal or notebook, delayed bars."""

from __future__ import annotations

import io
import sys
import types

import pytest

from harpx import _progress
from harpx._progress import DELAY, progress_bar, show_progress


class _Stream(io.StringIO):
    def __init__(self, tty: bool) -> None:
        super().__init__()
        self._tty = tty

    def isatty(self) -> bool:
        return self._tty


@pytest.mark.parametrize(
    ("tty", "expected"),
    [pytest.param(True, True, id="terminal"), pytest.param(False, False, id="pipe")],
)
def test_auto_follows_stderr(monkeypatch, tty, expected):
    monkeypatch.setattr(sys, "stderr", _Stream(tty))
    monkeypatch.setattr(_progress, "in_notebook", lambda: False)
    assert show_progress(None) is expected
    # explicit values win over the detection
    assert show_progress(True) is True and show_progress(False) is False


def test_auto_is_on_in_a_jupyter_kernel(monkeypatch):
    shell = types.SimpleNamespace(config={"IPKernelApp": {}})
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))
    monkeypatch.setattr(sys, "stderr", _Stream(False))  # a kernel's stderr is no terminal
    assert _progress.in_notebook() and show_progress(None)


def test_terminal_ipython_is_not_a_notebook(monkeypatch):
    shell = types.SimpleNamespace(config={"TerminalIPythonApp": {}})
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))
    assert not _progress.in_notebook()


def test_auto_bar_waits_before_it_appears(monkeypatch):
    stream = _Stream(True)
    monkeypatch.setattr(sys, "stderr", stream)
    monkeypatch.setattr(_progress, "in_notebook", lambda: False)
    with progress_bar(range(3), progress=None, file=stream) as bar:
        assert not bar.disable and bar.delay == DELAY
        list(bar)
    assert stream.getvalue() == ""  # a call faster than DELAY prints nothing
    with progress_bar(range(3), progress=True, file=stream) as bar:
        list(bar)
    assert "3/3" in stream.getvalue()  # forced on: shown at once


def test_solve_shows_the_load_factor_reached_with_iterations_and_cutbacks(monkeypatch):
    import numpy as np

    from harpx.mechanics import Body, Fixed, NeoHookean, Prescribed, box, solve

    body = Body(box((1.0, 1.0, 1.0), (1, 1, 1)), NeoHookean(c1=1.0, kappa=120.0))
    pull = Prescribed("right", lambda X, s: 0.1 * s * np.ones_like(X), components=(0,))
    loads = [Fixed("left", (0,)), Fixed("front", (1,)), Fixed("bottom", (2,)), pull]
    stream = _Stream(False)
    monkeypatch.setattr(sys, "stderr", stream)
    result = solve(body, loads, steps=4, progress=True)
    text = stream.getvalue()
    assert result.converged
    assert "load" in text and "100%" in text and "cutbacks=0" in text, text
    quiet = _Stream(False)
    monkeypatch.setattr(sys, "stderr", quiet)
    solve(body, loads, steps=4, progress=False)
    assert quiet.getvalue() == ""
